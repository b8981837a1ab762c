"""A graph cut to the imagery's window before any metric densifies, samples or rasterises it.

A line that runs far outside the imagery (a 1,000 km label) would otherwise cost time and memory
in proportion to its length in every step that walks along it (the confidence's and the
simulated review's 1 px samples, rasters); cut first, the cost follows the imagery's size.
Pure functions: the graph's topology inside the window is kept (vertices inside keep their
identity, an edge crossing the border ends in a new vertex on it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.metrics.confidence_quality import TRUE_WITHIN_PX
from csboundary.metrics.segments import clip_parameters

# what any metric looks at across the imagery's border: a line inside is judged true against the
# ground truth up to 5 px away (confidence, simulated review); the pixel metrics, APLS and TLTS
# clip to the imagery itself
MARGIN_PX = TRUE_WITHIN_PX


def grown(extent: tuple[float, float, float, float], margin: float = MARGIN_PX) -> tuple[float, float, float, float]:
    """``extent`` (x0, y0, x1, y1) grown by ``margin`` on every side."""
    x0, y0, x1, y1 = extent
    return (x0 - margin, y0 - margin, x1 + margin, y1 + margin)


@dataclass(frozen=True)
class Piece:
    """One run of a polyline inside a window; whether it starts at the polyline's first point and
    ends at its last (there it keeps the edge's vertex, elsewhere it ends on the border)."""

    points: np.ndarray
    from_start: bool
    to_end: bool


def clip_polyline(line: np.ndarray, window: tuple[float, float, float, float]) -> list[Piece]:
    """The runs of ``line`` (M, 2) inside ``window`` (x0, y0, x1, y1), in order along it."""
    line = np.asarray(line, float).reshape(-1, 2)
    if len(line) < 2:
        return []
    a, d = line[:-1], np.diff(line, axis=0)
    t0, t1, keep = clip_parameters(a, d, *window)
    kept = np.flatnonzero(keep)
    if not len(kept):
        return []
    joined = (np.diff(kept) == 1) & (t1[kept[:-1]] == 1) & (t0[kept[1:]] == 0)  # the shared point is inside
    pieces = []
    for run in np.split(kept, np.flatnonzero(~joined) + 1):
        i, j = int(run[0]), int(run[-1])
        start = line[i] if t0[i] == 0 else a[i] + t0[i] * d[i]
        end = line[j + 1] if t1[j] == 1 else a[j] + t1[j] * d[j]
        points = np.vstack([start, line[i + 1 : j + 1], end])
        if np.any(points != points[0]):  # a run of zero length (a point on the border) is no line
            pieces.append(Piece(points, i == 0 and t0[i] == 0, j == len(a) - 1 and t1[j] == 1))
    return pieces


def clip_graph(graph: BoundaryGraph, window: tuple[float, float, float, float]) -> BoundaryGraph:
    """The part of ``graph`` inside ``window`` (x0, y0, x1, y1 pixels); the graph itself when all
    of it lies inside. Each piece of a cut edge keeps that edge's kind, score and patch; edges
    keep their order (pieces in the place of their edge); isolated vertices outside go."""
    x0, y0, x1, y1 = window
    low, high = _edge_boxes(graph)
    vertices = graph.vertices
    vertex_inside = (vertices[:, 0] >= x0) & (vertices[:, 0] <= x1) & (vertices[:, 1] >= y0) & (vertices[:, 1] <= y1)
    inside = (low[:, 0] >= x0) & (low[:, 1] >= y0) & (high[:, 0] <= x1) & (high[:, 1] <= y1)
    if inside.all() and vertex_inside.all():
        return graph
    crossing = np.flatnonzero(~inside & (high[:, 0] >= x0) & (high[:, 1] >= y0) & (low[:, 0] <= x1) & (low[:, 1] <= y1))
    kept = np.flatnonzero(inside)
    source, ends = list(kept), [graph.edges[kept]]
    polylines = [None if graph.edge_polylines is None else graph.edge_polylines[k] for k in kept]
    border: list[np.ndarray] = []
    for k in crossing.tolist():
        u, v = graph.edges[k].tolist()
        line = graph.edge_polyline(k)
        if np.linalg.norm(line[0] - vertices[u]) > np.linalg.norm(line[0] - vertices[v]):
            u, v = v, u  # stored from v to u: its first point is v
        for piece in clip_polyline(line, window):
            a = u if piece.from_start else len(vertices) + len(border)
            border += [] if piece.from_start else [piece.points[0]]
            b = v if piece.to_end else len(vertices) + len(border)
            border += [] if piece.to_end else [piece.points[-1]]
            source.append(k)
            ends.append(np.array([[a, b]]))
            polylines.append(piece.points if len(piece.points) > 2 else None)
    source = np.asarray(source, np.int64)
    order = np.argsort(source, kind="stable")
    source, edges = source[order], np.concatenate(ends).reshape(-1, 2)[order]
    points = np.concatenate([vertices, np.asarray(border, float).reshape(-1, 2)])
    used = np.zeros(len(points), bool)
    used[edges.ravel()] = True
    used[: len(vertices)] |= vertex_inside & (np.bincount(graph.edges.ravel(), minlength=len(vertices)) == 0)
    renumber = np.cumsum(used) - 1
    kinds = graph.vertex_kinds
    return BoundaryGraph(
        points[used],
        renumber[edges],
        vertex_kinds=None
        if kinds is None
        else [kinds[i] if i < len(kinds) else "" for i in np.flatnonzero(used).tolist()],
        edge_kinds=None if graph.edge_kinds is None else [graph.edge_kinds[k] for k in source.tolist()],
        edge_polylines=None if graph.edge_polylines is None else [polylines[i] for i in order.tolist()],
        edge_scores=None if graph.edge_scores is None else np.asarray(graph.edge_scores, float)[source],
        edge_patches=None if graph.edge_patches is None else graph.edge_patches[source],
        transform=graph.transform,
        crs=graph.crs,
    )


def _edge_boxes(graph: BoundaryGraph) -> tuple[np.ndarray, np.ndarray]:
    """(E, 2) lowest and highest (col, row) of every edge: its two vertices and its polyline."""
    u, v = graph.vertices[graph.edges[:, 0]], graph.vertices[graph.edges[:, 1]]
    low, high = np.minimum(u, v), np.maximum(u, v)
    for k, line in enumerate(graph.edge_polylines or []):
        if line is not None and len(line):
            line = np.asarray(line, float).reshape(-1, 2)
            low[k], high[k] = np.minimum(low[k], line.min(axis=0)), np.maximum(high[k], line.max(axis=0))
    return low, high
