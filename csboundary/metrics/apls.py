"""Average Path Length Similarity, two named variants (see docs/metrics.md).

``paper`` (Topo-boundary / csBoundary): one direction, ground truth -> prediction. Pairs of
sampled vertices are drawn per ground-truth boundary (:func:`~csboundary.metrics.pairs.boundary_pairs`);
each endpoint snaps to the nearest predicted *vertex*; a snap of ``snap_radius`` or more, or no
predicted path, costs 1; otherwise the pair costs ``min(1, |L_gt - L_pred| / L_gt)``. APLS is
1 minus the mean cost. TLTS reuses exactly these pairs (:class:`PairLengths`).

``symmetric`` (SpaceNet / CosmiQ style): control points every ``sym_spacing`` along both graphs;
each graph's control points are projected onto the *nearest edge* of the other graph within
``sym_buffer`` (unmatched points make every pair they belong to cost 1); both directions are
scored over the within-component pairs of their source graph; the total is the harmonic mean of
the two directions, 0 if either is 0. Extra predicted boundaries are penalised here (as sources
of the prediction -> ground-truth direction) but not in the ``paper`` variant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from csboundary.metrics.config import MetricConfig
from csboundary.metrics.pairs import boundary_pairs, component_pairs
from csboundary.metrics.paths import location_distances, pair_distances
from csboundary.metrics.sampled_graph import SampledGraph

VARIANTS = ("paper", "symmetric")


@dataclass(frozen=True)
class PairLengths:
    """The paper's sampled ground-truth pairs and what the prediction makes of them.

    ``pred_length`` is ``inf`` when the pair is unmatched, disconnected, or longer than twice the
    ground-truth length (beyond that neither APLS nor TLTS needs the exact value); ``connected``
    tells the last case (a path exists: too long) from the others (infeasible).
    """

    src: np.ndarray  # ground-truth sampled-vertex ids
    dst: np.ndarray
    gt_length: np.ndarray
    matched: np.ndarray  # both endpoints snapped closer than snap_radius
    connected: np.ndarray  # matched and both snapped vertices in one predicted component
    pred_length: np.ndarray

    @property
    def n_pairs(self) -> int:
        return len(self.gt_length)


def paper_pairs(
    gt: SampledGraph, pred: SampledGraph, rng: np.random.Generator, config: MetricConfig = MetricConfig()
) -> PairLengths:
    """Draw the paper's pairs on the ground truth and measure them in both graphs."""
    src, dst = boundary_pairs(gt, rng, config.min_vertices, config.pairs_divisor, config.exhaustive_pairs)
    gt_length = pair_distances(gt, src, dst)
    keep = np.isfinite(gt_length) & (gt_length > 0)  # coincident samples have no path to compare
    src, dst, gt_length = src[keep], dst[keep], gt_length[keep]
    n = len(src)
    matched = np.zeros(n, dtype=bool)
    connected = np.zeros(n, dtype=bool)
    pred_length = np.full(n, np.inf)
    if n and pred.n_vertices:
        tree = cKDTree(pred.points)
        d_src, p_src = tree.query(gt.points[src], k=1)
        d_dst, p_dst = tree.query(gt.points[dst], k=1)
        matched = (d_src < config.snap_radius) & (d_dst < config.snap_radius)
        connected = matched & (pred.labels[p_src] == pred.labels[p_dst])
        pred_length[connected] = pair_distances(
            pred, p_src[connected], p_dst[connected], limit=2.0 * gt_length[connected]
        )
    return PairLengths(src, dst, gt_length, matched, connected, pred_length)


def pair_costs(gt_length: np.ndarray, pred_length: np.ndarray) -> np.ndarray:
    """APLS penalty per pair: ``min(1, |L_gt - L_pred| / L_gt)``, 1 where there is no path."""
    with np.errstate(invalid="ignore"):
        cost = np.minimum(1.0, np.abs(gt_length - pred_length) / gt_length)
    return np.where(np.isfinite(pred_length), cost, 1.0)


def apls_from_pairs(pairs: PairLengths) -> float:
    """Paper APLS of measured pairs: 1 - mean cost; nan when the ground truth gave no pair."""
    if pairs.n_pairs == 0:
        return float("nan")
    return float(1.0 - pair_costs(pairs.gt_length, pairs.pred_length).mean())


@dataclass(frozen=True)
class SymmetricApls:
    """Symmetric APLS and its two directions (nan = the direction's source graph has no pair)."""

    score: float
    gt_to_pred: float
    pred_to_gt: float
    n_pairs_gt: int
    n_pairs_pred: int


def symmetric_apls(
    gt: SampledGraph, pred: SampledGraph, rng: np.random.Generator, config: MetricConfig = MetricConfig()
) -> SymmetricApls:
    """Both directions and their harmonic mean. A direction whose source graph has no pair is
    undefined; with the other direction defined, the total is 0 (one graph has edges, the other
    none); both undefined gives nan."""
    forward, n_forward = _direction(gt, pred, rng, config)
    backward, n_backward = _direction(pred, gt, rng, config)
    if np.isnan(forward) and np.isnan(backward):
        total = float("nan")
    elif np.isnan(forward) or np.isnan(backward) or forward == 0 or backward == 0:
        total = 0.0
    else:
        total = 2 * forward * backward / (forward + backward)
    return SymmetricApls(float(total), forward, backward, n_forward, n_backward)


def _direction(
    source: SampledGraph, target: SampledGraph, rng: np.random.Generator, config: MetricConfig
) -> tuple[float, int]:
    """Score of ``source``'s pairs re-measured in ``target`` after projecting onto its edges."""
    a, b = component_pairs(source, rng, config.sym_max_pairs, config.sym_sources)
    length = pair_distances(source, a, b)
    keep = np.isfinite(length) & (length > 0)
    a, b, length = a[keep], b[keep], length[keep]
    if len(a) == 0:
        return float("nan"), 0
    needed = np.unique(np.concatenate([a, b]))
    found, where = target.locate(source.points[needed], config.sym_buffer)
    ia, ib = np.searchsorted(needed, a), np.searchsorted(needed, b)
    ok = found[ia] & found[ib]
    other = np.full(len(a), np.inf)
    other[ok] = location_distances(target, where.take(ia[ok]), where.take(ib[ok]), limit=2.0 * length[ok])
    return float(1.0 - pair_costs(length, other).mean()), len(a)
