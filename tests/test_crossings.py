"""Grid-crossing vertices: where the boundary map's skeleton crosses the window's grid lines."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.graph.crossings import CrossingConfig, _run_centres, crossing_points


def test_runs_have_their_centres():
    assert _run_centres(np.array([0, 1, 1, 1, 0, 0, 1, 0], bool)) == [2.0, 6.0]
    assert _run_centres(np.zeros(5, bool)) == []


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
