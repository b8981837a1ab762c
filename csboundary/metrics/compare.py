"""Two models scored on the same cities: is the difference of their mean scores larger than the
choice of cities can make it? (A paired bootstrap over the cities.)"""

from __future__ import annotations

import numpy as np


def paired_bootstrap(a, b, samples: int = 10000, seed: int = 0) -> tuple[float, float, float, float]:
    """(mean of b - a, the 2.5 % and 97.5 % quantiles of its bootstrap distribution, the share of
    draws where b's mean is above a's) for per-city scores ``a`` and ``b`` of the same cities,
    resampled with replacement, the same draw for both. An interval that spans 0 means the set
    cannot tell the two apart."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape or a.ndim != 1 or len(a) == 0:
        raise ValueError("a and b must be per-city scores of the same cities")
    diff = b - a
    draws = np.random.default_rng(seed).integers(0, len(diff), size=(samples, len(diff)))
    means = diff[draws].mean(axis=1)
    low, high = np.quantile(means, [0.025, 0.975])
    return float(diff.mean()), float(low), float(high), float((means > 0).mean())
