"""Evaluation of road-boundary graphs (paper Section V-C); definitions in docs/metrics.md.

Pixel level: relaxed precision, recall and F1 at tau = 2, 5, 10 px. Topology: APLS in two named
variants (``paper``, ``symmetric``) and TLTS on the paper's pairs. City scale scores whole
graphs; patch scale averages over the 1000 px patch cores. Every random choice comes from a
seeded ``numpy`` generator: the same seed gives bit-identical results.

All functions take :class:`~csboundary.graph.BoundaryGraph` objects in one common pixel frame
(:mod:`csboundary.metrics.io` loads files into one) and put the prediction first.
"""

from __future__ import annotations

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.metrics.aggregate import evaluate_city, evaluate_patches, metric_names
from csboundary.metrics.apls import (
    VARIANTS,
    PairLengths,
    SymmetricApls,
    apls_from_pairs,
    paper_pairs,
    symmetric_apls,
)
from csboundary.metrics.confidence_quality import confidence_report, edge_truth
from csboundary.metrics.config import MetricConfig
from csboundary.metrics.graph_clip import clip_graph, grown
from csboundary.metrics.pixel import rasterize, relaxed_scores
from csboundary.metrics.review_time import ReviewCosts, review_report
from csboundary.metrics.sampled_graph import resample
from csboundary.metrics.segments import Segments, common_origin, flatten
from csboundary.metrics.tlts import TltsResult, tlts_from_pairs

__all__ = [
    "MetricConfig",
    "ReviewCosts",
    "VARIANTS",
    "PairLengths",
    "SymmetricApls",
    "TltsResult",
    "apls",
    "apls_paper",
    "apls_paper_pairs",
    "apls_symmetric",
    "evaluate",
    "evaluate_city",
    "evaluate_patches",
    "metric_names",
    "pixel_scores",
    "review_report",
    "tlts",
]


def _segments(pred: BoundaryGraph, gt: BoundaryGraph) -> tuple[Segments, Segments]:
    pred_seg, gt_seg = flatten(pred), flatten(gt)
    origin = common_origin(pred_seg, gt_seg)
    return pred_seg.shifted(origin), gt_seg.shifted(origin)


def pixel_scores(
    pred: BoundaryGraph, gt: BoundaryGraph, taus=MetricConfig().taus
) -> dict[float, tuple[float, float, float]]:
    """``{tau: (precision, recall, f1)}`` of the rasterised graphs."""
    pred_seg, gt_seg = _segments(pred, gt)
    return relaxed_scores(rasterize(pred_seg), rasterize(gt_seg), taus)


def apls_paper_pairs(
    pred: BoundaryGraph, gt: BoundaryGraph, seed: int = 0, config: MetricConfig = MetricConfig()
) -> PairLengths:
    """The paper's sampled ground-truth pairs and what ``pred`` makes of them (seeded): what
    :func:`apls_paper` averages, kept for diagnosis (experiments/scripts/apls_failures.py)."""
    pred_seg, gt_seg = _segments(pred, gt)
    return paper_pairs(
        resample(gt_seg, config.spacing), resample(pred_seg, config.spacing), np.random.default_rng(seed), config
    )


def apls_paper(pred: BoundaryGraph, gt: BoundaryGraph, seed: int = 0, config: MetricConfig = MetricConfig()) -> float:
    """APLS as Topo-boundary / csBoundary define it (seeded; nan if the ground truth gives no pair)."""
    return apls_from_pairs(apls_paper_pairs(pred, gt, seed, config))


def apls_symmetric(
    pred: BoundaryGraph, gt: BoundaryGraph, seed: int = 0, config: MetricConfig = MetricConfig()
) -> SymmetricApls:
    """SpaceNet-style APLS: both directions and their harmonic mean."""
    pred_seg, gt_seg = _segments(pred, gt)
    rng = np.random.default_rng(seed)
    return symmetric_apls(resample(gt_seg, config.sym_spacing), resample(pred_seg, config.sym_spacing), rng, config)


def apls(
    pred: BoundaryGraph, gt: BoundaryGraph, variant: str = "paper", seed: int = 0, config: MetricConfig = MetricConfig()
) -> float:
    """APLS of the named variant (``paper`` or ``symmetric``)."""
    if variant == "paper":
        return apls_paper(pred, gt, seed, config)
    if variant == "symmetric":
        return apls_symmetric(pred, gt, seed, config).score
    raise ValueError(f"apls variant must be one of {VARIANTS}, got {variant!r}")


def tlts(pred: BoundaryGraph, gt: BoundaryGraph, seed: int = 0, config: MetricConfig = MetricConfig()) -> TltsResult:
    """TLTS on the paper's pairs (the same pairs :func:`apls_paper` draws for the same seed)."""
    pred_seg, gt_seg = _segments(pred, gt)
    pairs = paper_pairs(
        resample(gt_seg, config.spacing), resample(pred_seg, config.spacing), np.random.default_rng(seed), config
    )
    return tlts_from_pairs(pairs, config.phi)


def evaluate(
    pred: BoundaryGraph,
    gt: BoundaryGraph,
    *,
    scale: str = "city",
    grid=None,
    apls: str = "paper",
    seed: int = 0,
    config: MetricConfig = MetricConfig(),
    extent: tuple[float, float, float, float] | None = None,
    review: ReviewCosts | None = ReviewCosts(),
    metres_per_px: float | None = None,
) -> dict:
    """Every metric at ``scale`` ``city`` or ``patch`` (the latter needs the city's ``grid``).
    ``extent`` (the imagery's pixel rectangle) first cuts both graphs to it grown by
    :data:`~csboundary.metrics.graph_clip.MARGIN_PX` (so a line far outside the imagery costs
    no more than its part inside); at city scale the pixel metrics, APLS and TLTS then clip to
    ``extent`` itself. When the prediction's edges carry scores, ``confidence`` says how well
    they tell true edges from false ones (:func:`csboundary.metrics.confidence_quality.confidence_report`,
    on the graphs cut to the grown ``extent``). At city scale, ``review_effort`` is the simulated
    review at ``review`` costs (:func:`csboundary.metrics.review_time.review_report`, the same
    cut graphs, so its km of true boundary are the imagery's; per km of true boundary
    when ``metres_per_px`` is known); ``review=None`` skips it."""
    if extent is not None:
        window = grown(extent)
        pred, gt = clip_graph(pred, window), clip_graph(gt, window)
    if scale == "city":
        result = evaluate_city(pred, gt, apls=apls, seed=seed, config=config, extent=extent)
    elif scale == "patch":
        if grid is None:
            raise ValueError("patch scale needs the city's PatchGrid")
        result = evaluate_patches(pred, gt, grid, apls=apls, seed=seed, config=config)
    else:
        raise ValueError(f"scale must be 'city' or 'patch', got {scale!r}")
    if pred.edge_scores is not None and np.isfinite(np.asarray(pred.edge_scores, float)).any():
        result["confidence"] = confidence_report(pred.edge_scores, edge_truth(pred, gt), pred.edge_lengths())
    if scale == "city" and review is not None and gt.n_edges:
        result["review_effort"] = review_report(pred, gt, metres_per_px, review, seed)
    return result
