"""Boundary the graph missed, filled in from the segmentation skeleton: hand-built maps and graphs."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.polyline import polyline_length
from csboundary.graph.settings import GraphOverrides, GraphSettings
from csboundary.graph.skeleton_fill import (
    SKELETON,
    FillConfig,
    fill_from_skeleton,
    long_stretches,
    pieces,
    uncovered_skeleton,
)
from helpers import bundle_without, shipped_parts

ON = FillConfig(min_length_px=30)


def row_map(x0: int = 20, x1: int = 220, row: int = 50, size: int = 120) -> np.ndarray:
    """A 3 px wide boundary along ``row`` from column x0 to x1 - 1 (a (size, 240) map)."""
    m = np.zeros((size, 240), np.float32)
    m[row - 1 : row + 2, x0:x1] = 1.0
    return m


def graph(vertices, edges) -> BoundaryGraph:
    edges = np.array(edges, np.int64).reshape(-1, 2)
    return BoundaryGraph(
        np.array(vertices, float).reshape(-1, 2),
        edges,
        vertex_kinds=["isolated"] * len(vertices),
        edge_kinds=["normal"] * len(edges),
        edge_polylines=[None] * len(edges),
        edge_scores=np.ones(len(edges)),
    )


def test_off_returns_the_graph_itself():
    g = graph([[0.5, 0.5], [9.5, 0.5]], [[0, 1]])
    assert fill_from_skeleton(g, row_map(), FillConfig()) is g


def test_a_boundary_with_no_vertex_becomes_one_skeleton_edge_along_it():
    out = fill_from_skeleton(graph([], []), row_map(), ON)
    assert out.n_edges == 1 and out.edge_kinds == [SKELETON]
    line = out.edge_polyline(0)
    assert np.abs(line[:, 1] - 50.5).max() <= 1.0  # the middle row (thinning may bend the very end)
    # skeletonize shortens a 3 px wide bar by about a pixel at each end: 200 px drawn
    assert 195 <= out.edge_lengths()[0] <= 200
    assert out.edge_scores[0] == pytest.approx(1.0)


def test_a_covered_boundary_adds_nothing():
    g = graph([[20.5, 50.5], [219.5, 52.5]], [[0, 1]])  # a chord at most 2 px off the line
    out = fill_from_skeleton(g, row_map(), ON)
    assert out is g


def test_the_filled_stretch_joins_the_vertex_where_the_graph_stops():
    # the graph covers the line up to x = 100; the rest (about 110 px) is filled and attached there
    g = graph([[20.5, 50.5], [100.5, 50.5]], [[0, 1]])
    out = fill_from_skeleton(g, row_map(), ON)
    assert out.n_edges == 2 and out.n_vertices == 3
    u, v = out.edges[1]
    assert 1 in (u, v)  # joined to the graph's end vertex, not a new vertex 6 px away
    far = out.vertices[v if u == 1 else u]
    assert far[0] == pytest.approx(218.5, abs=1.5)
    line = out.edge_polyline(1)
    assert np.allclose(line[0], out.vertices[u]) and np.allclose(line[-1], out.vertices[v])


def test_short_uncovered_stretches_are_left_alone():
    assert fill_from_skeleton(graph([], []), row_map(20, 45), ON).n_edges == 0  # ~24 px < 30
    assert fill_from_skeleton(graph([], []), row_map(20, 60), ON).n_edges == 1  # ~39 px


def test_long_stretches_counts_pixels_of_eight_connected_pieces():
    mask = np.zeros((10, 10), bool)
    mask[np.arange(6), np.arange(6)] = True  # a diagonal of 6 pixels: one piece
    mask[9, 0:3] = True  # 3 pixels
    kept = long_stretches(mask, 4)
    assert kept[np.arange(6), np.arange(6)].all() and not kept[9].any()


def test_neighbouring_regions_cut_the_skeleton_at_one_shared_pixel():
    # two windows' cores meet at column 120; each fills its core plus one column beyond
    boundary = row_map()
    left = fill_from_skeleton(graph([], []), boundary, ON, region=(0, 120, 0, 121))
    right = fill_from_skeleton(graph([], []), boundary, ON, region=(0, 120, 120, 240))
    ends_left = {tuple(p) for p in left.vertices}
    ends_right = {tuple(p) for p in right.vertices}
    assert ends_left & ends_right == {(120.5, 50.5)}


def test_uncovered_skeleton_measures_distance_to_the_edge_polylines():
    # an L-shaped polyline edge covers the line where it runs along it
    poly = np.array([[20.5, 50.5], [120.5, 50.5], [120.5, 110.5]])
    g = BoundaryGraph(poly[[0, 2]], [[0, 1]], edge_kinds=["corner"], edge_polylines=[poly], edge_scores=np.ones(1))
    unc = uncovered_skeleton(row_map(), g, ON)
    cols = np.flatnonzero(unc.any(axis=0))
    assert cols.min() == 127 and cols.max() >= 217  # more than 6 px beyond the polyline's corner


@settings(max_examples=25, deadline=None)
@given(st.floats(0, np.pi), st.integers(60, 150), st.floats(-10, 10), st.floats(-10, 10))
@example(0.75, 60, 0.0, 1.5)
def test_a_drawn_straight_boundary_is_filled_on_its_own_line(angle, length, dx, dy):
    m = np.zeros((200, 200), np.uint8)
    c = np.array([100 + dx, 100 + dy])
    d = np.array([np.cos(angle), np.sin(angle)]) * length / 2
    a, b = np.round(c - d).astype(int), np.round(c + d).astype(int)
    cv2.line(m, tuple(int(v) for v in a), tuple(int(v) for v in b), 1, thickness=3)
    out = fill_from_skeleton(graph([], []), m.astype(np.float32), ON)
    assert out.n_edges >= 1
    total = out.edge_lengths().sum()
    assert (
        0.8 * length <= total <= 1.1 * length + 4
    )  # a short diagonal line loses up to ~10 px (found: 0.75 rad, 60 px -> 50.2)
    # every filled point lies on the drawn line (pixel centres, so within ~2 px of its axis)
    points = np.concatenate([out.edge_polyline(k) for k in range(out.n_edges)]) - 0.5
    axis = (b - a) / np.linalg.norm(b - a)
    offset = points - a
    across = np.abs(offset[:, 0] * axis[1] - offset[:, 1] * axis[0])
    assert across.max() <= 2.5


def test_a_closed_boundary_is_filled_as_a_ring_of_three_edges():
    m = np.zeros((120, 120), np.uint8)
    cv2.circle(m, (60, 60), 30, 1, thickness=3)  # a traffic island's curb, no vertex on it
    out = fill_from_skeleton(graph([], []), m.astype(np.float32), ON)
    assert out.n_edges == 3 and out.n_vertices == 3
    assert np.bincount(out.edges.ravel()).tolist() == [2, 2, 2]
    assert out.edge_lengths().sum() == pytest.approx(2 * np.pi * 30, rel=0.05)


def test_pieces_cut_a_line_at_equal_arc_lengths():
    line = np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 300.0]])  # an L, 600 px
    parts = pieces(line, 200.0)
    assert [p.tolist() for p in parts] == [
        [[0, 0], [200, 0]],
        [[200, 0], [300, 0], [300, 100]],
        [[300, 100], [300, 300]],
    ]
    assert len(pieces(line, 0.0)) == 1 and pieces(line, 0.0)[0] is line
    assert pieces(np.array([[5.0, 5.0], [5.0, 5.0]]), 200.0, closed=True) == []  # nothing between the ends
    ring = pieces(
        np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 30.0], [0.0, 30.0], [0.0, 0.0]]), 200.0, closed=True
    )  # 120 px
    assert [p.tolist() for p in ring] == [
        [[0, 0], [30, 0], [30, 10]],
        [[30, 10], [30, 30], [10, 30]],
        [[10, 30], [0, 30], [0, 0]],
    ]


@settings(max_examples=50, deadline=None)
@given(
    st.lists(st.tuples(st.floats(0, 500), st.floats(0, 500)), min_size=2, max_size=12), st.floats(5, 400), st.booleans()
)
def test_pieces_join_up_into_the_line(points, split_px, closed):
    line = np.array(points)
    parts = pieces(line, split_px, closed)
    if polyline_length(line) == 0:
        assert parts == []
        return
    total = sum(polyline_length(p) for p in parts)
    assert total == pytest.approx(polyline_length(line), abs=1e-6)
    assert np.allclose(parts[0][0], line[0]) and np.allclose(parts[-1][-1], line[-1])
    for a, b in zip(parts[:-1], parts[1:]):
        assert np.array_equal(a[-1], b[0])
    length = polyline_length(line)
    assert len(parts) == max(int(np.ceil(length / split_px)), 3 if closed else 1)
    assert [polyline_length(p) for p in parts] == pytest.approx([length / len(parts)] * len(parts), abs=1e-6)


def test_a_long_filled_stretch_is_cut_into_edges_chained_end_to_end():
    out = fill_from_skeleton(graph([], []), row_map(), FillConfig(min_length_px=30, split_px=50))
    assert out.n_edges == 4
    degree = np.bincount(out.edges.ravel())
    assert sorted(degree.tolist()) == [1, 1, 2, 2, 2]
    assert 195 <= out.edge_lengths().sum() <= 200


def test_bundle_carries_the_fill_and_a_command_line_value_overrides_it(tmp_path):
    import torch

    from csboundary.graph.settings import GraphSettings
    from csboundary.models.training.bundle import make_bundle
    from csboundary.pipeline.prediction.patch import PatchPredictor, load_predictor

    shipped_parts(tmp_path)
    make_bundle(
        tmp_path / "fpn.pt", tmp_path / "afanet.pt", tmp_path / "b.pt", GraphSettings().replaced(fill_min_length=55)
    )
    assert PatchPredictor.load(tmp_path / "b.pt", torch.device("cpu")).settings.fill.min_length_px == 55
    assert not load_predictor(
        tmp_path / "b.pt", "cpu", GraphOverrides(fill_min_length=0), engine="torch"
    ).settings.fill.active
    bundle_without(tmp_path / "b.pt", tmp_path / "older.pt", ("fill_min_length",))  # a bundle from before the fill
    assert not PatchPredictor.load(tmp_path / "older.pt", torch.device("cpu")).settings.fill.active


def test_the_predictor_fills_a_window_only_inside_its_core_and_one_pixel_beyond():
    from types import SimpleNamespace

    from csboundary.data.windows import PixelWindow
    from csboundary.pipeline.prediction.patch import PatchPredictor

    maps = np.zeros((2, 120, 240), np.float32)
    maps[1] = row_map()
    host = SimpleNamespace(settings=GraphSettings(fill=ON))
    core = SimpleNamespace(core_local=PixelWindow(col_off=10, row_off=10, width=100, height=100))
    out = PatchPredictor.filled(host, core, maps, graph([], []))
    xs = np.concatenate([out.edge_polyline(k)[:, 0] for k in range(out.n_edges)])
    assert xs.min() == pytest.approx(20.5) and xs.max() == pytest.approx(
        110.5
    )  # columns 20..110: the core's 10..109 and 110
    whole = PatchPredictor.filled(host, None, maps, graph([], []))  # a single patch: no core
    assert whole.edge_lengths().sum() > out.edge_lengths().sum() + 100
