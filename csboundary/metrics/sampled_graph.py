"""A graph resampled along its chains at a fixed spacing (:func:`resample`), so that vertex density
no longer depends on how the input was digitised, and the locations of points on it that the
shortest paths (:mod:`csboundary.metrics.paths`) start and end at.

See :mod:`csboundary.metrics.sampling` for how chains are cut and why paths run over keys only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

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
    pts = seg.points
    found = find_chains(len(pts), seg.edges)
    anchor_ids = np.flatnonzero(found.anchor)
    n_keys = len(anchor_ids)
    key_id = np.full(len(pts), -1, dtype=np.int64)
    key_id[anchor_ids] = np.arange(n_keys)
    sampled = _sample_chains(pts, found.vertices, key_id, n_keys, spacing) if found.vertices else _SampledChains.empty()
    # the keys, then all vertices, numbered component by component of the key graph (chains as its edges)
    n_comp, key_label = _key_components(n_keys, sampled.chain_start, sampled.chain_end, sampled.chain_length)
    key_order, new_key = _component_order(key_label)
    key_label = key_label[key_order].astype(np.int64)
    chain_start, chain_end = new_key[sampled.chain_start], new_key[sampled.chain_end]
    vertices = _vertices_by_component(pts[anchor_ids], new_key, key_label, chain_start, sampled)
    return SampledGraph(
        points=vertices.points,
        labels=vertices.labels,
        starts=_block_starts(vertices.labels, n_comp),
        vertex_key=vertices.key,
        vertex_chain=vertices.chain,
        vertex_arc=vertices.arc,
        chain_start=chain_start,
        chain_end=chain_end,
        chain_length=sampled.chain_length,
        chain_pieces=sampled.pieces,
        key_matrix=_adjacency(n_keys, chain_start, chain_end, sampled.chain_length),
        key_starts=_block_starts(key_label, n_comp),
        edge_u=vertices.renumber[sampled.edge_u],
        edge_v=vertices.renumber[sampled.edge_v],
        edge_w=sampled.edge_w,
        seg_a=sampled.seg_a,
        seg_b=sampled.seg_b,
        seg_chain=sampled.seg_chain,
        seg_arc=sampled.seg_arc,
    )


class _SampledChains(NamedTuple):
    """The chains of a graph cut into pieces, keys still in the graph's vertex order.

    ``seg_a``, ``seg_b`` (S, 2) are the input segments chain by chain, on chain ``seg_chain`` (S,)
    at arc ``seg_arc`` (S,) from its start. Chain c runs from key ``chain_start[c]`` to key
    ``chain_end[c]`` over ``chain_length[c]`` and is cut into ``pieces[c]`` >= 1 pieces. The
    interior samples (K,) lie at ``sample_points`` (K, 2), on chain ``sample_chain`` at arc
    ``sample_arc``; sample i is vertex ``n_keys + i``. The pieces are the edges ``edge_u`` ->
    ``edge_v`` of length ``edge_w``, chain by chain in walk order.
    """

    seg_a: np.ndarray
    seg_b: np.ndarray
    seg_chain: np.ndarray
    seg_arc: np.ndarray
    chain_start: np.ndarray
    chain_end: np.ndarray
    chain_length: np.ndarray
    pieces: np.ndarray
    sample_chain: np.ndarray
    sample_arc: np.ndarray
    sample_points: np.ndarray
    edge_u: np.ndarray
    edge_v: np.ndarray
    edge_w: np.ndarray

    @classmethod
    def empty(cls) -> "_SampledChains":
        """A graph without chains (no edges): nothing to cut."""
        points, ids, lengths = np.zeros((0, 2)), np.zeros(0, dtype=np.int64), np.zeros(0)
        return cls(points, points, ids, lengths, ids, ids, lengths, ids, ids, lengths, points, ids, ids, lengths)


class _ChainSegments(NamedTuple):
    """The segments of all chains laid end to end: ``a``, ``b`` (S, 2) their ends, ``length`` (S,),
    ``chain`` (S,) the chain each lies on, ``arc`` (S,) the arc length from its chain's start to
    its start, ``before`` (S,) the same over all chains laid end to end, and ``first`` (C,) each
    chain's first segment."""

    a: np.ndarray
    b: np.ndarray
    length: np.ndarray
    chain: np.ndarray
    arc: np.ndarray
    before: np.ndarray
    first: np.ndarray


class _Vertices(NamedTuple):
    """The sampled vertices numbered by component: ``points`` (M, 2), non-decreasing component
    ``labels`` (M,), ``key`` (M,) key id or -1, ``chain`` (M,) chain id or -1 and ``arc`` (M,) arc
    position along it; ``renumber`` (M,) maps the keys-then-samples numbering of
    :class:`_SampledChains` to this one."""

    points: np.ndarray
    labels: np.ndarray
    key: np.ndarray
    chain: np.ndarray
    arc: np.ndarray
    renumber: np.ndarray


def _sample_chains(
    points: np.ndarray, chains: list[list[int]], key_id: np.ndarray, n_keys: int, spacing: float
) -> _SampledChains:
    """Cut each of ``chains`` (vertex sequences into ``points``, at least one chain) into the
    fewest pieces of equal length at most ``spacing``.

    ``key_id`` (N,) numbers the chain ends 0 .. ``n_keys`` - 1 (-1 elsewhere). Raises
    :class:`RasterTooLarge` when the samples would exceed ``MAX_SAMPLES``, before any is made.
    """
    lens, flat, seq_off = _laid_end_to_end(chains)
    segs = _chain_segments(points[flat], lens, seq_off)
    chain_length = np.bincount(segs.chain, weights=segs.length, minlength=len(chains))
    pieces = _piece_counts(chain_length, spacing)
    step = chain_length / pieces
    samples = _interior_samples(segs, lens, pieces, step)
    chain_start = key_id[flat[seq_off[:-1]]]
    chain_end = key_id[flat[seq_off[1:] - 1]]
    edges = _piece_edges(chain_start, chain_end, pieces, step, n_keys)
    return _SampledChains(
        segs.a, segs.b, segs.chain, segs.arc, chain_start, chain_end, chain_length, pieces, *samples, *edges
    )


def _laid_end_to_end(chains: list[list[int]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The vertex sequences of ``chains`` as flat arrays: ``lens`` (C,) each sequence's length,
    ``flat`` (sum(lens),) the sequences one after another and ``seq_off`` (C + 1,) where each
    starts in ``flat``."""
    lens = np.fromiter((len(c) for c in chains), dtype=np.int64, count=len(chains))
    flat = np.fromiter((v for c in chains for v in c), dtype=np.int64, count=int(lens.sum()))
    seq_off = np.concatenate([[0], np.cumsum(lens)])
    return lens, flat, seq_off


def _chain_segments(path: np.ndarray, lens: np.ndarray, seq_off: np.ndarray) -> _ChainSegments:
    """The straight segments of the chains whose vertex positions ``path`` (sum(lens), 2) lie one
    after another as :func:`_laid_end_to_end` gives them; the step from one chain's last vertex to
    the next one's first is no segment."""
    inner = np.ones(len(path) - 1, dtype=bool)
    inner[seq_off[1:-1] - 1] = False
    seg_a = path[:-1][inner]
    seg_b = path[1:][inner]
    seg_len = np.linalg.norm(seg_b - seg_a, axis=1)
    seg_chain = np.repeat(np.arange(len(lens)), lens - 1)
    seg_first = np.concatenate([[0], np.cumsum(lens - 1)])[:-1]
    before = np.cumsum(seg_len) - seg_len
    seg_arc = before - before[seg_first][seg_chain]
    return _ChainSegments(seg_a, seg_b, seg_len, seg_chain, seg_arc, before, seg_first)


def _piece_counts(chain_length: np.ndarray, spacing: float) -> np.ndarray:
    """The fewest pieces (>= 1) of length at most ``spacing`` each chain of ``chain_length`` (C,)
    is cut into; a length just over a multiple of ``spacing`` by rounding error adds no piece.
    Raises :class:`RasterTooLarge` above ``MAX_SAMPLES`` pieces in all."""
    pieces = np.maximum(1, np.ceil(chain_length / spacing - 1e-9)).astype(np.int64)
    if pieces.sum() > MAX_SAMPLES:
        raise RasterTooLarge(
            f"the boundaries are {chain_length.sum():.3g} px long (sampling limit {MAX_SAMPLES:.0e} points)"
        )
    return pieces


def _interior_samples(
    segs: _ChainSegments, lens: np.ndarray, pieces: np.ndarray, step: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The interior samples of every chain, at arcs ``j * step`` for j = 1 .. ``pieces`` - 1, each
    interpolated on the segment it falls on (``lens`` (C,) the chains' vertex counts).

    Returns ``(chain, arc, points)``: (K,) chain ids, (K,) arc positions and (K, 2) positions,
    chain by chain in walk order.
    """
    n_inner = pieces - 1
    s_chain = np.repeat(np.arange(len(pieces)), n_inner)
    j = np.arange(int(n_inner.sum())) - np.repeat(np.concatenate([[0], np.cumsum(n_inner)])[:-1], n_inner)
    s_arc = (j + 1) * step[s_chain]
    k = np.searchsorted(segs.before, segs.before[segs.first][s_chain] + s_arc, side="right") - 1
    k = np.clip(k, segs.first[s_chain], segs.first[s_chain] + lens[s_chain] - 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(segs.length[k] > 0, (s_arc - segs.arc[k]) / segs.length[k], 0.0)
    t = np.clip(t, 0.0, 1.0)
    return s_chain, s_arc, segs.a[k] + t[:, None] * (segs.b[k] - segs.a[k])


def _piece_edges(
    chain_start: np.ndarray, chain_end: np.ndarray, pieces: np.ndarray, step: np.ndarray, n_keys: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pieces as edges ``(u, v, w)``: each chain's node sequence is its start key, its
    interior samples (vertices ``n_keys`` on, in order) and its end key, each step one piece of
    length ``step`` of its chain."""
    node_off = np.concatenate([[0], np.cumsum(pieces + 1)])
    nodes = np.empty(int(node_off[-1]), dtype=np.int64)
    first_pos, last_pos = node_off[:-1], node_off[1:] - 1
    nodes[first_pos] = chain_start
    nodes[last_pos] = chain_end
    middle = np.ones(len(nodes), dtype=bool)
    middle[first_pos] = middle[last_pos] = False
    nodes[middle] = n_keys + np.arange(int((pieces - 1).sum()))
    step_ok = np.ones(len(nodes) - 1, dtype=bool)
    step_ok[last_pos[:-1]] = False  # the step from one chain's end key to the next one's start key
    return nodes[:-1][step_ok], nodes[1:][step_ok], np.repeat(step, pieces)


def _key_components(
    n_keys: int, chain_start: np.ndarray, chain_end: np.ndarray, chain_length: np.ndarray
) -> tuple[int, np.ndarray]:
    """The connected components of the key graph (the chains as its edges): their number and each
    key's component label (n_keys,)."""
    key_matrix = _adjacency(n_keys, chain_start, chain_end, chain_length)
    return connected_components(key_matrix, directed=False) if n_keys else (0, np.zeros(0, dtype=np.int64))


def _component_order(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``order``, which sorts ``labels`` stably so that each component becomes one block in its
    earlier order, and its inverse ``renumber``: item i's position in that order."""
    order = np.argsort(labels, kind="stable")
    renumber = np.empty(len(labels), dtype=np.int64)
    renumber[order] = np.arange(len(labels))
    return order, renumber


def _block_starts(labels: np.ndarray, n_comp: int) -> np.ndarray:
    """The offsets (n_comp + 1,) of each component's block in the sorted ``labels``."""
    return np.concatenate([[0], np.cumsum(np.bincount(labels, minlength=n_comp))]).astype(np.int64)


def _vertices_by_component(
    key_points: np.ndarray, new_key: np.ndarray, key_label: np.ndarray, chain_start: np.ndarray, sampled: _SampledChains
) -> _Vertices:
    """The keys at ``key_points`` then the interior samples of ``sampled``, numbered component by
    component (stably), so that shortest paths work on small diagonal blocks.

    ``new_key`` (n_keys,) is each key's id in component order, ``key_label`` the component of
    each key so numbered and ``chain_start`` each chain's start key so numbered.
    """
    n_keys = len(new_key)
    points = np.concatenate([key_points, sampled.sample_points]).reshape(-1, 2)
    v_key = np.concatenate([new_key, np.full(len(sampled.sample_chain), -1, dtype=np.int64)])
    v_chain = np.concatenate([np.full(n_keys, -1, dtype=np.int64), sampled.sample_chain]).astype(np.int64)
    v_arc = np.concatenate([np.zeros(n_keys), sampled.sample_arc])
    v_label = np.concatenate([key_label[new_key], key_label[chain_start[sampled.sample_chain]]]).astype(np.int64)
    order, renumber = _component_order(v_label)
    return _Vertices(points[order], v_label[order], v_key[order], v_chain[order], v_arc[order], renumber)


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
