"""Edge evidence on hand-made maps: the numbers a confidence is computed from."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.graph import BoundaryGraph
from csboundary.graph.edge_evidence import FEATURES, edge_evidence
from csboundary.graph.polyline import points_along


def array_sampler(maps: np.ndarray):
    def sample(points: np.ndarray) -> np.ndarray:
        col = np.clip(np.rint(points[:, 0]).astype(int), 0, maps.shape[2] - 1)
        row = np.clip(np.rint(points[:, 1]).astype(int), 0, maps.shape[1] - 1)
        return maps[:, row, col].T

    return sample


def curb_maps() -> np.ndarray:
    """100 x 100 px: boundary on row 50, roadway above it (rows < 50), a keypoint at (71, 50)."""
    maps = np.zeros((3, 100, 100))
    maps[1, 50, :] = 1.0
    maps[2, :50, :] = 1.0
    maps[0, 50, 71] = 0.8  # on one of the points read every 2 px from x = 11
    return maps


def features_of(graph: BoundaryGraph, maps=None) -> list[dict[str, float]]:
    table = edge_evidence(graph, None if maps is None else array_sampler(maps))
    return [dict(zip(FEATURES, row)) for row in table]


def test_a_curb_has_roadway_on_one_side_and_boundary_along_it():
    graph = BoundaryGraph(
        np.array([[10.0, 50.0], [90.0, 50.0]]), np.array([[0, 1]]), edge_kinds=["normal"], edge_scores=np.array([0.7])
    )
    (f,) = features_of(graph, curb_maps())
    assert f["boundary_mean"] == f["boundary_min"] == 1.0
    assert f["surface_high"] == 1.0 and f["surface_low"] == 0.0 and f["surface_contrast"] == 1.0
    assert f["surface_on"] == 0.0 and f["keypoint_max"] == 0.8
    assert f["score"] == 0.7 and f["kind_normal"] == 1.0 and f["kind_corner"] == 0.0
    assert f["log_length"] == pytest.approx(np.log1p(80.0))
    assert f["sinuosity"] == 1.0 and f["degree_min"] == f["degree_max"] == 1.0


def test_an_edge_across_the_roadway_has_roadway_on_both_sides():
    # from the curb up into the roadway: the boundary map is on it only at its end
    graph = BoundaryGraph(np.array([[40.0, 50.0], [40.0, 10.0]]), np.array([[0, 1]]))
    (f,) = features_of(graph, curb_maps())
    assert f["surface_low"] > 0.9 and f["surface_contrast"] < 0.1
    assert f["boundary_min"] == 0.0 and f["boundary_mean"] < 0.1


def test_shape_and_place_in_the_graph():
    # an L of two edges (degree 2 where they meet) and a lone zig-zag edge of its own piece
    vertices = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 40.0], [100.0, 100.0], [130.0, 100.0]])
    zigzag = np.array([[100.0, 100.0], [115.0, 110.0], [130.0, 100.0]])
    graph = BoundaryGraph(
        vertices,
        np.array([[0, 1], [1, 2], [3, 4]]),
        edge_kinds=["corner", "normal", "skeleton"],
        edge_polylines=[None, None, zigzag],
    )
    a, b, c = features_of(graph)
    assert a["degree_min"] == 1 and a["degree_max"] == 2 and b["degree_max"] == 2
    assert a["log_piece_length"] == b["log_piece_length"] == pytest.approx(np.log1p(70.0))
    assert a["log_piece_edges"] == pytest.approx(np.log1p(2))
    assert c["sinuosity"] == pytest.approx(2 * np.hypot(15, 10) / 30)
    assert c["kind_skeleton"] == 1.0 and np.isnan(c["boundary_mean"])  # no maps given


def test_points_along_are_evenly_spaced_with_left_normals():
    points, normals = points_along(np.array([[0.0, 0.0], [10.0, 0.0]]), 2.0)
    np.testing.assert_allclose(points[:, 0], [1, 3, 5, 7, 9])
    np.testing.assert_allclose(normals, [[0.0, -1.0]] * 5)  # image rows grow downwards: left of east is up


def test_groups_end_pieces_and_boundaries_where_they_meet():
    # a straight boundary of three 10 px edges through degree-2 vertices, the last edge in another group
    vertices = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [30.0, 0.0]])
    graph = BoundaryGraph(vertices, np.array([[0, 1], [1, 2], [2, 3]]))
    whole = [dict(zip(FEATURES, row)) for row in edge_evidence(graph)]
    split = [dict(zip(FEATURES, row)) for row in edge_evidence(graph, groups=np.array([5, 5, 9]))]
    assert [f["log_piece_length"] for f in whole] == pytest.approx([np.log1p(30.0)] * 3)
    assert [f["log_piece_length"] for f in split] == pytest.approx([np.log1p(20.0)] * 2 + [np.log1p(10.0)])
    assert [f["log_chain_length"] for f in split] == pytest.approx([np.log1p(20.0)] * 2 + [np.log1p(10.0)])
    assert [f["log_piece_edges"] for f in split] == pytest.approx([np.log1p(2)] * 2 + [np.log1p(1)])
    # the degrees are the graph's: the vertex the groups share still has two edges
    assert split[1]["degree_max"] == split[2]["degree_max"] == 2
