"""Too Long / Too Short (Wegner et al., CVPR 2013), on the paper's APLS pairs.

A pair whose two ground-truth vertices both snapped to the prediction and are connected there is
*correct* when ``|L_gt - L_pred| <= phi * L_gt``, *too short* when ``L_pred < (1 - phi) L_gt``,
and *too long* when ``L_pred > (1 + phi) L_gt``; an unmatched endpoint or a missing path makes
it *infeasible*. TLTS is the share of correct pairs; the four shares sum to 1.
"""

from __future__ import annotations

from dataclasses import dataclass

from csboundary.metrics.apls import PairLengths


@dataclass(frozen=True)
class TltsResult:
    """TLTS and the shares of too-long, too-short and infeasible pairs (nan without pairs)."""

    score: float
    too_long: float
    too_short: float
    infeasible: float
    n_pairs: int


def tlts_from_pairs(pairs: PairLengths, phi: float = 0.05) -> TltsResult:
    n = pairs.n_pairs
    if n == 0:
        nan = float("nan")
        return TltsResult(nan, nan, nan, nan, 0)
    tolerance = phi * pairs.gt_length
    diff = pairs.pred_length - pairs.gt_length  # +inf for connected pairs beyond the search limit
    short = pairs.connected & (diff < -tolerance)
    long = pairs.connected & (diff > tolerance)
    correct = pairs.connected & ~short & ~long
    return TltsResult(
        float(correct.mean()), float(long.mean()), float(short.mean()), float((~pairs.connected).mean()), n
    )
