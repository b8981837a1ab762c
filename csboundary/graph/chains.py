"""Chains: the maximal runs of edges through vertices of degree 2, and closed loops.

A road boundary is one line however many edges the prediction cut it into, so both the topology
metrics (which resample chains, not edges) and the map outputs (one feature per boundary) work on
chains. A chain ends at vertices of degree != 2 (ends, junctions); a component made only of
degree-2 vertices is a closed loop, anchored at the first vertex of its lowest-numbered edge.
Self-loops and parallel edges are ordinary edges here: every edge lies on exactly one chain.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph


class Chains(NamedTuple):
    """``vertices[c]`` is chain c's vertex sequence (first == last for a loop), ``edges[c]`` the
    edges between them in walk order; ``anchor`` (N,) marks the chain ends (degree != 2 and the
    loops' anchors)."""

    vertices: list[list[int]]
    edges: list[list[int]]
    anchor: np.ndarray


def chains(n_points: int, edges: np.ndarray) -> Chains:
    """Maximal chains of an undirected graph of ``n_points`` vertices and ``edges`` (E, 2).

    Walks start at every vertex of degree != 2, in vertex order, along its edges in edge order;
    the edges still unused afterwards form closed loops. The result is deterministic, so the
    metrics built on it are reproducible.
    """
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    degree = np.bincount(edges.ravel(), minlength=n_points)
    anchor = degree != 2
    e_ids = np.arange(len(edges))
    ends = np.concatenate([edges[:, 0], edges[:, 1]])
    order = np.argsort(ends, kind="stable")  # the incidence lists, CSR-style
    inc_edge = np.concatenate([e_ids, e_ids])[order].tolist()
    inc_other = np.concatenate([edges[:, 1], edges[:, 0]])[order].tolist()
    indptr = np.concatenate([[0], np.cumsum(degree)]).tolist()
    is_anchor = anchor.tolist()
    used = [False] * len(edges)
    vertex_seqs: list[list[int]] = []
    edge_seqs: list[list[int]] = []

    def walk(start: int, slot: int) -> None:
        seq, path = [start], []
        e, nxt = inc_edge[slot], inc_other[slot]
        while True:
            used[e] = True
            seq.append(nxt)
            path.append(e)
            if is_anchor[nxt]:
                vertex_seqs.append(seq)
                edge_seqs.append(path)
                return
            s = indptr[nxt]  # a degree-2 vertex: leave by its other edge
            if inc_edge[s] == e:
                s += 1
            e, nxt = inc_edge[s], inc_other[s]

    for k in np.flatnonzero(anchor).tolist():
        for slot in range(indptr[k], indptr[k + 1]):
            if not used[inc_edge[slot]]:
                walk(k, slot)
    for e in range(len(edges)):
        if not used[e]:  # a loop of degree-2 vertices: anchor it at the edge's first vertex
            start = int(edges[e, 0])
            is_anchor[start] = True
            anchor[start] = True
            walk(start, indptr[start] if inc_edge[indptr[start]] == e else indptr[start] + 1)
    return Chains(vertex_seqs, edge_seqs, anchor)


@dataclass(frozen=True, eq=False)  # array fields: compare them explicitly
class Chain:
    """One merged boundary: ``vertices`` (n + 1,) in walk order, ``edges`` (n,) between them,
    ``reversed`` (n,) True where an edge is walked from its v to its u, and ``polyline`` (m, 2)
    the pixel line through all of them."""

    vertices: np.ndarray
    edges: np.ndarray
    reversed: np.ndarray
    polyline: np.ndarray

    @property
    def closed(self) -> bool:
        return bool(self.vertices[0] == self.vertices[-1])


def edge_line(graph: BoundaryGraph, k: int) -> np.ndarray:
    """Pixel polyline of edge ``k`` from u to v, its end points pinned to the two vertices.

    Pinning makes consecutive edges of a chain share their end point exactly, so a merged line
    has no gaps even if a stored polyline ends a rounding error away from its vertex. A polyline
    stored from v to u (closer to v at its start) is turned round, as the metrics do.
    """
    u, v = graph.edges[k]
    line = np.array(graph.edge_polyline(k), dtype=float).reshape(-1, 2)
    pu, pv = graph.vertices[u], graph.vertices[v]
    if len(line) < 2:
        return np.stack([pu, pv])
    if np.linalg.norm(line[0] - pu) > np.linalg.norm(line[0] - pv):
        line = line[::-1].copy()
    line[0], line[-1] = pu, pv
    return line


def merge_chains(graph: BoundaryGraph) -> list[Chain]:
    """The graph's chains (see :func:`chains`) with their polylines: each edge's line in walk
    order, reversed when walked backwards, the shared vertex written once. A loop's polyline is
    closed (first point == last point)."""
    found = chains(graph.n_vertices, graph.edges)
    out = []
    for verts, path in zip(found.vertices, found.edges):
        verts, path = np.asarray(verts, dtype=np.int64), np.asarray(path, dtype=np.int64)
        backwards = graph.edges[path, 0] != verts[:-1]  # a self-loop counts as walked forwards
        pieces = [
            edge_line(graph, k)[::-1] if back else edge_line(graph, k) for k, back in zip(path.tolist(), backwards)
        ]
        polyline = np.concatenate([pieces[0]] + [p[1:] for p in pieces[1:]])
        out.append(Chain(verts, path, backwards, polyline))
    return out
