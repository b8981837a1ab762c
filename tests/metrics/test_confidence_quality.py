"""The confidence report: which edges are true, and how well a confidence orders and calibrates them.

The hand-built case: ground truth is one horizontal line y = 50 from x = 0 to 200. Four predicted
edges, their share of length within 5 px of it worked out by hand:

* A: on the line, x 0 -> 100                      share 1   (true)
* B: 20 px above it, x 0 -> 100                   share 0   (false)
* C: x 100 -> 160 at y 52, then down to y 92       60 px along, 3 px of the riser: share 0.63 (true)
* D: from (150, 60) to (150, 160)                  starts 10 px away: share 0 (false)
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.graph import BoundaryGraph
from csboundary.metrics.confidence_quality import (
    confidence_report,
    edge_truth,
    expected_calibration_error,
    review_effort,
    roc_auc,
)


def hand_case() -> tuple[BoundaryGraph, BoundaryGraph]:
    gt = BoundaryGraph.from_polylines([np.array([[0.0, 50.0], [200.0, 50.0]])])
    lines = [
        np.array([[0.0, 50.0], [100.0, 50.0]]),  # A
        np.array([[0.0, 30.0], [100.0, 30.0]]),  # B
        np.array([[100.0, 52.0], [160.0, 52.0], [160.0, 92.0]]),  # C: one edge with a bend
        np.array([[150.0, 60.0], [150.0, 160.0]]),  # D: starts 10 px from the line
    ]
    vertices = np.concatenate([[line[0], line[-1]] for line in lines])
    pred = BoundaryGraph(vertices, np.arange(8).reshape(4, 2), edge_polylines=lines)
    return pred, gt


def test_edge_truth_by_hand():
    pred, gt = hand_case()
    share = edge_truth(pred, gt)
    # C: the riser's first 3 px (y 52 -> 55) are within 5 px of y = 50, so 63 of 100 px
    np.testing.assert_allclose(share, [1.0, 0.0, 0.63, 0.0], atol=0.011)


def test_ordering_and_auc_on_the_hand_case():
    pred, gt = hand_case()
    share = edge_truth(pred, gt)
    length = pred.edge_lengths()
    right = confidence_report(np.array([0.9, 0.2, 0.6, 0.4]), share, length)  # both true edges above both false
    assert right["auc"] == 1.0
    assert right["share_true"] == 0.5
    # least sure half: B and D, all the false length (100 + 100 px) is found there
    assert right["review"]["0.5"] == {
        "false_edges": 1.0,
        "false_length": 1.0,
        "false_edges_of_attainable": 1.0,
        "false_length_of_attainable": 1.0,
    }
    wrong = confidence_report(np.array([0.9, 0.2, 0.6, 0.95]), share, length)  # D above both true edges
    assert wrong["auc"] == 0.5  # pairs (A,B) (C,B) right, (A,D) (C,D) wrong
    assert wrong["review"]["0.5"]["false_edges"] == 0.5  # least sure half: B, C


def test_a_person_drawn_edge_without_confidence_is_left_out():
    pred, gt = hand_case()
    report = confidence_report(np.array([0.9, 0.2, np.nan, 0.4]), edge_truth(pred, gt), pred.edge_lengths())
    assert report["edges"] == 3 and report["edges_without_confidence"] == 1
    assert report["auc"] == 1.0


def test_expected_calibration_error_by_hand():
    # bin 9: mean confidence 0.95, half true -> gap 0.45 on 2 of 4 edges; bin 1: 0.15 vs 0 -> 0.15 on 2 of 4
    assert expected_calibration_error(np.array([0.95, 0.95, 0.15, 0.15]), np.array([1, 0, 0, 0])) == pytest.approx(0.3)
    # perfectly calibrated: a confidence of 1 on true edges and 0 on false ones
    assert expected_calibration_error(np.array([1.0, 0.0, 1.0]), np.array([1, 0, 1])) == 0.0


def test_review_effort_counts_length():
    confidence = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95])
    positive = np.array([0, 1, 1, 1, 1, 1, 1, 1, 1, 0], bool)
    length = np.array([10, 1, 1, 1, 1, 1, 1, 1, 1, 30.0])
    effort = review_effort(confidence, positive, length)
    # the least sure edge: 1 of 2 false edges, 10 of 40 px false length; one edge could hold 1 false
    # edge at best (all of it), and 30 px (the longest false edge)
    assert effort["0.1"] == {
        "false_edges": 0.5,
        "false_length": 0.25,
        "false_edges_of_attainable": 1.0,
        "false_length_of_attainable": 1 / 3,
    }
    # five edges could hold both false ones (2 edges, 40 px): this order finds one
    assert effort["0.5"] == {
        "false_edges": 0.5,
        "false_length": 0.25,
        "false_edges_of_attainable": 0.5,
        "false_length_of_attainable": 0.25,
    }


def test_review_effort_of_attainable_where_most_edges_are_false():
    """90 % false: no order can find all false edges in the least sure 20 %; one that puts only
    false edges there finds all it could."""
    positive = np.array([1] + [0] * 9, bool)
    effort = review_effort(np.linspace(0.9, 0.0, 10), positive, np.ones(10))  # the true edge is the surest
    assert effort["0.2"]["false_edges"] == pytest.approx(2 / 9)
    assert effort["0.2"]["false_edges_of_attainable"] == 1.0 and effort["0.2"]["false_length_of_attainable"] == 1.0


def test_auc_undefined_with_one_class():
    assert np.isnan(roc_auc(np.array([0.2, 0.4]), np.array([True, True])))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 20), st.booleans()), min_size=2, max_size=60))
def test_auc_is_the_share_of_correctly_ordered_pairs(rows):
    scores = np.array([r[0] for r in rows], float)
    positive = np.array([r[1] for r in rows])
    pos, neg = scores[positive], scores[~positive]
    if len(pos) == 0 or len(neg) == 0:
        assert np.isnan(roc_auc(scores, positive))
        return
    pairs = (pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()
    assert roc_auc(scores, positive) == pytest.approx(pairs / (len(pos) * len(neg)))
