"""Foreign clutter painted over the non-road area of road-surface samples (issue 66): off by
default, never over the roadway, its margin, a boundary, an unknown surface or no-data, and the
targets stay as they were."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.data.windows import PixelWindow
from csboundary.models.augmentation import AugmentConfig, dead_leaves, paint_surface_negatives
from csboundary.models.training.data import TrainingCity

SIZE = 96
ROAD = slice(40, 56)  # roadway rows
BOUNDARIES = (39, 56)  # its curbs
UNKNOWN = slice(0, 10)  # columns whose surface is unknown (-1)
NO_DATA = slice(86, 96)  # columns outside the imagery


def sample() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    image = np.full((4, SIZE, SIZE), 0.5, np.float32)
    target = np.zeros((3, SIZE, SIZE), np.float32)
    target[2, ROAD] = 1.0
    for row in BOUNDARIES:
        target[1, row] = 1.0
    target[2, :, UNKNOWN] = -1.0
    valid = np.ones((SIZE, SIZE), bool)
    valid[:, NO_DATA] = False
    return image, target, valid


ON = AugmentConfig(surface_negatives=1.0, surface_negatives_margin_px=(8, 8), surface_negatives_cover=(1.0, 1.0))


def test_off_by_default_it_returns_the_image_and_draws_nothing():
    assert AugmentConfig().surface_negatives == 0
    image, target, valid = sample()
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    assert paint_surface_negatives(rng, image, target, valid, AugmentConfig()) is image
    assert rng.bit_generator.state == state  # seeded runs without the option draw the same samples


def test_it_paints_far_from_the_roadway_and_nowhere_else():
    image, target, valid = sample()
    out = paint_surface_negatives(np.random.default_rng(1), image, target, valid, ON)
    changed = np.any(out != image, axis=0)
    rows = np.arange(SIZE)[:, None]
    near = (rows >= BOUNDARIES[0] - 8) & (rows <= BOUNDARIES[1] + 8)  # the roadway, its curbs and the margin
    assert not changed[np.broadcast_to(near, changed.shape)].any()
    assert not changed[:, UNKNOWN].any() and not changed[:, NO_DATA].any()
    far = ~np.broadcast_to(near, changed.shape).copy()
    far[:, UNKNOWN] = far[:, NO_DATA] = False
    assert changed[far].mean() > 0.9
    assert np.array_equal(out[3][changed], out[1][changed])  # NIR := green, as RGB imagery is read
    assert out.dtype == np.float32 and out.min() >= 0 and out.max() <= 1


def test_a_sample_without_a_road_surface_is_never_painted():
    image, target, valid = sample()
    assert paint_surface_negatives(np.random.default_rng(2), image, target[:2], valid, ON) is image
    target[2] = -1.0  # a city without a road_surface layer
    assert paint_surface_negatives(np.random.default_rng(2), image, target, valid, ON) is image


def test_the_clutter_is_in_range_varied_and_seeded():
    a = dead_leaves(np.random.default_rng(3), 64)
    assert a.shape == (3, 64, 64) and a.dtype == np.float32 and a.min() >= 0 and a.max() <= 1
    assert a.std(axis=(1, 2)).min() > 0.03 and len(np.unique(a[0])) > 200
    assert np.array_equal(a, dead_leaves(np.random.default_rng(3), 64))


@pytest.mark.parametrize("probability", [0.0, 1.0])
def test_augmented_samples_keep_their_targets_and_are_painted_when_asked(probability):
    image, target, valid = sample()
    city = TrainingCity.__new__(TrainingCity)  # no files: the window's sample is given
    city.random_window = lambda rng, size: PixelWindow(0, 0, size, size)
    city.fpn_sample = lambda window, surface: (image.copy(), target.copy(), valid.copy())
    plain = dict(
        rotate=False,
        scale=(1.0, 1.0),
        brightness=0.0,
        contrast=(1.0, 1.0),
        gamma=(1.0, 1.0),
        hue=0.0,
        saturation=(1.0, 1.0),
        channel_gain=0.0,
        blur_p=0.0,
        noise_p=0.0,
        jpeg_p=0.0,
        nir_as_green_p=0.0,
    )
    config = AugmentConfig(
        **plain, surface_negatives=probability, surface_negatives_margin_px=(8, 8), surface_negatives_cover=(1.0, 1.0)
    )
    out, out_target, out_valid = city.augmented_fpn_sample(np.random.default_rng(4), SIZE, config, surface=True)
    assert out_target[2].sum() == target[2].sum() and out_valid.sum() == valid.sum()  # flipped or turned, not changed
    changed = np.any(np.abs(out - 0.5) > 1e-6, axis=0)
    assert changed.any() == (probability > 0)
    assert not changed[out_target[2] != 0].any() and not changed[~out_valid].any()
