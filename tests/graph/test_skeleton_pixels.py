"""The skeleton pixel graph: nodes in raster order, 8-neighbour links, optional corner diagonals."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csgraph

from csboundary.graph.skeleton_pixels import skeleton_distance_graph, skeleton_pixel_links


def l_corner() -> np.ndarray:
    skeleton = np.zeros((5, 5), bool)
    skeleton[2, 1:4] = True
    skeleton[1, 3] = True  # (2,3)-(1,3) orthogonal; (2,2)-(1,3) diagonal beside it
    return skeleton


def test_nodes_are_the_pixels_in_raster_order():
    pixels, _, _ = skeleton_pixel_links(l_corner())
    assert pixels.tolist() == [[1, 3], [2, 1], [2, 2], [2, 3]]


def test_a_corner_diagonal_is_kept_for_distances_and_left_out_for_chains():
    pixels, links, lengths = skeleton_pixel_links(l_corner())
    named = {tuple(sorted((tuple(pixels[a]), tuple(pixels[b])))): d for (a, b), d in zip(links.tolist(), lengths)}
    assert named == {
        ((2, 1), (2, 2)): 1.0,
        ((2, 2), (2, 3)): 1.0,
        ((1, 3), (2, 3)): 1.0,
        ((1, 3), (2, 2)): np.sqrt(2.0),
    }
    _, links, lengths = skeleton_pixel_links(l_corner(), corner_diagonals=False)
    assert len(links) == 3 and np.all(lengths == 1.0)


def test_distances_along_a_staircase():
    skeleton = np.eye(6, dtype=bool)  # a diagonal line: 5 diagonal steps
    skeleton[0, 1] = True  # and one pixel beside its first step
    pixels, graph = skeleton_distance_graph(skeleton)
    dist = csgraph.dijkstra(graph, directed=False, indices=0)
    last = int(np.flatnonzero((pixels == [5, 5]).all(axis=1))[0])
    assert np.isclose(dist[last], 5 * np.sqrt(2.0))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=36, max_size=36), st.booleans())
def test_links_join_exactly_the_8_neighbour_pairs(cells, corner_diagonals):
    mask = np.array(cells).reshape(6, 6)
    pixels, links, lengths = skeleton_pixel_links(mask, corner_diagonals)
    found = {frozenset((tuple(pixels[a]), tuple(pixels[b]))) for a, b in links.tolist()}
    assert len(found) == len(links)  # each pair once
    on = {tuple(p) for p in pixels.tolist()}
    expected = set()
    for r, c in on:
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                q = (r + dr, c + dc)
                if (dr or dc) and q in on:
                    beside = (r, c + dc) in on or (r + dr, c) in on
                    if dr == 0 or dc == 0 or corner_diagonals or not beside:
                        expected.add(frozenset(((r, c), q)))
    assert found == expected
    for (a, b), d in zip(links.tolist(), lengths):
        assert np.isclose(d, np.hypot(*(pixels[a] - pixels[b])))
