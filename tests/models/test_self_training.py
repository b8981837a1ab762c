"""Self-training's parts, each on inputs whose right answer is known by hand: where the roadway's
edge is, which teacher pixels become which pseudo-labels with which weight, what mixing pastes,
the EMA teacher's arithmetic, and windows of unlabelled imagery that never are no-data."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from csboundary.data.raster import WindowRead
from csboundary.data.windows import PixelWindow
from csboundary.models.training.self_training import (
    AdaptConfig,
    MeanTeacher,
    paste_roadway,
    posterior,
    pseudo_labels,
    roadway_edge_near,
)
from csboundary.models.training.unlabelled import MIN_VALID_SHARE, UnlabelledImagery


def _road_stripe(size: int = 64, first: int = 20, last: int = 39) -> torch.Tensor:
    """(1, size, size) surface probabilities: 0.9 on columns first..last, 0.1 elsewhere."""
    surface = torch.full((1, size, size), 0.1)
    surface[:, :, first : last + 1] = 0.9
    return surface


def test_the_roadway_edge_is_near_the_stripe_sides_only():
    near = roadway_edge_near(_road_stripe(), px=3)[0]
    # the edge pixels are columns 19/20 (left side) and 39/40 (right side); 3 px around them
    expected = np.zeros(64, bool)
    expected[16:24] = True
    expected[36:44] = True
    assert np.array_equal(near[32].numpy(), expected)
    assert near.all(dim=0).tolist() == expected.tolist()  # the same on every row


def test_posteriors_undo_the_positive_weighting_the_network_learnt_with():
    # a network trained with positives weighted w gives p = w q / (w q + 1 - q) for a posterior q
    q = torch.tensor([0.0, 0.1, 0.5, 0.9, 1.0]).view(1, 1, 5, 1).repeat(1, 3, 1, 1)
    w = (20.0, 10.0)
    p = q.clone()
    for c, wc in enumerate(w):
        p[:, c] = wc * q[:, c] / (wc * q[:, c] + 1 - q[:, c])
    assert torch.allclose(posterior(p, w), q, atol=1e-6)
    assert posterior(torch.full((1, 2, 1, 1), 10 / 11), (10.0, 10.0))[0, 0, 0, 0].item() == pytest.approx(0.5)


def test_pseudo_labels_are_confidence_weighted_and_anchored_to_the_roadway():
    maps = torch.zeros((1, 3, 64, 64))
    maps[:, 2] = _road_stripe()
    maps[:, 0] = 0.3  # keypoint heat: a soft target, weight 1
    maps[:, 1] = 0.05
    maps[0, 1, 10, 20] = 0.9  # a boundary pixel on the roadway's edge
    maps[0, 1, 10, 30] = 0.9  # one in the middle of the roadway (a car row, a lane line)
    maps[0, 1, 10, 3] = 0.7  # one far from any roadway (a roof outline)
    valid = torch.ones((1, 64, 64), dtype=torch.bool)
    valid[0, 60:] = False
    target, weight = pseudo_labels(maps, valid, AdaptConfig(anchor_px=3))
    assert torch.allclose(target[0, 0], torch.full((64, 64), 0.3)) and torch.all(weight[0, 0, :60] == 1)
    assert target[0, 1, 10, 20] == pytest.approx(0.9) and weight[0, 1, 10, 20] == pytest.approx(0.8)
    assert target[0, 1, 11, 18] == pytest.approx(0.05) and weight[0, 1, 11, 18] == pytest.approx(
        0.9
    )  # near the edge: as the teacher says
    for col in (30, 3, 50):  # away from the roadway's edge: background, with full weight
        assert target[0, 1, 10, col] == 0 and weight[0, 1, 10, col] == 1
    assert target[0, 2, 5, 25] == pytest.approx(0.9) and weight[0, 2, 5, 25] == pytest.approx(0.8)
    assert torch.all(weight[0, :, 60:] == 0)  # no-data teaches nothing
    loose, _ = pseudo_labels(maps, valid, AdaptConfig(surface_anchor=False))
    assert loose[0, 1, 10, 30] == pytest.approx(0.9) and loose[0, 1, 10, 3] == pytest.approx(0.7)
    hard, _ = pseudo_labels(maps, valid, AdaptConfig(surface_anchor=False, hard_labels=True))
    assert (
        hard[0, 1, 10, 3] == 1
        and hard[0, 1, 11, 18] == 0
        and hard[0, 2, 5, 25] == 1
        and hard[0, 0, 5, 5] == pytest.approx(0.3)
    )
    _, flat = pseudo_labels(maps, valid, AdaptConfig(confidence_weighting=False))
    assert torch.all(flat[0, :, :60] == 1)


def test_mixing_pastes_the_widened_roadway_with_its_labels():
    size = 32
    image, target, weight = (
        np.zeros((4, size, size), np.float32),
        np.zeros((3, size, size), np.float32),
        np.full((3, size, size), 0.2, np.float32),
    )
    src_image = np.ones((4, size, size), np.float32)
    src_target = np.zeros((3, size, size), np.float32)
    src_target[2, :, 10:14] = 1  # the roadway: columns 10-13
    src_target[1, :, 9] = 1  # its boundary, just outside it
    src_valid = np.ones((size, size), bool)
    share = paste_roadway(image, target, weight, (src_image, src_target, src_valid), widen_px=2)
    pasted = np.zeros(size, bool)
    pasted[8:16] = True  # columns 10-13 widened by 2 px each way
    assert share == pytest.approx(8 / size)
    assert np.array_equal(image[0, 5] > 0, pasted) and np.array_equal(weight[1, 5] == 1, pasted)
    assert np.array_equal(target[1, 5] > 0, np.arange(size) == 9)  # the boundary came along
    assert np.all(weight[:, :, ~pasted] == np.float32(0.2))


def test_the_teacher_is_the_moving_average_of_the_student():
    student = torch.nn.Sequential(torch.nn.Linear(2, 2), torch.nn.BatchNorm1d(2))
    pair = MeanTeacher(student)
    with torch.no_grad():
        student[0].weight.fill_(1.0)
        student[1].running_mean.fill_(2.0)
    teacher_before = pair.teacher[0].weight.clone()
    pair.update_teacher(0.9)
    assert torch.allclose(pair.teacher[0].weight, 0.9 * teacher_before + 0.1)
    assert torch.allclose(pair.teacher[1].running_mean, torch.full((2,), 0.2))
    assert not any(p.requires_grad for p in pair.teacher.parameters())
    pair.train()
    assert student.training and not pair.teacher.training
    assert {k.split(".")[0] for k in pair.state_dict()} == {"teacher", "student"}  # a checkpoint resumes both


class _View:
    """A mosaic-like array: the left ``valid_cols`` columns hold imagery, the rest no-data."""

    def __init__(self, size: int, valid_cols: int):
        self.width = self.height = size
        self.valid_cols = valid_cols
        self.footprint = [PixelWindow(0, 0, size, size)]  # one file: no-data inside it is found by reading

    def read(self, window) -> WindowRead:
        cols = np.arange(window.col_off, window.col_off + window.width)
        rows = np.arange(window.row_off, window.row_off + window.height)
        inside = ((cols >= 0) & (cols < min(self.valid_cols, self.width)))[None, :] & (
            (rows >= 0) & (rows < self.height)
        )[:, None]
        data = np.where(inside, 200, 0).astype(np.uint8)[None].repeat(4, axis=0)
        return WindowRead(window, data, inside)


def test_windows_of_unlabelled_imagery_avoid_no_data():
    imagery = UnlabelledImagery([_View(400, 150), _View(100, 100)], ["a", "b"])
    assert imagery.pixels == 400 * 400 + 100 * 100
    rng = np.random.default_rng(0)
    for _ in range(40):
        image, valid = imagery.sample(rng, 64)
        assert image.shape == (4, 64, 64) and valid.mean() >= MIN_VALID_SHARE
        assert np.all(image[:, ~valid] == 0) and np.allclose(image[:, valid], 200 / 255)
    small = UnlabelledImagery([_View(100, 100)], ["b"]).sample(rng, 128)[
        1
    ]  # a mosaic smaller than the window: all of it
    assert small.sum() == 100 * 100
    with pytest.raises(ValueError, match="no valid pixel"):
        UnlabelledImagery([_View(200, 0)], ["empty"]).sample(rng, 64)
