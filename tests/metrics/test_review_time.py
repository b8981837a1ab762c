"""The simulated review by boundary: costs worked out by hand, and F1@5 tracked as the pixel metric
defines it.

The hand-built case (costs: look 1 s + 0.5 s per 20 m, delete 1 s, click 1.5 s, find 2 s; 0.2 m
per pixel, so eye travel is 0.005 s per px): ground truth is two straight lines, y = 10 and
y = 60, x 0 -> 200 (400 px). The prediction:

* four edges along y = 11, x 0 -> 50 -> 100 -> 150 -> 200: one boundary of 200 px, confidence
  (length-weighted) 0.825, true;
* one edge along y = 60, x 0 -> 100: a boundary of 100 px, confidence 0.6, true (half the second line);
* one edge along y = 150, x 0 -> 100: a boundary of 100 px, confidence 0.1, false.

The review draft keeps a boundary when p x seconds to draw it > its look + (1 - p) x a delete:
the first 0.825 x (2 + 2 x 1.5 + 1.0) = 4.95 > 2.0 + 0.175, the second 0.6 x 5.5 = 3.3 > 1.5 +
0.4, the third 0.1 x 5.5 = 0.55 < 1.5 + 0.9: held back. Looking at the draft costs 2.0 + 1.5 =
3.5 s. Missing is the second line from x ~ 104.5 to 199.5: found (2 s), its left end snaps onto
the kept line, so one click (1.5 s), and 95 px of eye travel (0.475 s). From scratch: each line
is found, clicked twice and followed over its 199 px of samples: 2 x 5.995 s.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph import BoundaryGraph
from csboundary.metrics import evaluate, pixel_scores
from csboundary.metrics.io import load_pair
from csboundary.metrics.review_time import (
    ReviewCosts,
    boundary_samples,
    clicks_to_trace,
    graph_boundaries,
    keeps_boundary,
    missing_runs,
    review_draft,
    review_order,
    review_report,
    scratch_clicks,
)
from csboundary.pipeline.outputs.prediction_files import write_graph_outputs

HAND = ReviewCosts(look_s=1.0, look_s_per_20m=0.5, delete_s=1.0, vertex_s=1.5, find_s=2.0, trace_tolerance_px=2.0)


def graph(lines, scores=None) -> BoundaryGraph:
    return BoundaryGraph.from_polylines([np.asarray(line, float) for line in lines], scores=scores)  # a score per line


GT = graph([[[0, 10], [200, 10]], [[0, 60], [200, 60]]])
PRED_LINES = [
    [[0, 11], [50, 11]],
    [[50, 11], [100, 11]],
    [[100, 11], [150, 11]],
    [[150, 11], [200, 11]],
    [[0, 60], [100, 60]],
    [[0, 150], [100, 150]],
]


def test_hand_case_costs():
    pred = graph(PRED_LINES, [0.9, 0.8, 0.9, 0.7, 0.6, 0.1])
    r = review_report(pred, GT, metres_per_px=0.2, costs=HAND)
    assert (r["boundaries"], r["draft_boundaries"], r["held_back_boundaries"]) == (3, 2, 1)
    assert r["false_boundaries"] == 0 and r["scratch_clicks"] == 4
    assert r["scratch_minutes"] == pytest.approx(2 * 5.995 / 60, abs=0.02 / 60)
    assert r["true_boundary_km"] == pytest.approx(400 * 0.2 / 1000)
    conf = r["orders"]["confidence"]
    assert conf["look_minutes"] == pytest.approx(3.5 / 60)
    assert conf["clicks"] == 1 and conf["draw_minutes"] == pytest.approx(3.975 / 60, abs=0.02 / 60)
    assert conf["minutes_to_target_f1"] == pytest.approx(3.975 / 60, abs=0.02 / 60)  # nothing to delete: draw at once
    assert conf["end_f1"] == pytest.approx(1.0)
    assert conf["start_f1"] == pytest.approx(
        pixel_scores(pred.edge_subgraph(np.arange(6) < 5), GT)[5.0][2]
    )  # the draft's F1
    assert r["orders"]["random"]["minutes"] == pytest.approx(conf["minutes"])


def test_keeps_boundary_weighs_the_saving_against_the_look_and_the_delete():
    line = np.array([[0.0, 0.0], [100.0, 0.0]])  # 20 m at 0.2 m: drawn in 2 + 2 x 1.5 + 0.5 = 5.5 s, looked at in 1.5 s
    assert keeps_boundary(0.6, line, HAND, 0.2)  # 3.3 > 1.5 + 0.4
    assert not keeps_boundary(0.3, line, HAND, 0.2)  # 1.65 < 1.5 + 0.7
    assert keeps_boundary(float("nan"), line, HAND, 0.2)  # nothing says it does not pay
    # p x 5.5 = 1.5 + (1 - p) x 1 at p = 2.5 / 6.5
    assert keeps_boundary(2.5 / 6.5 + 1e-6, line, HAND, 0.2) and not keeps_boundary(2.5 / 6.5 - 1e-6, line, HAND, 0.2)


def test_a_boundary_with_a_long_detour_gets_a_cut_and_a_delete():
    """Along y = 11 for 150 px, then 30 px down a side street that is not there: true (150 of
    180 px on the truth), its last ~25 px off it: one cut (it is the boundary's end, so one
    inner end) and a delete; what stays is on the truth."""
    gt = graph([[[0, 10], [200, 10]]])
    pred = BoundaryGraph(
        np.array([[0.0, 11.0], [150.0, 40.0]]),
        [[0, 1]],
        edge_scores=np.array([0.9]),
        edge_polylines=[np.array([[0.0, 11.0], [150.0, 11.0], [150.0, 40.0]])],
    )
    r = review_report(pred, gt, metres_per_px=0.2, costs=HAND)
    conf = r["orders"]["confidence"]
    assert r["false_boundaries"] == 0 and r["cut_pieces"] == 1
    assert conf["look_minutes"] == pytest.approx((1.0 + 179 * 0.005 + 1.5 + 1.0) / 60)
    assert conf["end_f1"] == pytest.approx(1.0, abs=0.005)  # a pixel at the cut may stay off the truth
    assert pixel_scores(pred, gt)[5.0][0] < 0.9  # before: the stray pixels count against precision


def test_a_short_stray_gets_a_vertex_moved():
    """A bump 9 px out in the middle of a true line, about 12 px of it off the truth: shorter
    than cut_px (20 px), so one vertex moved (a click), no cut."""
    gt = graph([[[0, 10], [300, 10]]])
    line = np.array([[0.0, 10.0], [142.0, 10.0], [144.0, 19.0], [148.0, 19.0], [150.0, 10.0], [300.0, 10.0]])
    pred = BoundaryGraph(line[[0, -1]], [[0, 1]], edge_scores=np.array([0.9]), edge_polylines=[line])
    r = review_report(pred, gt, metres_per_px=0.2, costs=HAND)
    length = float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())
    assert r["cut_pieces"] == 0
    assert r["orders"]["confidence"]["look_minutes"] == pytest.approx((1.0 + length * 0.005 + 1.5) / 60)


def test_same_minutes_from_graph_json_geopackage_and_geojson(tmp_path):
    """The boundaries are rebuilt from the lines' shared ends and their confidence read from the
    file, so the three files of one prediction cost the same."""
    transform = Affine(0.2, 0.0, 500000.0, 0.0, -0.2, 4500000.0)
    lines = PRED_LINES + [[[100, 11], [100, 60]], [[0, 100], [40, 130], [90, 131.5]]]  # a junction, and a bent boundary
    pred = graph(lines, [0.9, 0.8, 0.9, 0.7, 0.6, 0.1, 0.45, 0.7])
    pred = dataclasses.replace(pred, transform=transform, crs="EPSG:32618")
    paths = write_graph_outputs(pred, tmp_path / "pred")
    dataclasses.replace(GT, transform=transform, crs="EPSG:32618").write_json(tmp_path / "gt.json")
    reports = {}
    for key in ("graph_json", "gpkg", "geojson"):
        p, g, _ = load_pair(paths[key], tmp_path / "gt.json")
        reports[key] = review_report(p, g, metres_per_px=0.2)
    first = reports["graph_json"]
    assert first["boundaries"] == 5 and "confidence" in first["orders"]
    for other in reports.values():
        assert other["boundaries"] == first["boundaries"] and other["draft_boundaries"] == first["draft_boundaries"]
        for order in first["orders"]:
            assert other["orders"][order]["minutes"] == pytest.approx(first["orders"][order]["minutes"], rel=1e-9)
            assert other["orders"][order]["minutes_to_target_f1"] == pytest.approx(
                first["orders"][order]["minutes_to_target_f1"], rel=1e-9
            )


def test_without_a_confidence_only_the_random_order_and_the_whole_prediction():
    pred = graph(PRED_LINES)
    r = review_report(pred, GT, metres_per_px=0.2, costs=HAND)
    assert list(r["orders"]) == ["random"] and "note" in r
    assert r["draft_boundaries"] == r["boundaries"] == 3 and r["false_boundaries"] == 1


def test_curve_starts_at_the_pixel_f1_and_rises_when_false_edges_go():
    pred = graph(PRED_LINES, [0.9, 0.8, 0.9, 0.7, 0.6, 0.4])
    r = review_report(
        pred, GT, costs=dataclasses.replace(HAND, look_s=0.1)
    )  # every boundary pays its look: the false one is shown
    assert r["held_back_boundaries"] == 0
    curve = r["orders"]["confidence"]["curve"]
    assert curve["f1"][0] == pytest.approx(pixel_scores(pred, GT)[5.0][2])
    assert np.all(np.diff(curve["minutes"]) >= 0)
    assert curve["f1"][-1] > curve["f1"][0]


def test_a_perfect_draft_costs_the_looks_only():
    pred = graph([[[0, 10], [200, 10]], [[0, 60], [200, 60]]], [0.5, 0.5])
    r = review_report(pred, GT, metres_per_px=0.2, costs=HAND)
    conf = r["orders"]["confidence"]
    assert conf["clicks"] == 0 and conf["minutes"] == pytest.approx(2 * (1.0 + 200 * 0.005) / 60)
    assert conf["minutes_to_target_f1"] == 0.0  # already at F1 1


def test_an_empty_draft_is_drawn_from_scratch():
    empty = BoundaryGraph(np.zeros((0, 2)), np.zeros((0, 2), np.int64))
    r = review_report(empty, GT)
    assert r["orders"]["random"]["clicks"] == r["scratch_clicks"]
    assert r["orders"]["random"]["minutes"] == pytest.approx(r["scratch_minutes"])


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


def test_review_order_and_boundary_confidence():
    pred = graph(PRED_LINES, [0.9, 0.8, np.nan, 0.7, 0.6, 0.1])
    confidence = [b.confidence for b in graph_boundaries(pred)]
    assert confidence == pytest.approx([0.8, 0.6, 0.1])  # the first boundary: its three scored edges, of equal length
    assert review_order(np.array([0.8, np.nan, 0.1]), "confidence").tolist() == [2, 0, 1]  # no confidence last
    assert sorted(review_order(np.array(confidence), "random", seed=3).tolist()) == [0, 1, 2]
    with pytest.raises(ValueError):
        review_order(np.array(confidence), "longest")


def test_evaluate_reports_review_effort_at_city_scale():
    pred = graph(PRED_LINES, [0.9, 0.8, 0.9, 0.7, 0.6, 0.1])
    result = evaluate(pred, GT, scale="city", metres_per_px=0.152)
    review = result["review_effort"]
    assert review["held_back_boundaries"] == 1  # the false line at 0.1: its review starts from the draft without it
    draft_f1 = pixel_scores(pred.edge_subgraph(np.arange(pred.n_edges) < 5), GT)[5.0][2]
    assert (
        review["orders"]["confidence"]["start_f1"] == pytest.approx(draft_f1) and draft_f1 > result["metrics"]["f1@5"]
    )
    assert "review_effort" not in evaluate(pred, GT, scale="city", review=None)


@settings(max_examples=25, deadline=None)
@given(
    st.lists(
        st.tuples(st.integers(0, 120), st.integers(0, 120), st.integers(0, 120), st.integers(0, 120)),
        min_size=1,
        max_size=8,
    ),
    st.integers(0, 2**16),
)
def test_review_ends_near_f1_one_and_starts_at_pixel_f1(segments, seed):
    """Any prediction: the curve starts at the pixel F1@5 of its review draft; after the full review every run of the
    ground truth is drawn, so recall is 1, and what is kept is the true edges plus the traced
    runs (F1 below 1 only by the parts of kept true edges that stray off the truth)."""
    rng = np.random.default_rng(seed)
    lines = [[[a, b], [c, d]] for a, b, c, d in segments if (a, b) != (c, d)]
    if not lines:
        return
    pred = graph(lines)  # duplicate segments merge: one score per edge left
    pred = dataclasses.replace(pred, edge_scores=rng.random(pred.n_edges))
    r = review_report(pred, GT, seed=seed)
    boundaries = graph_boundaries(pred)
    shown = review_draft(boundaries, ReviewCosts(), ReviewCosts().assumed_metres_per_px)
    in_draft = np.zeros(pred.n_edges, bool)
    for b, keep in zip(boundaries, shown):
        in_draft[b.edges] = keep
    for order in r["orders"].values():
        if in_draft.any():
            assert order["start_f1"] == pytest.approx(pixel_scores(pred.edge_subgraph(in_draft), GT)[5.0][2], abs=1e-9)
        assert order["end_f1"] >= order["start_f1"] - 1e-9
        assert order["end_f1"] > 0.8
