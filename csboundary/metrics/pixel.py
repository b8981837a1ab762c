"""Pixel-level relaxed precision, recall and F1 (paper V-C, after Topo-boundary).

Both graphs are rasterised 1 px wide on the same pixel grid: continuous (col, row) lies in pixel
``(floor(col), floor(row))``, and each straight segment between its end pixels is drawn with a
DDA line (8-connected, one pixel per step along the major axis). Isolated vertices are points,
not boundaries, and are not drawn. Distances are between pixel indices (Euclidean), and a pixel
counts when its distance to the other set is strictly below ``tau``, as in the paper.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from csboundary.metrics.limits import MAX_RASTER_PIXELS, RasterTooLarge
from csboundary.metrics.segments import Segments, clip

DEFAULT_TAUS = (2.0, 5.0, 10.0)


def rasterize(seg: Segments, within: tuple[float, float, float, float] | None = None) -> np.ndarray:
    """Distinct pixels (P, 2) int64 (col, row) covered by the graph's segments.

    ``within`` (x0, y0, x1, y1) clips the segments to the raster first, so memory is bounded by
    the raster, not by the coordinates; without it, a graph covering more than
    :data:`MAX_RASTER_PIXELS` pixels raises :class:`RasterTooLarge` before anything is allocated.
    """
    if within is not None:
        seg = clip(seg, *within)
    if seg.n_edges == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if not np.isfinite(seg.points).all():
        raise ValueError("graph has a vertex with a non-finite coordinate")
    ends = np.floor(seg.points).astype(np.int64)
    a, b = ends[seg.edges[:, 0]], ends[seg.edges[:, 1]]
    delta = b - a
    steps = np.abs(delta).max(axis=1)
    counts = steps + 1
    total = int(counts.sum())
    if total > MAX_RASTER_PIXELS:
        raise RasterTooLarge(f"the boundaries would cover {total:.3g} pixels (limit {MAX_RASTER_PIXELS:.0e})")
    which = np.repeat(np.arange(len(steps)), counts)
    j = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    t = j / np.maximum(steps, 1)[which]
    pixels = a[which] + np.floor(t[:, None] * delta[which] + 0.5).astype(np.int64)
    low = pixels.min(axis=0)
    width = int(pixels[:, 0].max() - low[0]) + 1
    key = np.sort((pixels[:, 1] - low[1]) * width + (pixels[:, 0] - low[0]))  # row-major
    key = key[np.concatenate([[True], key[1:] != key[:-1]])]
    return np.stack([key % width + low[0], key // width + low[1]], axis=1)


def relaxed_scores(
    pred_px: np.ndarray, gt_px: np.ndarray, taus=DEFAULT_TAUS
) -> dict[float, tuple[float, float, float]]:
    """``{tau: (precision, recall, f1)}`` of predicted against ground-truth pixels.

    Empty sets: an empty prediction scores precision 0 (not skipped, unlike the original code);
    an empty ground truth leaves recall undefined (nan) and gives precision 0 when something was
    predicted; both empty is nan throughout. F1 is 0 when precision or recall is 0.
    """
    taus = tuple(float(t) for t in taus)
    top = max(taus)
    d_pred = _nearest(gt_px, pred_px, top)  # each predicted pixel to the ground truth
    d_gt = _nearest(pred_px, gt_px, top)
    out = {}
    for tau in taus:
        if len(pred_px) == 0 and len(gt_px) == 0:
            p = r = np.nan
        else:
            p = float(np.mean(d_pred < tau)) if len(pred_px) else 0.0
            r = float(np.mean(d_gt < tau)) if len(gt_px) else np.nan
        out[tau] = (p, r, f1_score(p, r))
    return out


def f1_score(p: float, r: float) -> float:
    """Harmonic mean; 0 if either is 0, nan if either is undefined and neither is 0."""
    if p == 0 or r == 0:
        return 0.0
    if np.isnan(p) or np.isnan(r):
        return np.nan
    return 2 * p * r / (p + r)


def _nearest(reference: np.ndarray, query: np.ndarray, bound: float) -> np.ndarray:
    """Distance from each query pixel to the nearest reference pixel (inf beyond ``bound``)."""
    if len(query) == 0:
        return np.zeros(0)
    if len(reference) == 0:
        return np.full(len(query), np.inf)
    return cKDTree(reference, balanced_tree=False, compact_nodes=False).query(query, k=1, distance_upper_bound=bound)[0]
