"""Short isolated fragments of a predicted graph: the outlines of roofs, cars and shadows that
the boundary map fires on in real photographs come out as small pieces of their own, while a
road boundary runs on for tens of metres. A connected piece whose edges add up to less than a
minimum length is dropped (``min_fragment_px``; 0 keeps everything)."""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from csboundary.graph.boundary_graph import BoundaryGraph


def fragment_lengths(graph: BoundaryGraph) -> tuple[np.ndarray, np.ndarray]:
    """(E,) the connected piece of every edge (0..P-1) and (P,) each piece's total edge length
    in px (along the polylines). Pieces are those of the vertex graph, so two edges meeting at a
    vertex are in one piece."""
    n = graph.n_vertices
    if graph.n_edges == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    u, v = graph.edges[:, 0], graph.edges[:, 1]
    adjacency = sparse.coo_matrix((np.ones(len(u)), (u, v)), shape=(n, n))
    _, vertex_piece = csgraph.connected_components(adjacency, directed=False)
    edge_piece = vertex_piece[u]
    used, edge_piece = np.unique(edge_piece, return_inverse=True)
    return edge_piece, np.bincount(edge_piece, weights=graph.edge_lengths(), minlength=len(used))


def drop_short_fragments(graph: BoundaryGraph, min_fragment_px: float) -> BoundaryGraph:
    """``graph`` without the connected pieces whose edges add up to less than ``min_fragment_px``
    (the vertices only they use go too); the graph itself when the limit is 0."""
    if min_fragment_px <= 0 or graph.n_edges == 0:
        return graph
    edge_piece, length = fragment_lengths(graph)
    return graph.edge_subgraph(length[edge_piece] >= min_fragment_px)
