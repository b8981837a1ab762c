"""Graphs cut to the imagery's window before the metrics walk along them (metrics/graph_clip.py)."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.metrics import evaluate
from csboundary.metrics.graph_clip import clip_graph, clip_polyline, grown

WINDOW = (0.0, 0.0, 100.0, 100.0)


def test_a_polyline_leaving_and_coming_back_gives_two_runs_ending_on_the_border():
    line = np.array([[10.0, 50.0], [150.0, 50.0], [150.0, 80.0], [50.0, 80.0], [50.0, 90.0]])
    first, second = clip_polyline(line, WINDOW)
    assert first.from_start and not first.to_end
    np.testing.assert_allclose(first.points, [[10, 50], [100, 50]])
    assert not second.from_start and second.to_end
    np.testing.assert_allclose(second.points, [[100, 80], [50, 80], [50, 90]])
    assert clip_polyline(np.array([[200.0, 0.0], [300.0, 0.0]]), WINDOW) == []


def test_a_graph_inside_is_returned_as_it_is():
    graph = BoundaryGraph([[1, 1], [50, 50], [99, 1]], [[0, 1], [1, 2]], edge_scores=np.array([0.2, 0.9]))
    assert clip_graph(graph, WINDOW) is graph


def test_a_far_edge_is_cut_at_the_border_keeping_vertices_inside_and_each_edges_fields():
    graph = BoundaryGraph(
        [[10, 10], [50, 10], [1e9, 10], [-5e8, -5e8]],
        [[0, 1], [1, 2], [2, 3]],
        edge_kinds=["a", "b", "c"],
        edge_scores=np.array([0.1, 0.7, 0.3]),
        vertex_kinds=["x", "y", "z", "w"],
    )
    cut = clip_graph(graph, WINDOW)
    np.testing.assert_allclose(cut.vertices, [[10, 10], [50, 10], [100, 10]])
    np.testing.assert_array_equal(cut.edges, [[0, 1], [1, 2]])  # the far edge (2, 3) misses the window: gone
    assert cut.edge_kinds == ["a", "b"] and cut.vertex_kinds == ["x", "y", ""]
    np.testing.assert_allclose(cut.edge_scores, [0.1, 0.7])
    assert cut.edge_lengths().sum() == pytest.approx(90.0)


def test_a_polyline_stored_backwards_keeps_its_vertices():
    graph = BoundaryGraph(
        [[20, 20], [500, 20]], [[0, 1]], edge_polylines=[np.array([[500.0, 20.0], [300.0, 60.0], [20.0, 20.0]])]
    )
    cut = clip_graph(graph, WINDOW)
    assert cut.n_edges == 1
    np.testing.assert_allclose(cut.vertices[cut.edges[0, 1]], [20, 20])  # the polyline's end, still vertex 0's point
    line = cut.edge_polyline(0)
    np.testing.assert_allclose(line[-1], [20, 20])
    assert line[0][0] == pytest.approx(100.0)


def test_metrics_of_a_line_far_outside_are_those_of_its_part_inside():
    """Cutting to the window first changes no score of what lies in the imagery."""
    pred = BoundaryGraph.from_polylines(
        [np.array([[5.0, 20.0], [95.0, 20.0]]), np.array([[5.0, 60.0], [95.0, 62.0]])], scores=[0.9, 0.2]
    )
    far = BoundaryGraph.from_polylines([np.array([[5.0, 21.0], [4e8, 21.0], [4e8, 7e8]])])
    near = BoundaryGraph.from_polylines(
        [np.array([[5.0, 21.0], [grown(WINDOW)[2], 21.0]])]
    )  # cut by hand where the metrics look
    a = evaluate(pred, far, extent=WINDOW)
    b = evaluate(pred, near, extent=WINDOW)
    assert a["metrics"] == pytest.approx(b["metrics"], nan_ok=True)
    assert a["confidence"]["auc"] == pytest.approx(b["confidence"]["auc"], nan_ok=True)
    assert a["review_effort"]["true_boundary_px"] == pytest.approx(b["review_effort"]["true_boundary_px"])
