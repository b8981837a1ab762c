"""threshold -> skeleton -> graph on drawn masks with known graphs."""

from __future__ import annotations

import cv2
import numpy as np

from csboundary.graph.skeleton_graph import SkeletonConfig, skeleton_graph


def drawn(lines, shape=(200, 200), width=3) -> np.ndarray:
    img = np.zeros(shape, np.uint8)
    for line in lines:
        cv2.polylines(img, [np.asarray(line, np.int32)], False, 1, width)
    return img.astype(float)


def test_a_straight_line_is_one_edge_between_its_ends():
    g = skeleton_graph(drawn([[(20, 100), (180, 100)]]))
    assert g.n_vertices == 2 and g.n_edges == 1
    xs = sorted(g.vertices[:, 0])
    assert abs(xs[0] - 20.5) <= 2 and abs(xs[1] - 180.5) <= 2
    assert np.allclose(g.vertices[:, 1], 100.5, atol=1)
    assert len(g.edge_polyline(0)) == 2  # simplified to its two ends


def test_a_t_junction_has_three_edges_meeting_at_one_vertex():
    g = skeleton_graph(drawn([[(20, 100), (180, 100)], [(100, 100), (100, 20)]]))
    assert g.n_edges == 3
    degree = np.bincount(g.edges.ravel())
    assert sorted(degree.tolist()) == [1, 1, 1, 3]
    junction = g.vertices[np.argmax(degree)]
    assert np.hypot(*(junction - [100.5, 100.5])) <= 3


def test_a_ring_is_a_closed_edge_and_spurs_and_specks_go():
    ring = [[(50, 50), (150, 50), (150, 150), (50, 150), (50, 50)]]
    mask = drawn(ring)
    mask[10:13, 10:13] = 1  # a speck
    g = skeleton_graph(mask)
    assert g.n_edges == 1 and g.edges[0, 0] == g.edges[0, 1]  # one closed chain
    assert abs(g.edge_lengths()[0] - 400) <= 12
    spur = drawn(ring + [[(100, 150), (100, 156)]])
    assert skeleton_graph(spur).n_edges == 1  # the 6 px spur is removed
    # a 40 px branch stays: the ring (now a loop through the junction) + the branch
    assert skeleton_graph(drawn(ring + [[(100, 150), (100, 190)]])).n_edges == 2


def test_an_empty_map_gives_an_empty_graph():
    assert skeleton_graph(np.zeros((50, 50))).n_edges == 0
    assert skeleton_graph(np.full((50, 50), 0.4), SkeletonConfig(threshold=0.5)).n_vertices == 0
