"""Shortest-path lengths between many pairs of points on a :class:`SampledGraph`, fast.

Written once and shared by the paper's APLS, TLTS and the symmetric APLS. A point lies on a chain
(or is a key: a junction, an end, or a loop's anchor) and leaves it through the chain's two end
keys, so a path between two points is ``exit offset + key-to-key distance + exit offset`` over
the four exit combinations, or the direct way along a shared chain. Dijkstra
(``scipy.sparse.csgraph``) therefore runs on the small key graph only: a ring needs no search at
all, a long boundary one per end. Only keys of one component can be connected, and components
are contiguous blocks of the key matrix, so the searches run on diagonal blocks (small components
batched together, a large one alone), from the distinct source keys only, in chunks that bound
memory. An optional per-pair ``limit`` stops a search early: callers pass the length beyond which
the exact value does not matter (e.g. ``2 * L_gt`` for APLS, whose penalty is 1 from there on).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import dijkstra

from csboundary.metrics.sampled_graph import Locations, SampledGraph

BLOCK = 2048  # batch small components until a block has this many keys
BUDGET = 1 << 22  # at most this many distance-matrix cells per Dijkstra call (32 MB)


def pair_distances(graph: SampledGraph, src, dst, limit=None) -> np.ndarray:
    """Shortest-path length between sampled vertices ``src[i]`` and ``dst[i]``; ``inf`` when not
    connected or longer than ``limit[i]`` (a scalar or one value per pair; None = no limit)."""
    return location_distances(graph, graph.vertex_locations(src), graph.vertex_locations(dst), limit)


def location_distances(graph: SampledGraph, a: Locations, b: Locations, limit=None) -> np.ndarray:
    """Shortest-path length between points ``a[i]`` and ``b[i]`` (see module doc)."""
    n = len(a)
    if n == 0:
        return np.zeros(0)
    lim = np.full(n, np.inf) if limit is None else np.broadcast_to(np.asarray(limit, dtype=float), (n,)).astype(float)
    combos = ((0, 0), (0, 1), (1, 0), (1, 1))
    src = np.concatenate([a.exit_key[:, i] for i, _ in combos])
    dst = np.concatenate([b.exit_key[:, j] for _, j in combos])
    extra = np.concatenate([a.exit_off[:, i] + b.exit_off[:, j] for i, j in combos])
    best = (key_distances(graph, src, dst, np.tile(lim, 4)) + extra).reshape(4, n).min(axis=0)
    same = (a.chain >= 0) & (a.chain == b.chain)
    best[same] = np.minimum(best[same], np.abs(a.arc[same] - b.arc[same]))
    best[best > lim] = np.inf
    return best


def key_distances(graph: SampledGraph, src: np.ndarray, dst: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Key-to-key shortest paths (``inf`` if disconnected; may exceed ``limit`` when finite)."""
    src = np.asarray(src, dtype=np.int64)
    dst = np.asarray(dst, dtype=np.int64)
    out = np.full(len(src), np.inf)
    out[src == dst] = 0.0
    starts = graph.key_starts
    comp_src = np.searchsorted(starts, src, side="right") - 1
    comp_dst = np.searchsorted(starts, dst, side="right") - 1
    todo = np.flatnonzero((comp_src == comp_dst) & (src != dst))
    if len(todo) == 0:
        return out
    comp = comp_src[todo]
    order = np.argsort(comp, kind="stable")
    todo, comp = todo[order], comp[order]
    ucomp, first = np.unique(comp, return_index=True)
    first = np.append(first, len(todo))
    i = 0
    while i < len(ucomp):
        lo = starts[ucomp[i]]
        j = i + 1
        while j < len(ucomp) and starts[ucomp[j] + 1] - lo <= BLOCK:
            j += 1
        hi = starts[ucomp[j - 1] + 1]
        sel = todo[first[i] : first[j]]
        _solve_block(graph.key_matrix[lo:hi, lo:hi], src[sel] - lo, dst[sel] - lo, limit[sel], out, sel)
        i = j
    return out


def _solve_block(block, src: np.ndarray, dst: np.ndarray, lim: np.ndarray, out: np.ndarray, where: np.ndarray) -> None:
    sources, inv = np.unique(src, return_inverse=True)
    need = np.full(len(sources), -np.inf)
    np.maximum.at(need, inv, lim)
    rank_order = np.argsort(need, kind="stable")  # similar limits share a chunk
    rank = np.empty(len(sources), dtype=np.int64)
    rank[rank_order] = np.arange(len(sources))
    chunk = max(1, BUDGET // max(block.shape[0], 1))
    pair_rank = rank[inv]
    pair_order = np.argsort(pair_rank, kind="stable")
    bounds = np.searchsorted(pair_rank[pair_order], np.arange(0, len(sources) + chunk, chunk))
    for c, start in enumerate(range(0, len(sources), chunk)):
        ids = rank_order[start : start + chunk]
        dist = dijkstra(block, directed=False, indices=sources[ids], limit=float(need[ids].max()))
        pairs = pair_order[bounds[c] : bounds[c + 1]]
        out[where[pairs]] = dist[pair_rank[pairs] - start, dst[pairs]]
