"""A graph resampled along its chains at a fixed spacing (:func:`resample`), so that vertex density
no longer depends on how the input was digitised, and the locations of points on it that the
shortest paths (:mod:`csboundary.metrics.paths`) start and end at.

See :mod:`csboundary.metrics.sampling` for how chains are cut and why paths run over keys only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from csboundary.graph.chains import chains as find_chains
from csboundary.metrics.limits import MAX_SAMPLES, RasterTooLarge
from csboundary.metrics.segments import Segments

_MIN_WEIGHT = 1e-9  # csgraph drops zero weights; a zero-length piece still connects its ends


@dataclass(frozen=True)
class Locations:
    """Points on a graph, each reachable through its two *exits*: the end vertices (junctions or
    ends, "keys") of the chain it lies on, at arc distances ``exit_off``. A key vertex exits through
    itself at distance 0 (``chain`` -1). Points on the same chain can also be joined along it."""

    exit_key: np.ndarray  # (n, 2) key ids
    exit_off: np.ndarray  # (n, 2) arc lengths to them
    chain: np.ndarray  # (n,) chain id, -1 for key vertices
    arc: np.ndarray  # (n,) arc position along the chain

    def __len__(self) -> int:
        return len(self.chain)

    def take(self, index) -> "Locations":
        return Locations(self.exit_key[index], self.exit_off[index], self.chain[index], self.arc[index])


@dataclass
class SampledGraph:
    """A graph resampled along its chains, numbered component by component.

    ``points`` (M, 2) sampled vertices with ``labels`` (M,) non-decreasing component ids and
    ``starts`` (C + 1,) block offsets. Each vertex is a key (``vertex_key`` >= 0: degree != 2, or
    the anchor of a closed loop) or lies on chain ``vertex_chain`` at arc ``vertex_arc``. Shortest
    paths run on ``key_matrix``: keys joined by their chains' arc lengths, keys numbered by
    component too (``key_starts``), so Dijkstra works on small diagonal blocks. The original
    segments (``seg_*``) let :meth:`locate` put any point onto its chain.
    """

    points: np.ndarray
    labels: np.ndarray
    starts: np.ndarray
    vertex_key: np.ndarray
    vertex_chain: np.ndarray
    vertex_arc: np.ndarray
    chain_start: np.ndarray  # key ids
    chain_end: np.ndarray
    chain_length: np.ndarray
    chain_pieces: np.ndarray
    key_matrix: csr_matrix
    key_starts: np.ndarray
    edge_u: np.ndarray  # the sampled pieces (vertex ids), in chain order; weights edge_w
    edge_v: np.ndarray
    edge_w: np.ndarray
    seg_a: np.ndarray
    seg_b: np.ndarray
    seg_chain: np.ndarray
    seg_arc: np.ndarray
    _tree: object = field(default=None, repr=False)
    _matrix: object = field(default=None, repr=False)

    @property
    def n_vertices(self) -> int:
        return len(self.points)

    @property
    def n_components(self) -> int:
        return len(self.starts) - 1

    def component_sizes(self) -> np.ndarray:
        return np.diff(self.starts)

    @property
    def matrix(self) -> csr_matrix:
        """The symmetric arc-length adjacency of the sampled vertices (for inspection and tests)."""
        if self._matrix is None:
            self._matrix = _adjacency(self.n_vertices, self.edge_u, self.edge_v, self.edge_w)
        return self._matrix

    def vertex_locations(self, ids) -> Locations:
        """Where sampled vertices ``ids`` lie: on a chain, or at a key."""
        ids = np.asarray(ids, dtype=np.int64)
        key, chain, arc = self.vertex_key[ids], self.vertex_chain[ids], self.vertex_arc[ids]
        if len(self.chain_start) == 0:  # only isolated vertices
            return Locations(
                np.stack([key, key], axis=1), np.zeros((len(ids), 2)), np.full(len(ids), -1), np.zeros(len(ids))
            )
        on_chain = key < 0
        c = np.where(on_chain, chain, 0)
        ends = np.stack([self.chain_start[c], self.chain_end[c]], axis=1)
        exit_key = np.where(on_chain[:, None], ends, key[:, None])
        exit_off = np.where(on_chain[:, None], np.stack([arc, self.chain_length[c] - arc], axis=1), 0.0)
        return Locations(
            exit_key.astype(np.int64), exit_off, np.where(on_chain, chain, -1), np.where(on_chain, arc, 0.0)
        )

    def locate(self, query: np.ndarray, buffer: float) -> tuple[np.ndarray, Locations]:
        """Project each query point onto the nearest segment within ``buffer`` (inclusive).

        Returns ``(found, locations)``; the locations of points not found are meaningless.
        """
        query = np.asarray(query, dtype=float).reshape(-1, 2)
        n = len(query)
        chain = np.zeros(n, dtype=np.int64)
        arc = np.zeros(n)
        found = np.zeros(n, dtype=bool)
        if n == 0 or len(self.seg_a) == 0:
            return found, Locations(np.zeros((n, 2), dtype=np.int64), np.zeros((n, 2)), np.full(n, -1), arc)
        import shapely

        if self._tree is None:
            self._tree = shapely.STRtree(shapely.linestrings(np.stack([self.seg_a, self.seg_b], axis=1)))
        (qi, si), _ = self._tree.query_nearest(
            shapely.points(query), max_distance=buffer, return_distance=True, all_matches=False
        )
        a, d = self.seg_a[si], self.seg_b[si] - self.seg_a[si]
        length2 = (d**2).sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(np.where(length2 > 0, ((query[qi] - a) * d).sum(axis=1) / length2, 0.0), 0.0, 1.0)
        chain[qi] = self.seg_chain[si]
        arc[qi] = np.minimum(self.seg_arc[si] + t * np.sqrt(length2), self.chain_length[self.seg_chain[si]])
        found[qi] = True
        exit_key = np.stack([self.chain_start[chain], self.chain_end[chain]], axis=1)
        exit_off = np.stack([arc, self.chain_length[chain] - arc], axis=1)
        return found, Locations(exit_key.astype(np.int64), exit_off, chain, arc)


def resample(seg: Segments, spacing: float) -> SampledGraph:
    """Resample every chain of ``seg`` into pieces of equal length at most ``spacing``."""
    if spacing <= 0:
        raise ValueError(f"spacing must be > 0, got {spacing}")
    pts, edges = seg.points, seg.edges
    found = find_chains(len(pts), edges)
    chains, anchor = found.vertices, found.anchor
    anchor_ids = np.flatnonzero(anchor)
    key_id = np.full(len(pts), -1, dtype=np.int64)
    key_id[anchor_ids] = np.arange(len(anchor_ids))
    n_keys = len(anchor_ids)
    n_chains = len(chains)

    if n_chains:
        lens = np.fromiter((len(c) for c in chains), dtype=np.int64, count=n_chains)
        flat = np.fromiter((v for c in chains for v in c), dtype=np.int64, count=int(lens.sum()))
        seq_off = np.concatenate([[0], np.cumsum(lens)])
        P = pts[flat]
        inner = np.ones(len(flat) - 1, dtype=bool)
        inner[seq_off[1:-1] - 1] = False  # the step from one chain's last vertex to the next's first
        seg_a = P[:-1][inner]
        seg_b = P[1:][inner]
        seg_len = np.linalg.norm(seg_b - seg_a, axis=1)
        seg_chain = np.repeat(np.arange(n_chains), lens - 1)
        seg_first = np.concatenate([[0], np.cumsum(lens - 1)])[:-1]
        before = np.cumsum(seg_len) - seg_len
        seg_arc = before - before[seg_first][seg_chain]
        chain_length = np.bincount(seg_chain, weights=seg_len, minlength=n_chains)
        pieces = np.maximum(1, np.ceil(chain_length / spacing - 1e-9)).astype(np.int64)
        if pieces.sum() > MAX_SAMPLES:
            raise RasterTooLarge(
                f"the boundaries are {chain_length.sum():.3g} px long (sampling limit {MAX_SAMPLES:.0e} points)"
            )
        step = chain_length / pieces
        # interior samples j * step, j = 1 .. pieces - 1, located on their segment
        n_inner = pieces - 1
        s_chain = np.repeat(np.arange(n_chains), n_inner)
        j = np.arange(int(n_inner.sum())) - np.repeat(np.concatenate([[0], np.cumsum(n_inner)])[:-1], n_inner)
        s_arc = (j + 1) * step[s_chain]
        k = np.searchsorted(before, before[seg_first][s_chain] + s_arc, side="right") - 1
        k = np.clip(k, seg_first[s_chain], seg_first[s_chain] + lens[s_chain] - 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(seg_len[k] > 0, (s_arc - seg_arc[k]) / seg_len[k], 0.0)
        t = np.clip(t, 0.0, 1.0)
        inner_pts = seg_a[k] + t[:, None] * (seg_b[k] - seg_a[k])
        chain_start = key_id[flat[seq_off[:-1]]]
        chain_end = key_id[flat[seq_off[1:] - 1]]
        # node sequence of every chain: start key, interior samples, end key
        node_off = np.concatenate([[0], np.cumsum(pieces + 1)])
        nodes = np.empty(int(node_off[-1]), dtype=np.int64)
        first_pos, last_pos = node_off[:-1], node_off[1:] - 1
        nodes[first_pos] = chain_start
        nodes[last_pos] = chain_end
        middle = np.ones(len(nodes), dtype=bool)
        middle[first_pos] = middle[last_pos] = False
        nodes[middle] = n_keys + np.arange(int(n_inner.sum()))
        step_ok = np.ones(len(nodes) - 1, dtype=bool)
        step_ok[last_pos[:-1]] = False
        edge_u, edge_v = nodes[:-1][step_ok], nodes[1:][step_ok]
        edge_w = np.repeat(step, pieces)
    else:
        seg_a = seg_b = inner_pts = np.zeros((0, 2))
        seg_chain = s_chain = chain_start = chain_end = pieces = edge_u = edge_v = np.zeros(0, dtype=np.int64)
        seg_arc = s_arc = chain_length = edge_w = np.zeros(0)

    # components of the key graph (chains as edges); keys and vertices are numbered by component
    key_matrix = _adjacency(n_keys, chain_start, chain_end, chain_length)
    n_comp, key_label = connected_components(key_matrix, directed=False) if n_keys else (0, np.zeros(0, dtype=np.int64))
    key_order = np.argsort(key_label, kind="stable")
    new_key = np.empty(n_keys, dtype=np.int64)
    new_key[key_order] = np.arange(n_keys)
    key_label = key_label[key_order].astype(np.int64)
    chain_start, chain_end = new_key[chain_start], new_key[chain_end]
    key_starts = np.concatenate([[0], np.cumsum(np.bincount(key_label, minlength=n_comp))]).astype(np.int64)

    points = np.concatenate([pts[anchor_ids], inner_pts]).reshape(-1, 2)
    m = len(points)
    v_key = np.concatenate([new_key, np.full(len(s_chain), -1, dtype=np.int64)])
    v_chain = np.concatenate([np.full(n_keys, -1, dtype=np.int64), s_chain]).astype(np.int64)
    v_arc = np.concatenate([np.zeros(n_keys), s_arc])
    v_label = np.concatenate([key_label[new_key], key_label[chain_start[s_chain]]]).astype(np.int64)
    order = np.argsort(v_label, kind="stable")
    renumber = np.empty(m, dtype=np.int64)
    renumber[order] = np.arange(m)
    labels = v_label[order]
    return SampledGraph(
        points=points[order],
        labels=labels,
        starts=np.concatenate([[0], np.cumsum(np.bincount(labels, minlength=n_comp))]).astype(np.int64),
        vertex_key=v_key[order],
        vertex_chain=v_chain[order],
        vertex_arc=v_arc[order],
        chain_start=chain_start,
        chain_end=chain_end,
        chain_length=chain_length,
        chain_pieces=pieces,
        key_matrix=_adjacency(n_keys, chain_start, chain_end, chain_length),
        key_starts=key_starts,
        edge_u=renumber[edge_u],
        edge_v=renumber[edge_v],
        edge_w=edge_w,
        seg_a=seg_a,
        seg_b=seg_b,
        seg_chain=seg_chain,
        seg_arc=seg_arc,
    )


def _adjacency(m: int, u: np.ndarray, v: np.ndarray, w: np.ndarray) -> csr_matrix:
    """Symmetric CSR adjacency; parallel edges keep their shortest weight, self-loops are dropped."""
    rows = np.concatenate([u, v]).astype(np.int64)
    cols = np.concatenate([v, u]).astype(np.int64)
    weights = np.maximum(np.concatenate([w, w]), _MIN_WEIGHT)
    keep = rows != cols
    rows, cols, weights = rows[keep], cols[keep], weights[keep]
    order = np.lexsort((weights, cols, rows))
    rows, cols, weights = rows[order], cols[order], weights[order]
    first = np.ones(len(rows), dtype=bool)
    first[1:] = (rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1])
    return csr_matrix((weights[first], (rows[first], cols[first])), shape=(m, m))
