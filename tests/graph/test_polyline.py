"""Polyline geometry: arc length, the nearest point on a polyline, cutting one in two."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph.polyline import nearest_on_polyline, polyline_length, segment_feet, split_polyline

L = np.array([[0.0, 0], [10, 0], [10, 20]])  # an L: 10 px east, then 20 px south


def test_segment_feet_by_hand():
    t, foot, d = segment_feet(
        np.array([[0.0, 0], [0, 0]]), np.array([[10.0, 0], [10, 0]]), np.array([[4.0, 3], [-6, 8]])
    )
    assert t.tolist() == [0.4, 0.0] and foot.tolist() == [[4, 0], [0, 0]] and d.tolist() == [3, 10]


def test_nearest_on_polyline_by_hand():
    distance, k, foot = nearest_on_polyline(L, np.array([13.0, 15]))
    assert (distance, k, foot.tolist()) == (3.0, 1, [10, 15])
    distance, k, foot = nearest_on_polyline(L, np.array([4.0, -2]))
    assert (distance, k, foot.tolist()) == (2.0, 0, [4, 0])
    distance, k, foot = nearest_on_polyline(
        L, np.array([13.0, -4])
    )  # beyond the corner: the corner itself, first segment
    assert (distance, k, foot.tolist()) == (5.0, 0, [10, 0])


def test_split_polyline_by_hand():
    head, tail = split_polyline(L, 1, np.array([10.0, 5]))
    assert head.tolist() == [[0, 0], [10, 0], [10, 5]] and tail.tolist() == [[10, 5], [10, 20]]
    head, tail = split_polyline(L, 0, np.array([10.0, 0]))  # at a corner: not repeated
    assert head.tolist() == [[0, 0], [10, 0]] and tail.tolist() == [[10, 0], [10, 20]]


coords = st.floats(-500, 500, allow_nan=False, width=32)


@settings(max_examples=80, deadline=None)
@given(points=st.lists(st.tuples(coords, coords), min_size=2, max_size=8), q=st.tuples(coords, coords))
def test_a_cut_at_the_nearest_point_keeps_the_length_and_meets_there(points, q):
    line = np.array(points, float)
    distance, k, foot = nearest_on_polyline(line, np.array(q, float))
    vertices_distance = np.linalg.norm(line - np.array(q), axis=1).min()
    assert distance <= vertices_distance + 1e-6  # never farther than the nearest vertex
    head, tail = split_polyline(line, k, foot)
    assert np.array_equal(head[-1], foot) and np.array_equal(tail[0], foot)
    assert np.array_equal(head[0], line[0]) and np.array_equal(tail[-1], line[-1])
    assert np.isclose(polyline_length(head) + polyline_length(tail), polyline_length(line), rtol=1e-9, atol=1e-6)
