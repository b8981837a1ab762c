"""Decoding a patch's graph: extracted vertices + an adjacency matrix -> the patch graph.

Shared by csBoundary (AfANet's adjacency), the ground-truth oracle (adjacency labels) and the
Sat2Graph baseline: corner edges from vertex extraction are kept with their skeleton polylines
smoothed, the other edges are decoded greedily from the probabilities.
"""

from __future__ import annotations

import numpy as np
import torch
from shapely.geometry import LineString

from csboundary.graph import BoundaryGraph
from csboundary.models.afanet import edges_from_adjacency

CORNER_SIMPLIFY_PX = 0.75  # skeleton staircases -> smooth polylines (they are ~5 % too long otherwise)


def _smooth(polyline: np.ndarray | None) -> np.ndarray | None:
    """A corner edge's skeleton path without its pixel staircase (Douglas-Peucker, ends kept)."""
    if polyline is None or len(polyline) < 3:
        return polyline
    return np.asarray(LineString(polyline).simplify(CORNER_SIMPLIFY_PX).coords)


def graph_from_adjacency(
    found: BoundaryGraph, probs: np.ndarray, threshold: float, max_degree: int | None
) -> BoundaryGraph:
    """Extracted vertices + an (M, M) edge probability matrix -> the patch graph.

    Corner edges from vertex extraction are always kept (kind ``corner``, their skeleton smoothed
    into the polyline, score = mean keypoint probability along it); the other edges are decoded
    from ``probs`` (kind ``normal``, score = their probability).
    """
    corner = [tuple(int(x) for x in e) for e in found.edges]
    polylines = (
        {tuple(sorted(e)): _smooth(found.edge_polylines[k]) for k, e in enumerate(corner)}
        if found.edge_polylines
        else {}
    )
    corner_scores = (
        {tuple(sorted(e)): float(found.edge_scores[k]) for k, e in enumerate(corner)}
        if found.edge_scores is not None
        else {}
    )
    edges = (
        edges_from_adjacency(torch.as_tensor(probs, dtype=torch.float32), threshold, max_degree, fixed=corner)
        if len(probs) >= 2
        else [tuple(sorted(e)) for e in corner]
    )
    kinds, lines, scores = [], [], []
    for u, v in edges:
        line = polylines.get((u, v))
        if line is not None:
            line = np.asarray(line)
            if np.linalg.norm(line[0] - found.vertices[u]) > np.linalg.norm(line[0] - found.vertices[v]):
                line = line[::-1]
        kinds.append("corner" if line is not None else "normal")
        lines.append(line)
        scores.append(corner_scores.get((u, v), 1.0) if line is not None else float(probs[u, v]))
    return BoundaryGraph(
        found.vertices,
        np.array(edges, dtype=np.int64).reshape(-1, 2),
        vertex_kinds=found.vertex_kinds,
        edge_kinds=kinds,
        edge_polylines=lines,
        edge_scores=np.array(scores, dtype=float),
    )
