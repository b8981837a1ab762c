"""The simulated review: costs worked out by hand, and F1@5 tracked as the pixel metric defines it.

The hand-built case (costs: look 3 s, delete 1 s, click 1.5 s): ground truth is two straight
lines, y = 10 and y = 60, x 0 -> 200 (400 px). The prediction:

* four edges along y = 11, x 0 -> 50 -> 100 -> 150 -> 200 (true; the first line is found);
* one edge along y = 60, x 0 -> 100 (true; half the second line);
* one edge along y = 150, x 0 -> 100 (false), the least sure.

A full review looks at 6 edges and deletes 1: 6 x 3 + 1 = 19 s. What is missing is the second
line from x = 100 to 200: one run, found with a look (3 s), whose left end meets the kept edge
(snapped, free) and whose straight run needs its right end only: 1 click, 1.5 s. Drawing from
scratch is 2 lines, each a look and 2 clicks: 12 s. Least sure first, the reviewer finds the
false edge first (4 s), may stop there and draw (4.5 s): F1@5 1 after 8.5 s.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph import BoundaryGraph
from csboundary.metrics import evaluate, pixel_scores
from csboundary.metrics.review_time import (ReviewCosts, boundary_samples, clicks_to_trace, missing_runs, review_order, review_report,
                                            scratch_clicks)


HAND = ReviewCosts(look_s=3.0, delete_s=1.0, vertex_s=1.5, trace_tolerance_px=2.0)


def graph(lines, scores=None) -> BoundaryGraph:
    g = BoundaryGraph.from_polylines([np.asarray(line, float) for line in lines])
    return dataclasses.replace(g, edge_scores=np.asarray(scores, float)) if scores is not None else g


GT = graph([[[0, 10], [200, 10]], [[0, 60], [200, 60]]])
PRED_LINES = [[[0, 11], [50, 11]], [[50, 11], [100, 11]], [[100, 11], [150, 11]], [[150, 11], [200, 11]], [[0, 60], [100, 60]],
              [[0, 150], [100, 150]]]


def test_hand_case_costs():
    pred = graph(PRED_LINES, [0.9, 0.8, 0.9, 0.7, 0.6, 0.1])
    r = review_report(pred, GT, metres_per_px=0.2, costs=HAND)
    assert r["false_edges"] == 1 and r["scratch_clicks"] == 4
    assert r["scratch_minutes"] == pytest.approx(12 / 60)
    assert r["true_boundary_km"] == pytest.approx(400 * 0.2 / 1000)
    conf = r["orders"]["confidence"]
    assert conf["look_minutes"] == pytest.approx(19 / 60)
    assert conf["clicks"] == 1 and conf["draw_minutes"] == pytest.approx(4.5 / 60)
    assert conf["minutes_to_target_f1"] == pytest.approx(8.5 / 60)
    assert conf["end_f1"] == pytest.approx(1.0)
    assert r["per_km"]["scratch_minutes"] == pytest.approx(12 / 60 / 0.08)
    # both orders look at every edge for the fully corrected map; only the way there differs
    assert r["orders"]["random"]["minutes"] == pytest.approx(conf["minutes"])
    assert r["orders"]["random"]["minutes_to_target_f1"] >= conf["minutes_to_target_f1"]


def test_curve_starts_at_the_pixel_f1_and_rises_when_false_edges_go():
    pred = graph(PRED_LINES, [0.9, 0.8, 0.9, 0.7, 0.6, 0.1])
    r = review_report(pred, GT)
    curve = r["orders"]["confidence"]["curve"]
    assert curve["f1"][0] == pytest.approx(pixel_scores(pred, GT)[5.0][2])
    assert np.all(np.diff(curve["minutes"]) >= 0)
    assert curve["f1"][-1] > curve["f1"][0]


def test_a_perfect_draft_costs_the_looks_only():
    pred = graph([[[0, 10], [200, 10]], [[0, 60], [200, 60]]], [0.5, 0.5])
    r = review_report(pred, GT, costs=ReviewCosts(look_s=2.0))
    conf = r["orders"]["confidence"]
    assert conf["clicks"] == 0 and conf["minutes"] == pytest.approx(4 / 60)
    assert conf["minutes_to_target_f1"] == 0.0  # already at F1 1


def test_an_empty_draft_is_drawn_from_scratch():
    empty = BoundaryGraph(np.zeros((0, 2)), np.zeros((0, 2), np.int64))
    r = review_report(empty, GT)
    assert r["orders"]["random"]["clicks"] == r["scratch_clicks"]
    assert r["orders"]["random"]["minutes"] == pytest.approx(r["scratch_minutes"])


def test_a_true_edge_that_strays_gets_a_vertex_moved_onto_the_truth():
    """Along y = 10 for 150 px, then 30 px down a side street that is not there: true (150 of
    180 px on the truth), but 25 px stray. The reviewer moves one vertex (a look and a click);
    what stays is on the truth, so precision is 1."""
    gt = graph([[[0, 10], [200, 10]]])
    pred = BoundaryGraph(np.array([[0.0, 11.0], [150.0, 40.0]]), [[0, 1]], edge_scores=np.array([0.7]),
                         edge_polylines=[np.array([[0.0, 11.0], [150.0, 11.0], [150.0, 40.0]])])  # one edge, bent
    r = review_report(pred, gt, costs=HAND)
    conf = r["orders"]["confidence"]
    assert r["false_edges"] == 0
    assert conf["look_minutes"] == pytest.approx((3.0 + 1.5) / 60)
    assert conf["end_f1"] == pytest.approx(1.0)
    assert pixel_scores(pred, gt)[5.0][0] < 0.9  # before: the stray pixels count against precision


def test_clicks_to_trace():
    assert clicks_to_trace(np.array([[0, 0], [50, 0.5], [100, 0]]), 2.0) == 2  # within tolerance of a straight line
    assert clicks_to_trace(np.array([[0, 0], [50, 0], [50, 50]]), 2.0) == 3  # a corner
    square = np.array([[0, 0], [40, 0], [40, 40], [0, 40], [0, 0]], float)
    assert clicks_to_trace(square, 2.0) == 4  # closed: the first vertex is clicked once
    arc = np.stack([100 * np.cos(np.linspace(0, np.pi / 2, 200)), 100 * np.sin(np.linspace(0, np.pi / 2, 200))], axis=1)
    assert clicks_to_trace(arc, 0.5) > clicks_to_trace(arc, 4.0) >= 3  # a tighter tolerance takes more clicks


def test_scratch_clicks_follow_chains_through_degree_two_vertices():
    one = graph([[[0, 0], [50, 0]], [[50, 0], [100, 0]]])  # two edges, one straight boundary
    assert scratch_clicks(one, 2.0) == 2


def test_missing_runs_snap_to_kept_lines():
    kept = np.stack([np.arange(0, 101), np.full(101, 60)], axis=1)  # x 0..100 on y = 60
    runs = missing_runs(boundary_samples(graph([[[0, 60], [200, 60]]])), kept, 5.0)
    assert len(runs) == 1
    run, snapped = runs[0]
    assert snapped == 1  # the left end meets the kept line, the right end is free
    assert run[0, 0] == pytest.approx(104.5, abs=1.0) and run[-1, 0] == pytest.approx(199.5, abs=1.0)


def test_review_order():
    pred = graph(PRED_LINES, [0.9, 0.8, np.nan, 0.7, 0.6, 0.1])
    assert review_order(pred, "confidence").tolist() == [5, 4, 3, 1, 0, 2]  # unscored last
    assert sorted(review_order(pred, "random", seed=3).tolist()) == list(range(6))
    with pytest.raises(ValueError):
        review_order(pred, "longest")


def test_evaluate_reports_review_effort_at_city_scale():
    pred = graph(PRED_LINES, [0.9, 0.8, 0.9, 0.7, 0.6, 0.1])
    result = evaluate(pred, GT, scale="city", metres_per_px=0.152)
    assert result["review_effort"]["orders"]["confidence"]["start_f1"] == pytest.approx(result["metrics"]["f1@5"])
    assert "review_effort" not in evaluate(pred, GT, scale="city", review=None)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 120), st.integers(0, 120), st.integers(0, 120), st.integers(0, 120)), min_size=1, max_size=8),
       st.integers(0, 2**16))
def test_review_ends_near_f1_one_and_starts_at_pixel_f1(segments, seed):
    """Any draft: the curve starts at the pixel F1@5; after the full review every run of the
    ground truth is drawn, so recall is 1, and what is kept is the true edges plus the traced
    runs (F1 below 1 only by the parts of kept true edges that stray off the truth)."""
    rng = np.random.default_rng(seed)
    lines = [[[a, b], [c, d]] for a, b, c, d in segments if (a, b) != (c, d)]
    if not lines:
        return
    pred = graph(lines)  # duplicate segments merge: one score per edge left
    pred = dataclasses.replace(pred, edge_scores=rng.random(pred.n_edges))
    r = review_report(pred, GT, seed=seed)
    for order in r["orders"].values():
        assert order["start_f1"] == pytest.approx(pixel_scores(pred, GT)[5.0][2], abs=1e-9)
        assert order["end_f1"] >= order["start_f1"] - 1e-9
        assert order["end_f1"] > 0.8
