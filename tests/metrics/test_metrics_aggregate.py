"""Patch-scale averaging and its rules for empty ground truth / empty prediction."""

from __future__ import annotations

import math

import numpy as np
import pytest

from csboundary.data.grid import GridConfig, PatchGrid
from csboundary.graph import BoundaryGraph
from csboundary.metrics import MetricConfig, evaluate, evaluate_city, evaluate_patches

# Two 200 px patch cores side by side: (0, 0) covers x 0..200, (0, 1) covers x 200..400.
GRID = PatchGrid(400, 200, config=GridConfig(core=200, margin=20))
LEFT = [[10.5, 50.5], [190.5, 50.5]]  # 180 px -> 6 pieces, 7 samples > 5: 7 // 3 = 2 pairs
RIGHT = [[210.5, 150.5], [390.5, 150.5]]


def lines(*polylines) -> BoundaryGraph:
    return BoundaryGraph.from_polylines([np.asarray(p, dtype=float) for p in polylines])


def test_perfect_prediction_scores_one_in_every_patch():
    gt = lines(LEFT, RIGHT)
    result = evaluate_patches(gt, gt, GRID, apls="symmetric")
    assert result["counts"]["patches_scored"] == 2
    assert all(v == pytest.approx(1.0) for k, v in result["metrics"].items() if not k.startswith("tlts_"))


def test_empty_ground_truth_patch_counts_for_precision_f1_and_symmetric_apls_only():
    # Patch (0, 0): perfect. Patch (0, 1): no ground truth, one predicted boundary ->
    # precision 0, F1 0, symmetric APLS 0 are counted; recall, paper APLS and TLTS are undefined.
    gt, pred = lines(LEFT), lines(LEFT, RIGHT)
    paper = evaluate_patches(pred, gt, GRID)
    m, per_metric = paper["metrics"], paper["counts"]["patches_per_metric"]
    assert m["precision@5"] == pytest.approx(0.5) and m["f1@5"] == pytest.approx(0.5) and per_metric["precision@5"] == 2
    assert m["recall@5"] == 1.0 and per_metric["recall@5"] == 1
    assert m["apls"] == 1.0 and m["tlts"] == 1.0 and per_metric["apls"] == per_metric["tlts"] == 1
    right = next(p for p in paper["patches"] if p["col"] == 1)["metrics"]
    assert right["precision@2"] == 0.0 and math.isnan(right["recall@2"]) and math.isnan(right["apls"])
    sym = evaluate_patches(pred, gt, GRID, apls="symmetric")
    assert sym["metrics"]["apls"] == pytest.approx(0.5) and sym["counts"]["patches_per_metric"]["apls"] == 2


def test_empty_prediction_patch_scores_zero_and_counts():
    gt, pred = lines(LEFT, RIGHT), lines(LEFT)
    result = evaluate_patches(pred, gt, GRID)
    m = result["metrics"]
    assert m["precision@2"] == pytest.approx(0.5) and m["recall@2"] == pytest.approx(0.5)
    assert (
        m["apls"] == pytest.approx(0.5)
        and m["tlts"] == pytest.approx(0.5)
        and m["tlts_infeasible"] == pytest.approx(0.5)
    )
    assert result["counts"]["patches_per_metric"]["apls"] == 2


def test_patches_without_anything_are_skipped():
    grid = PatchGrid(600, 200, config=GridConfig(core=200, margin=20))  # third patch empty on both sides
    gt = lines(LEFT)
    result = evaluate_patches(gt, gt, grid)
    assert result["counts"]["patches"] == 3 and result["counts"]["patches_scored"] == 1
    assert result["metrics"]["precision@2"] == 1.0


def test_boundaries_are_cut_at_patch_borders():
    # one 380 px line across both cores: each patch scores its own 189.5 px piece, cut at x = 200
    # (ceil(189.5 / 30) = 7 pieces -> 8 samples -> 8 * 7 / 2 = 28 pairs each)
    across = lines([[10.5, 100.5], [390.5, 100.5]])
    result = evaluate_patches(across, across, GRID, config=MetricConfig(exhaustive_pairs=True))
    assert [p["counts"]["pairs"] for p in result["patches"]] == [28, 28]
    assert result["metrics"]["apls"] == 1.0


def test_patch_seeds_are_per_patch():
    gt = lines(LEFT, RIGHT)
    pred = lines([[10.5, 52.5], [100.5, 52.5]], [[110.5, 52.5], [190.5, 52.5]], RIGHT)
    a = evaluate_patches(pred, gt, GRID, seed=3)
    assert a == evaluate_patches(pred, gt, GRID, seed=3)
    # the right patch's score does not depend on what happens in the left one
    b = evaluate_patches(lines(RIGHT), gt, GRID, seed=3)
    assert a["patches"][1]["metrics"] == b["patches"][1]["metrics"]


def test_evaluate_dispatches_and_checks_arguments():
    gt = lines(LEFT)
    assert evaluate(gt, gt)["scale"] == "city"
    assert evaluate(gt, gt, scale="patch", grid=GRID)["scale"] == "patch"
    with pytest.raises(ValueError):
        evaluate(gt, gt, scale="patch")
    with pytest.raises(ValueError):
        evaluate_city(gt, gt, apls="sideways")
