"""Seeded vertex pairs of a sampled graph, the start and end points of the topology metrics'
shortest paths: the paper's pairs per boundary and SpaceNet-style pairs per component.

Kept apart from the resampling because the pairs are the metrics' random part: the same seed
gives the same pairs, and both APLS variants and TLTS draw theirs here.
"""

from __future__ import annotations

import numpy as np

from csboundary.metrics.sampled_graph import SampledGraph


def boundary_pairs(
    graph: SampledGraph, rng: np.random.Generator, min_vertices: int = 5, divisor: int = 3, exhaustive: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The paper's pairs: for every boundary (connected component) with more than ``min_vertices``
    sampled vertices, ``n // divisor`` pairs of two distinct vertices drawn uniformly at random.

    ``exhaustive=True`` takes every unordered pair of those boundaries instead (exact, for small
    graphs and hand-checked tests). Pairs are returned as sampled-vertex ids.
    """
    sizes = graph.component_sizes()
    comps = np.flatnonzero(sizes > min_vertices)
    if exhaustive:
        return _all_pairs(graph.starts, comps)
    n = sizes[comps]
    k = n // divisor
    comp = np.repeat(comps, k)
    size = np.repeat(n, k)
    return _distinct_pairs(graph.starts[comp], size, rng)


def component_pairs(
    graph: SampledGraph, rng: np.random.Generator, max_pairs: int, sources: int = 500
) -> tuple[np.ndarray, np.ndarray]:
    """SpaceNet-style pairs: every unordered pair of distinct vertices in one component when there
    are at most ``max_pairs``; otherwise a seeded sample of ``max_pairs`` pairs, each uniform over
    that set, drawn as ``sources`` source vertices (chosen with probability proportional to their
    component size - 1) with ``max_pairs // sources`` uniform partners each. Sharing sources keeps
    the number of shortest-path searches small even when one component spans the whole city."""
    sizes = graph.component_sizes()
    comps = np.flatnonzero(sizes >= 2)
    n = sizes[comps].astype(np.float64)
    total = (n * (n - 1) / 2).sum()
    if total <= max_pairs:
        return _all_pairs(graph.starts, comps)
    sources = max(1, min(sources, max_pairs))
    weight = n - 1  # P(source) * P(partner | source) = 1 / (number of ordered pairs): uniform
    comp = comps[rng.choice(len(comps), size=sources, p=weight * n / (weight * n).sum())]
    src = graph.starts[comp] + rng.integers(0, sizes[comp])
    per = max_pairs // sources
    comp, src = np.repeat(comp, per), np.repeat(src, per)
    partner = rng.integers(0, sizes[comp] - 1)
    partner = graph.starts[comp] + partner
    partner = partner + (partner >= src)  # skip the source itself
    return src.astype(np.int64), partner.astype(np.int64)


def _distinct_pairs(start: np.ndarray, size: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Two distinct uniform vertices in each block [start, start + size)."""
    if len(size) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    a = rng.integers(0, size)
    b = rng.integers(0, size - 1)
    b = b + (b >= a)
    return (start + a).astype(np.int64), (start + b).astype(np.int64)


def _all_pairs(starts: np.ndarray, comps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a_all, b_all = [np.zeros(0, dtype=np.int64)], [np.zeros(0, dtype=np.int64)]
    for c in comps.tolist():
        i, j = np.triu_indices(int(starts[c + 1] - starts[c]), k=1)
        a_all.append(starts[c] + i)
        b_all.append(starts[c] + j)
    return np.concatenate(a_all).astype(np.int64), np.concatenate(b_all).astype(np.int64)
