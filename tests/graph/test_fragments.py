"""Short isolated fragments: piece lengths by hand, the filter, and the edge subgraph under it."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph import BoundaryGraph
from csboundary.graph.fragments import drop_short_fragments, fragment_lengths


def three_pieces() -> BoundaryGraph:
    """A 3-4-5 path of two edges (length 3 + 4 along an L polyline of 4 + 4), a 10 px segment,
    and a 2 px speck; vertex 7 is isolated."""
    vertices = [(0, 0), (3, 0), (3, 4), (100, 100), (110, 100), (50, 50), (52, 50), (200, 200)]
    edges = [(0, 1), (1, 2), (3, 4), (5, 6)]
    polylines = [None, np.array([(3, 0), (7, 0), (7, 4), (3, 4)], float), None, None]
    return BoundaryGraph(
        np.array(vertices, float),
        np.array(edges),
        vertex_kinds=["a", "b", "c", "d", "e", "f", "g", "h"],
        edge_kinds=["normal", "corner", "normal", "normal"],
        edge_polylines=polylines,
        edge_scores=np.array([0.9, 1.0, 0.8, 0.4]),
        edge_patches=np.array([[0, 0], [0, 0], [0, 1], [1, 1]]),
    )


def test_piece_lengths_follow_the_polylines():
    piece, length = fragment_lengths(three_pieces())
    assert piece[0] == piece[1] and len(set(piece.tolist())) == 3
    assert np.allclose(sorted(length), [2.0, 10.0, 15.0])  # 3 + (4 + 4 + 4); 10; 2
    assert np.isclose(length[piece[0]], 15.0)


def test_short_pieces_go_with_the_vertices_only_they_use():
    kept = drop_short_fragments(three_pieces(), 10.0)  # the 10 px segment stays (at the limit)
    assert kept.n_edges == 3 and kept.n_vertices == 5
    assert kept.vertex_kinds == ["a", "b", "c", "d", "e"] and kept.edge_kinds == ["normal", "corner", "normal"]
    assert kept.edges.tolist() == [[0, 1], [1, 2], [3, 4]]
    assert np.allclose(kept.edge_scores, [0.9, 1.0, 0.8]) and kept.edge_patches.tolist() == [[0, 0], [0, 0], [0, 1]]
    assert np.allclose(kept.edge_polyline(1), [(3, 0), (7, 0), (7, 4), (3, 4)])
    assert drop_short_fragments(three_pieces(), 15.5).n_edges == 0
    assert (
        drop_short_fragments(three_pieces(), 0.0) is not None and drop_short_fragments(three_pieces(), 0.0).n_edges == 4
    )


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 11), st.integers(0, 11)), min_size=0, max_size=20), st.floats(0, 40))
def test_every_kept_edge_lies_in_a_long_enough_piece_and_no_long_piece_loses_an_edge(pairs, limit):
    rng = np.random.default_rng(len(pairs))
    graph = BoundaryGraph(rng.uniform(0, 30, (12, 2)), np.array(pairs, dtype=np.int64).reshape(-1, 2))
    piece, length = fragment_lengths(graph)
    kept = drop_short_fragments(graph, limit)
    expected = int((length[piece] >= limit).sum()) if limit > 0 else graph.n_edges
    assert kept.n_edges == expected
    assert np.isclose(
        kept.edge_lengths().sum(),
        graph.edge_lengths()[length[piece] >= limit].sum() if limit > 0 else graph.edge_lengths().sum(),
    )
