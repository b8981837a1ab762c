"""Grid-crossing vertices: where the boundary map's skeleton crosses the window's grid lines."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.graph.crossings import CrossingConfig, crossing_points, run_centres
from helpers import shipped_parts


def test_runs_have_their_centres():
    assert run_centres(np.array([0, 1, 1, 1, 0, 0, 1, 0], bool)) == [2.0, 6.0]
    assert run_centres(np.zeros(5, bool)) == []


def test_a_straight_boundary_crosses_each_line_once():
    m = np.zeros((400, 400), np.float32)
    m[119:122, :] = 1.0  # a 3 px boundary along row 120
    m[:, 199:202] = 0.0  # with a gap, so the skeleton has two pieces
    points = crossing_points(m, CrossingConfig(spacing_px=250))
    # vertical lines at x = 50 and 300 (offset 50); the horizontal line y = 50 misses the boundary
    assert sorted(map(tuple, np.round(points, 1))) == [(50.5, 120.5), (300.5, 120.5)]


def test_no_crossing_next_to_an_existing_vertex_and_off_by_default():
    m = np.zeros((400, 400), np.float32)
    m[119:122, :] = 1.0
    points = crossing_points(m, CrossingConfig(spacing_px=250, min_distance_px=12), existing=np.array([[55.0, 121.0]]))
    assert [tuple(np.round(p, 1)) for p in points] == [(300.5, 120.5)]
    assert len(crossing_points(m, CrossingConfig())) == 0


@pytest.mark.parametrize("offset", [0, 50, 137])
def test_lines_sit_at_the_offset_every_spacing(offset):
    m = np.zeros((300, 300), np.float32)
    m[:, 10:13] = 1.0  # vertical boundary at column 11
    points = crossing_points(m, CrossingConfig(spacing_px=100, offset_px=offset, min_distance_px=1))
    assert sorted(p[1] for p in points) == [y + 0.5 for y in range(offset, 300, 100)]
    assert all(p[0] == 11.5 for p in points)


def test_bundle_carries_the_crossing_setting(tmp_path):
    import torch

    from csboundary.graph.settings import GraphSettings
    from csboundary.models.checkpoint import shipped_weights
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor

    shipped_parts(tmp_path)
    make_bundle(
        tmp_path / "fpn.pt",
        tmp_path / "afanet.pt",
        tmp_path / "b.pt",
        GraphSettings().replaced(edge_threshold=0.3, min_edge_support=0.2, grid_crossings=250, min_fragment_length=160),
    )
    predictor = PatchPredictor.load(tmp_path / "b.pt", torch.device("cpu"))
    settings = predictor.settings
    assert (
        settings.crossings.spacing_px == 250 and settings.support.min_support == 0.2 and settings.min_fragment_px == 160
    )
    maps = np.zeros((2, 400, 400), np.float32)
    maps[1, 119:122, :] = 1.0  # a boundary and no keypoint at all: the crossings are the vertices
    assert sorted(map(tuple, np.round(predictor.extract(maps).vertices, 1))) == [(50.5, 120.5), (300.5, 120.5)]
    shipped_predictor = PatchPredictor.load(shipped_weights(), torch.device("cpu"))
    # the model card's choice
    assert shipped_predictor.settings.crossings.spacing_px == 0 and shipped_predictor.settings.min_fragment_px == 240


def test_bundle_carries_the_vertex_threshold_its_afanet_was_trained_with(tmp_path):
    import torch

    from csboundary.graph.settings import GraphSettings
    from csboundary.models.checkpoint import shipped_weights
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor

    shipped_parts(tmp_path, train_config={"vertex_threshold": 0.35})
    make_bundle(tmp_path / "fpn.pt", tmp_path / "afanet.pt", tmp_path / "trained.pt")
    make_bundle(
        tmp_path / "fpn.pt",
        tmp_path / "afanet.pt",
        tmp_path / "given.pt",
        GraphSettings().replaced(vertex_threshold=0.6),
    )
    assert PatchPredictor.load(tmp_path / "trained.pt", torch.device("cpu")).settings.vertices.threshold == 0.35
    assert PatchPredictor.load(tmp_path / "given.pt", torch.device("cpu")).settings.vertices.threshold == 0.6
    shipped = torch.load(shipped_weights(), map_location="cpu", weights_only=True)["inference"]["vertex_threshold"]
    # chosen on both real sets
    assert (
        shipped == 0.25
        and PatchPredictor.load(shipped_weights(), torch.device("cpu")).settings.vertices.threshold == shipped
    )
    # a keypoint blob peaking at 0.45 is a vertex at 0.35, not at 0.6
    maps = np.zeros((2, 200, 200), np.float32)
    yy, xx = np.mgrid[:200, :200]
    maps[0] = 0.45 * np.exp(-((xx - 100.5) ** 2 + (yy - 80.5) ** 2) / 18.0)
    assert PatchPredictor.load(tmp_path / "trained.pt", torch.device("cpu")).extract(maps).n_vertices == 1
    assert PatchPredictor.load(tmp_path / "given.pt", torch.device("cpu")).extract(maps).n_vertices == 0
