"""How well an edge confidence tells true edges from false ones (docs/metrics.md, "Confidence").

An edge of a prediction is *true* when at least half its length lies within 5 px of the ground
truth (:func:`edge_truth`). Given each edge's confidence, :func:`confidence_report` says:

* ``auc``: the area under the ROC curve of the confidence for true against false edges (the
  chance that a random true edge is more confident than a random false one; 0.5 is chance);
* ``ece``: expected calibration error, the edge-weighted mean gap between the mean confidence
  and the share of true edges in ten equal-width confidence bins (0 is perfectly calibrated);
* ``review``: the review-effort curve. Edges are reviewed least sure first; after the least
  sure 10 %, 20 % and 50 % of edges, the share of all false edges (``false_edges``) and of all
  false boundary length (``false_length``) that the reviewer has seen, and the same as a share
  of what the best order could have shown in as many edges (``*_of_attainable``).

Pure functions on arrays and graphs in one pixel frame.
"""

from __future__ import annotations

import math

import numpy as np
import shapely
from scipy.stats import rankdata

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import edge_line
from csboundary.graph.polyline import points_along

TRUE_WITHIN_PX = 5.0  # an edge point this close to the ground truth is on it
TRUE_SHARE = 0.5  # an edge is true when at least this share of its length is on the ground truth
REVIEW_SHARES = (0.1, 0.2, 0.5)
ECE_BINS = 10


def edge_truth(
    pred: BoundaryGraph, gt: BoundaryGraph, within_px: float = TRUE_WITHIN_PX, step_px: float = 1.0
) -> np.ndarray:
    """Share of each predicted edge's length within ``within_px`` of ``gt``'s lines (both graphs
    in one pixel frame). Points are taken every ``step_px`` along the edge, at the middle of
    equal pieces, so the share of points is the share of length."""
    n = pred.n_edges
    if n == 0:
        return np.zeros(0)
    gt_lines = [shapely.LineString(edge_line(gt, k)) for k in range(gt.n_edges)]
    gt_lines = [line for line in gt_lines if line.length > 0]
    if not gt_lines:
        return np.zeros(n)
    tree = shapely.STRtree(gt_lines)
    points, owner = [], []
    for k in range(n):
        line = edge_line(pred, k)
        pts, _ = points_along(line, step_px)
        points.append(pts)
        owner.append(np.full(len(pts), k))
    pts, owner = np.concatenate(points), np.concatenate(owner)
    near = np.zeros(len(pts), bool)
    hit, _ = tree.query(shapely.points(pts), predicate="dwithin", distance=within_px)
    near[hit] = True
    count = np.bincount(owner, minlength=n)
    return np.bincount(owner, weights=near, minlength=n) / np.maximum(count, 1)


def roc_auc(confidence: np.ndarray, positive: np.ndarray) -> float:
    """Area under the ROC curve (Mann-Whitney, ties counted half); NaN without both classes."""
    confidence, positive = np.asarray(confidence, float), np.asarray(positive, bool)
    n_pos, n_neg = int(positive.sum()), int((~positive).sum())
    if n_pos == 0 or n_neg == 0:
        return float("nan")
    ranks = rankdata(confidence)
    return float((ranks[positive].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


def expected_calibration_error(confidence: np.ndarray, positive: np.ndarray, bins: int = ECE_BINS) -> float:
    """Edge-weighted mean of |mean confidence - share true| over ``bins`` equal-width bins of
    [0, 1] (the last bin includes 1); NaN without edges."""
    confidence, positive = np.asarray(confidence, float), np.asarray(positive, float)
    if len(confidence) == 0:
        return float("nan")
    which = np.clip((confidence * bins).astype(int), 0, bins - 1)
    count = np.bincount(which, minlength=bins)
    gap = np.abs(np.bincount(which, confidence, bins) - np.bincount(which, positive, bins))  # per-bin sums
    return float(gap.sum() / count.sum())


def review_effort(
    confidence: np.ndarray, positive: np.ndarray, length: np.ndarray, shares=REVIEW_SHARES
) -> dict[str, dict[str, float]]:
    """After reviewing the least sure ``share`` of edges (by count, rounded up), for each share:
    the share of all false edges and of all false length seen (``false_edges``,
    ``false_length``), and the share of what any order could have put there
    (``*_of_attainable``): of min(false edges, k) edges, and of the length of the k longest
    false edges. Where most edges are false no order finds them all in k; this one still can
    reach 1. Equal confidences are reviewed in edge order."""
    confidence, positive, length = np.asarray(confidence, float), np.asarray(positive, bool), np.asarray(length, float)
    order = np.argsort(confidence, kind="stable")
    false = ~positive[order]
    false_len = np.where(false, length[order], 0.0)
    longest_false = np.sort(length[~positive])[::-1]
    out = {}
    for share in shares:
        k = math.ceil(share * len(order) - 1e-9)
        best_edges, best_length = min(int(false.sum()), k), float(longest_false[:k].sum())
        out[f"{share:g}"] = {
            "false_edges": float(false[:k].sum() / false.sum()) if false.any() else float("nan"),
            "false_length": float(false_len[:k].sum() / false_len.sum()) if false_len.sum() > 0 else float("nan"),
            "false_edges_of_attainable": float(false[:k].sum() / best_edges) if best_edges else float("nan"),
            "false_length_of_attainable": float(false_len[:k].sum() / best_length) if best_length > 0 else float("nan"),
        }
    return out


def confidence_report(confidence: np.ndarray, truth_share: np.ndarray, length: np.ndarray) -> dict:
    """AUC, ECE and review-effort curve of ``confidence`` for edges whose ``truth_share`` (from
    :func:`edge_truth`) and pixel ``length`` are given. Edges without a confidence (NaN, e.g.
    drawn by a person) are left out and counted."""
    confidence = np.asarray(confidence, float)
    known = np.isfinite(confidence)
    positive = np.asarray(truth_share, float)[known] >= TRUE_SHARE
    c, length = confidence[known], np.asarray(length, float)[known]
    return {
        "edges": int(known.sum()),
        "edges_without_confidence": int((~known).sum()),
        "share_true": float(positive.mean()) if len(c) else float("nan"),
        "auc": roc_auc(c, positive),
        "ece": expected_calibration_error(c, positive),
        "review": review_effort(c, positive, length),
    }


def precision_recall_by_threshold(
    confidence: np.ndarray,
    truth_share: np.ndarray,
    length: np.ndarray,
    thresholds=(0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9),
) -> list[dict[str, float]]:
    """For each threshold P, the edges kept by ``--min-confidence P``: their share of the
    prediction's length, and the length precision (true length share) of what is kept. A
    cheap stand-in for re-running the metrics at every P (edges only, by the edge definition)."""
    confidence, length = np.asarray(confidence, float), np.asarray(length, float)
    on_truth = np.asarray(truth_share, float) * length
    rows = []
    for p in thresholds:
        keep = ~(confidence < p)  # NaN (manual) edges are kept
        kept = float(length[keep].sum())
        rows.append(
            {
                "min_confidence": float(p),
                "kept_length": kept / max(float(length.sum()), 1e-9),
                "precision": float(on_truth[keep].sum() / kept) if kept > 0 else float("nan"),
                "true_length_kept": float(on_truth[keep].sum() / max(float(on_truth.sum()), 1e-9)),
            }
        )
    return rows
