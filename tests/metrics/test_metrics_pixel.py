"""Relaxed pixel precision / recall / F1: rasterisation and hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from csboundary.graph import BoundaryGraph
from csboundary.metrics import pixel_scores
from csboundary.metrics.pixel import f1_score, rasterize, relaxed_scores
from csboundary.metrics.sampling import flatten


def lines(*polylines, dy: float = 0.0) -> BoundaryGraph:
    return BoundaryGraph.from_polylines([np.asarray(p, dtype=float) + [0.0, dy] for p in polylines])


TWO_STREETS = ([[10.5, 10.5], [110.5, 10.5]], [[10.5, 50.5], [110.5, 50.5]])


def test_raster_is_one_pixel_wide_and_8_connected():
    px = rasterize(flatten(lines([[0.5, 0.5], [10.5, 4.5]])))
    # 10 steps along the major axis -> 11 pixels, one per column, rows within 0..4
    assert len(px) == 11 and sorted(px[:, 0].tolist()) == list(range(11))
    assert px[:, 1].min() == 0 and px[:, 1].max() == 4
    order = np.argsort(px[:, 0])
    assert np.abs(np.diff(px[order], axis=0)).max() == 1  # 8-connected


def test_raster_uses_pixel_index_floor_and_skips_isolated_vertices():
    g = BoundaryGraph(np.array([[3.9, 7.2], [6.1, 7.8], [50.0, 50.0]]), np.array([[0, 1]]))
    assert rasterize(flatten(g)).tolist() == [[3, 7], [4, 7], [5, 7], [6, 7]]


def test_identical_graphs_score_one():
    scores = pixel_scores(lines(*TWO_STREETS), lines(*TWO_STREETS))
    assert all(v == (1.0, 1.0, 1.0) for v in scores.values())


def test_three_pixel_shift_fails_tau_2_and_passes_tau_5():
    # Both streets move down 3 px: every predicted pixel is exactly 3 px from its ground-truth
    # twin (same column) and further from every other one. 3 < 2 is false, 3 < 5 is true.
    scores = pixel_scores(lines(*TWO_STREETS, dy=3), lines(*TWO_STREETS))
    assert scores[2.0] == (0.0, 0.0, 0.0)
    assert scores[5.0] == (1.0, 1.0, 1.0)
    assert scores[10.0] == (1.0, 1.0, 1.0)


def test_tau_is_strict():
    # a 2 px shift: distance exactly 2 is not < 2
    scores = pixel_scores(lines(*TWO_STREETS, dy=2), lines(*TWO_STREETS), taus=(2, 2.01))
    assert scores[2.0][0] == 0.0 and scores[2.01][0] == 1.0


def test_extra_boundary_lowers_precision_only():
    # ground truth: 101 + 101 pixels; prediction adds a third street of 101 pixels 200 px away
    extra = [[10.5, 250.5], [110.5, 250.5]]
    scores = pixel_scores(lines(*TWO_STREETS, extra), lines(*TWO_STREETS))
    p, r, f = scores[5.0]
    assert p == pytest.approx(202 / 303) and r == 1.0 and f == pytest.approx(2 * p / (p + 1))


def test_gap_lowers_recall_by_hand():
    # ground truth 0..100 on one row = 101 pixels; prediction misses columns 41..59 (two pieces
    # 0..40 and 60..100). Recall at tau 5: columns 41..44 and 56..59 are within 4 px -> 101 - 11 = 90.
    gt = lines([[0.5, 0.5], [100.5, 0.5]])
    pred = lines([[0.5, 0.5], [40.5, 0.5]], [[60.5, 0.5], [100.5, 0.5]])
    p, r, _ = pixel_scores(pred, gt)[5.0]
    assert p == 1.0 and r == pytest.approx(90 / 101)


def test_empty_cases():
    gt_px = rasterize(flatten(lines(*TWO_STREETS)))
    none = np.zeros((0, 2), dtype=np.int64)
    assert relaxed_scores(none, gt_px)[2.0] == (0.0, 0.0, 0.0)  # empty prediction: 0, not skipped
    p, r, f = relaxed_scores(gt_px, none)[2.0]
    assert p == 0.0 and np.isnan(r) and f == 0.0  # nothing to find: recall undefined
    assert all(np.isnan(v) for v in relaxed_scores(none, none)[2.0])


def test_f1_rules():
    assert f1_score(0.5, 1.0) == pytest.approx(2 / 3)
    assert f1_score(0.0, float("nan")) == 0.0 and np.isnan(f1_score(float("nan"), float("nan")))
