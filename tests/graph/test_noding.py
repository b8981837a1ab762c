"""Edges whose polylines share points meet there (graph/noding.py)."""

from __future__ import annotations

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString

from csboundary.graph import BoundaryGraph
from csboundary.graph.fragments import fragment_lengths
from csboundary.graph.noding import node_shared_points

A = np.array([[0.0, 0], [10, 0], [20, 0], [30, 0], [40, 0], [50, 0], [60, 0]])  # a corner edge along y = 0
B = np.array([[15.0, -10], [20, 0], [30, 0], [40, 0], [45, 10]])  # runs along A from x = 20 to 40


def corners(*lines: np.ndarray, scores=None) -> BoundaryGraph:
    """One corner edge per polyline; equal end points are one vertex, as in a stitched graph."""
    index: dict[tuple, int] = {}
    edges = [[index.setdefault(tuple(line[k]), len(index)) for k in (0, -1)] for line in lines]
    vertices = np.array(list(index), float).reshape(-1, 2)
    return BoundaryGraph(
        vertices,
        edges,
        edge_kinds=["corner"] * len(lines),
        edge_polylines=list(lines),
        edge_scores=np.array(scores if scores is not None else [0.5] * len(lines), float),
    )


def test_two_corner_edges_running_together_meet_where_the_overlap_starts_and_ends():
    noded = node_shared_points(corners(A, B, scores=[0.5, 0.9]))
    degree = np.bincount(noded.edges.ravel(), minlength=noded.n_vertices)
    meets = sorted(map(tuple, noded.vertices[degree == 3].tolist()))
    assert meets == [(20, 0), (40, 0)]
    assert noded.n_edges == 5 and len(fragment_lengths(noded)[1]) == 1  # one piece
    shared = [
        k
        for k in range(noded.n_edges)
        if sorted(map(tuple, noded.vertices[noded.edges[k]].tolist())) == [(20, 0), (40, 0)]
    ]
    assert len(shared) == 1 and noded.edge_scores[shared[0]] == 0.9  # the common stretch once, the more confident
    assert noded.edge_polyline(shared[0]).tolist() in ([[20, 0], [30, 0], [40, 0]], [[40, 0], [30, 0], [20, 0]])
    assert np.isclose(noded.edge_lengths().sum(), 60 + 2 * np.hypot(5, 10))


def test_a_straight_edge_ending_on_a_corner_edge_splits_it_there():
    graph = corners(A)
    graph = BoundaryGraph(
        np.concatenate([graph.vertices, [[30, 30], [30, 0]]]),
        np.concatenate([graph.edges, [[2, 3]]]),
        edge_kinds=["corner", "normal"],
        edge_polylines=[A, None],
        edge_scores=np.array([0.5, 0.7]),
    )
    noded = node_shared_points(graph)
    assert noded.n_edges == 3 and len(fragment_lengths(noded)[1]) == 1
    assert np.bincount(noded.edges.ravel())[3] == 3  # the straight edge's end, (30, 0), now joins A's two halves
    assert noded.edge_polylines[noded.edge_kinds.index("normal")] is None


def test_a_graph_without_shared_points_is_returned_as_is():
    graph = corners(A, A + [0, 5])
    assert node_shared_points(graph) is graph


def _paths(draw_steps: list[list[int]], starts: list[tuple[int, int]]) -> list[np.ndarray]:
    steps = [(1, 0), (0, 1), (-1, 0), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)]
    out = []
    for start, moves in zip(starts, draw_steps):
        path = [start]
        for m in moves:
            nxt = (path[-1][0] + steps[m][0], path[-1][1] + steps[m][1])
            if nxt not in path:
                path.append(nxt)
        if len(path) >= 2 and LineString(path).is_simple and path not in out and path[::-1] not in out:
            out.append(path)
    return [np.array(path, float) + 0.5 for path in out]


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.lists(st.integers(0, 7), min_size=1, max_size=14), min_size=2, max_size=4),
    st.lists(st.tuples(st.integers(0, 4), st.integers(0, 4)), min_size=4, max_size=4),
)
def test_noded_edges_share_only_end_vertices_and_cover_the_union_once(moves, starts):
    """Skeleton-like paths (8-connected pixel steps, none crossing itself), touching, crossing
    and running along each other: afterwards no two edges have a common polyline point other than
    a common end vertex, and the edges' length is the union's."""
    lines = _paths(moves, starts)
    if len(lines) < 2:
        return
    noded = node_shared_points(corners(*lines))
    for i in range(noded.n_edges):
        for j in range(i + 1, noded.n_edges):
            a, b = noded.edge_polyline(i), noded.edge_polyline(j)
            common = {tuple(p) for p in a.tolist()} & {tuple(p) for p in b.tolist()}
            ends = {tuple(p) for p in noded.vertices[noded.edges[i]].tolist()} & {
                tuple(p) for p in noded.vertices[noded.edges[j]].tolist()
            }
            assert common <= ends
            meeting = LineString(a).intersection(LineString(b))  # geometrically too: no crossing, no shared stretch
            assert meeting.geom_type in ("Point", "MultiPoint") or meeting.is_empty
            assert all(
                min(np.hypot(px - qx, py - qy) for qx, qy in ends) < 1e-9 for px, py in shapely.get_coordinates(meeting)
            )
    union = shapely.unary_union([LineString(line) for line in lines]).length
    assert np.isclose(noded.edge_lengths().sum(), union)
