"""All metrics at once, at city scale (whole graphs) or patch scale (per patch core, averaged).

City scale scores the whole stitched graph against the whole ground truth. Patch scale clips
both graphs to every core window of the city's :class:`~csboundary.data.grid.PatchGrid`
(1000 x 1000 px; the cores tile the mosaic exactly once), scores each patch on its own (pixels of
the common city raster that fall in the core; boundaries = the clipped pieces) and averages every
metric over the patches where it is defined:

* a patch with neither ground truth nor prediction is skipped (every metric undefined);
* empty ground truth, non-empty prediction: precision 0, F1 0 and symmetric APLS 0 are counted;
  recall, paper APLS and TLTS are undefined (no ground truth to recover or to draw pairs from);
* non-empty ground truth, empty prediction: every metric is 0 and counted (the original code
  skipped such images, which inflated its averages);
* paper APLS / TLTS are also undefined where no clipped boundary has more than ``min_vertices``
  samples (short stubs in a patch corner).

Seeds: city scale draws from ``default_rng(seed)``; patch (row, col) from
``default_rng(SeedSequence([seed, row, col]))``, so a patch's pairs do not depend on the others.
"""

from __future__ import annotations

import math

import numpy as np

from csboundary.data.grid import PatchGrid
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.metrics.apls import VARIANTS, apls_from_pairs, paper_pairs, symmetric_apls
from csboundary.metrics.config import MetricConfig
from csboundary.metrics.pixel import rasterize, relaxed_scores
from csboundary.metrics.sampled_graph import resample
from csboundary.metrics.segments import Segments, clip, common_origin, flatten
from csboundary.metrics.tlts import tlts_from_pairs


def metric_names(config: MetricConfig = MetricConfig(), apls: str = "paper") -> list[str]:
    """Keys of the ``metrics`` dict, in reporting order."""
    names = [f"{m}@{tau:g}" for tau in config.taus for m in ("precision", "recall", "f1")]
    names.append("apls")
    if apls == "symmetric":
        names += ["apls_gt_to_pred", "apls_pred_to_gt"]
    return names + ["tlts", "tlts_too_long", "tlts_too_short", "tlts_infeasible"]


def score_segments(
    pred: Segments,
    gt: Segments,
    pred_px: np.ndarray,
    gt_px: np.ndarray,
    rng: np.random.Generator,
    apls: str = "paper",
    config: MetricConfig = MetricConfig(),
) -> tuple[dict, dict]:
    """Every metric of one evaluation unit (a city or a patch): ``(metrics, counts)``.

    The paper pairs are drawn first (they serve paper APLS and TLTS), then the symmetric ones,
    from the same generator.
    """
    if apls not in VARIANTS:
        raise ValueError(f"apls variant must be one of {VARIANTS}, got {apls!r}")
    metrics: dict[str, float] = {}
    for tau, (p, r, f) in relaxed_scores(pred_px, gt_px, config.taus).items():
        metrics[f"precision@{tau:g}"], metrics[f"recall@{tau:g}"], metrics[f"f1@{tau:g}"] = p, r, f
    gt_s, pred_s = resample(gt, config.spacing), resample(pred, config.spacing)
    pairs = paper_pairs(gt_s, pred_s, rng, config)
    counts = {
        "gt_pixels": len(gt_px),
        "pred_pixels": len(pred_px),
        "gt_samples": gt_s.n_vertices,
        "pred_samples": pred_s.n_vertices,
        "pairs": pairs.n_pairs,
        "matched_pairs": int(pairs.matched.sum()),
    }
    if apls == "paper":
        metrics["apls"] = apls_from_pairs(pairs)
    else:
        if config.sym_spacing != config.spacing:
            gt_s, pred_s = resample(gt, config.sym_spacing), resample(pred, config.sym_spacing)
        sym = symmetric_apls(gt_s, pred_s, rng, config)
        metrics["apls"], metrics["apls_gt_to_pred"], metrics["apls_pred_to_gt"] = (
            sym.score,
            sym.gt_to_pred,
            sym.pred_to_gt,
        )
        counts["symmetric_pairs_gt"], counts["symmetric_pairs_pred"] = sym.n_pairs_gt, sym.n_pairs_pred
    t = tlts_from_pairs(pairs, config.phi)
    metrics.update(tlts=t.score, tlts_too_long=t.too_long, tlts_too_short=t.too_short, tlts_infeasible=t.infeasible)
    return metrics, counts


def evaluate_city(
    pred: BoundaryGraph,
    gt: BoundaryGraph,
    *,
    apls: str = "paper",
    seed: int = 0,
    config: MetricConfig = MetricConfig(),
    extent: tuple[float, float, float, float] | None = None,
) -> dict:
    """City scale: the whole prediction against the whole ground truth (same pixel frame); with
    ``extent`` (x0, y0, x1, y1: the imagery's pixels) both are first clipped to it."""
    pred_seg, gt_seg = flatten(pred), flatten(gt)
    if extent is not None:
        pred_seg, gt_seg = clip(pred_seg, *extent), clip(gt_seg, *extent)
    origin = common_origin(pred_seg, gt_seg)  # whole pixels: rasters and results are translation-invariant
    pred_seg, gt_seg = pred_seg.shifted(origin), gt_seg.shifted(origin)
    metrics, counts = score_segments(
        pred_seg, gt_seg, rasterize(pred_seg), rasterize(gt_seg), np.random.default_rng(seed), apls, config
    )
    return {
        "scale": "city",
        "apls_variant": apls,
        "seed": seed,
        "config": config.to_dict(),
        "metrics": metrics,
        "counts": counts,
    }


def evaluate_patches(
    pred: BoundaryGraph,
    gt: BoundaryGraph,
    grid: PatchGrid,
    *,
    apls: str = "paper",
    seed: int = 0,
    config: MetricConfig = MetricConfig(),
    per_patch: bool = True,
) -> dict:
    """Patch scale: every core of ``grid`` scored on its own, then averaged (rules: module doc)."""
    pred_seg, gt_seg = flatten(pred), flatten(gt)
    core = grid.config.core
    pred_buckets, gt_buckets = _PatchBuckets(pred_seg, grid), _PatchBuckets(gt_seg, grid)
    names = metric_names(config, apls)
    rows, results = [], []
    for patch in grid:
        pred_part, pred_px = pred_buckets.patch(patch)
        gt_part, gt_px = gt_buckets.patch(patch)
        if pred_part.n_edges == 0 and gt_part.n_edges == 0 and not len(pred_px) and not len(gt_px):
            continue  # nothing on either side: the patch says nothing
        rng = np.random.default_rng(np.random.SeedSequence([seed, patch.row, patch.col]))
        metrics, counts = score_segments(pred_part, gt_part, pred_px, gt_px, rng, apls, config)
        rows.append([metrics[n] for n in names])
        results.append({"row": patch.row, "col": patch.col, "metrics": metrics, "counts": counts})
    table = np.array(rows, dtype=float).reshape(-1, len(names))
    defined = ~np.isnan(table)
    with np.errstate(invalid="ignore"):
        means = np.where(defined.any(axis=0), np.nansum(table, axis=0) / np.maximum(defined.sum(axis=0), 1), np.nan)
    out = {
        "scale": "patch",
        "apls_variant": apls,
        "seed": seed,
        "config": config.to_dict(),
        "metrics": {n: float(v) for n, v in zip(names, means)},
        "counts": {
            "patches": len(grid),
            "patches_scored": len(results),
            "patches_with_gt": sum(r["counts"]["gt_pixels"] > 0 for r in results),
            "patches_with_pred": sum(r["counts"]["pred_pixels"] > 0 for r in results),
            "patches_per_metric": {n: int(c) for n, c in zip(names, defined.sum(axis=0))},
            "pairs": sum(r["counts"]["pairs"] for r in results),
            "core_px": core,
        },
    }
    if per_patch:
        out["patches"] = results
    return out


class _PatchBuckets:
    """One graph's segments and raster pixels grouped by the patch cores they touch."""

    def __init__(self, seg: Segments, grid: PatchGrid):
        self.seg = seg
        core = grid.config.core
        n_cols = grid.n_cols
        # raster once for the whole city, then hand each core its own pixels
        px = rasterize(seg, within=(0, 0, grid.width, grid.height))
        inside = (px[:, 0] >= 0) & (px[:, 1] >= 0) & (px[:, 0] < grid.width) & (px[:, 1] < grid.height)
        px = px[inside]
        cell = (px[:, 1] // core) * n_cols + px[:, 0] // core
        order = np.argsort(cell, kind="stable")
        self.px, self.px_cell = px[order], cell[order]
        # segments: every cell their bounding box touches (almost always one)
        pts, edges = seg.points, seg.edges
        a, b = pts[edges[:, 0]], pts[edges[:, 1]]
        lo = np.floor(np.minimum(a, b) / core).astype(np.int64)
        hi = np.floor(np.maximum(a, b) / core).astype(np.int64)
        lo = np.maximum(lo, 0)
        hi = np.minimum(hi, [grid.n_cols - 1, grid.n_rows - 1])
        span_c, span_r = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0), np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
        count = span_c * span_r
        which = np.repeat(np.arange(len(edges)), count)
        k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        c = lo[which, 0] + k % np.maximum(span_c[which], 1)
        r = lo[which, 1] + k // np.maximum(span_c[which], 1)
        seg_cell = r * n_cols + c
        order = np.argsort(seg_cell, kind="stable")
        self.seg_edges, self.seg_cell = which[order], seg_cell[order]
        degree = np.bincount(edges.ravel(), minlength=seg.n_points)
        lonely = np.flatnonzero(degree == 0)
        lonely_cell = (np.floor(pts[lonely, 1] / core) * n_cols + np.floor(pts[lonely, 0] / core)).astype(np.int64)
        ok = (pts[lonely] >= 0).all(axis=1) & (pts[lonely, 0] < grid.width) & (pts[lonely, 1] < grid.height)
        self.lonely, self.lonely_cell = lonely[ok], lonely_cell[ok]
        self.n_cols = n_cols

    def patch(self, patch) -> tuple[Segments, np.ndarray]:
        cell = patch.row * self.n_cols + patch.col
        px = self.px[np.searchsorted(self.px_cell, cell) : np.searchsorted(self.px_cell, cell, side="right")]
        edges = self.seg_edges[
            np.searchsorted(self.seg_cell, cell) : np.searchsorted(self.seg_cell, cell, side="right")
        ]
        lonely = self.lonely[self.lonely_cell == cell]
        ids = np.unique(np.concatenate([self.seg.edges[edges].ravel(), lonely]))
        if len(ids) == 0:
            return Segments.empty(), px
        local = Segments(self.seg.points[ids], np.searchsorted(ids, self.seg.edges[edges]))
        w = patch.core
        return clip(local, w.col_off, w.row_off, w.col_end, w.row_end), px


def nan_to_none(value):
    """JSON has no NaN: undefined metrics are written as null."""
    if isinstance(value, dict):
        return {k: nan_to_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [nan_to_none(v) for v in value]
    if isinstance(value, float) and math.isnan(value):
        return None
    return value
