"""A graph as straight segments, the form every metric starts from: each polyline point a vertex,
each edge a straight segment, topology from the graph's edges only, never from coincident
coordinates. Also the whole-pixel common origin and clipping to a window, which keep topology.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph


@dataclass(frozen=True)
class Segments:
    """A graph as straight segments: ``points`` (N, 2) float pixel (col, row), ``edges`` (E, 2) int."""

    points: np.ndarray
    edges: np.ndarray

    @classmethod
    def empty(cls) -> "Segments":
        return cls(np.zeros((0, 2)), np.zeros((0, 2), dtype=np.int64))

    @property
    def n_points(self) -> int:
        return len(self.points)

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    def shifted(self, offset) -> "Segments":
        return Segments(self.points - np.asarray(offset, dtype=float), self.edges)


def flatten(graph: BoundaryGraph) -> Segments:
    """Every polyline point becomes a vertex, every edge a chain of straight segments.

    A polyline's end points are replaced by the edge's vertices (it is reversed if it was stored
    from ``v`` to ``u``). Self-loops without a polyline (zero length, no shape) are dropped; a
    closed polyline from a vertex back to itself is kept as a loop.
    """
    points = [np.asarray(graph.vertices, dtype=float).reshape(-1, 2)]
    edges = []
    next_id = graph.n_vertices
    polylines = graph.edge_polylines
    straight = []
    for k, (u, v) in enumerate(graph.edges.tolist()):
        line = polylines[k] if polylines is not None else None
        if line is None or len(line) <= 2:
            straight.append(k)
            continue
        line = np.asarray(line, dtype=float)
        if np.linalg.norm(line[0] - graph.vertices[u]) > np.linalg.norm(line[0] - graph.vertices[v]):
            line = line[::-1]  # stored from v to u: follow it from u
        interior = line[1:-1]
        ids = np.arange(next_id, next_id + len(interior))
        next_id += len(interior)
        points.append(interior)
        chain = np.concatenate([[u], ids, [v]])
        edges.append(np.stack([chain[:-1], chain[1:]], axis=1))
    edges.insert(0, graph.edges[straight].reshape(-1, 2))
    edges = np.concatenate(edges).astype(np.int64) if edges else np.zeros((0, 2), dtype=np.int64)
    edges = edges[edges[:, 0] != edges[:, 1]]
    return Segments(np.concatenate(points), edges)


def common_origin(*parts: Segments) -> np.ndarray:
    """Whole-pixel origin (floor of the smallest coordinates) of several graphs.

    Metrics subtract it before any computation so that results do not depend on where the
    graphs lie: translating both graphs by a whole number of pixels changes nothing.
    """
    points = [p.points for p in parts if p.n_points]
    if not points:
        return np.zeros(2)
    return np.floor(np.concatenate(points).min(axis=0))


def clip_parameters(
    a: np.ndarray, d: np.ndarray, x0: float, y0: float, x1: float, y1: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Liang-Barsky for the (S, 2) segments ``a -> a + d``: the parameters ``t0 < t1`` in [0, 1]
    of the part of each inside [x0, x1] x [y0, y1], and which segments have such a part."""
    t0 = np.zeros(len(a))
    t1 = np.ones(len(a))
    keep = np.ones(len(a), dtype=bool)
    for p, q in ((-d[:, 0], a[:, 0] - x0), (d[:, 0], x1 - a[:, 0]), (-d[:, 1], a[:, 1] - y0), (d[:, 1], y1 - a[:, 1])):
        parallel = p == 0
        keep &= ~(parallel & (q < 0))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(parallel, 0.0, q / np.where(parallel, 1.0, p))
        t0 = np.where(~parallel & (p < 0), np.maximum(t0, t), t0)
        t1 = np.where(~parallel & (p > 0), np.minimum(t1, t), t1)
    return t0, t1, keep & (t0 < t1)


def clip(seg: Segments, x0: float, y0: float, x1: float, y1: float) -> Segments:
    """The part of the graph inside the rectangle [x0, x1] x [y0, y1] (Liang-Barsky, vectorised).

    Vertices inside keep their identity (so topology inside the window is unchanged); a segment
    crossing the border ends in a new vertex on the border.
    """
    if seg.n_points == 0:
        return seg
    pts, edges = seg.points, seg.edges
    a, b = pts[edges[:, 0]], pts[edges[:, 1]]
    d = b - a
    t0, t1, keep = clip_parameters(a, d, x0, y0, x1, y1)
    a, d, t0, t1, edges = a[keep], d[keep], t0[keep], t1[keep], edges[keep]
    n = len(pts)
    cut0, cut1 = t0 > 0, t1 < 1
    new0 = a[cut0] + t0[cut0, None] * d[cut0]
    new1 = a[cut1] + t1[cut1, None] * d[cut1]
    u = edges[:, 0].copy()
    v = edges[:, 1].copy()
    u[cut0] = n + np.arange(cut0.sum())
    v[cut1] = n + cut0.sum() + np.arange(cut1.sum())
    all_pts = np.concatenate([pts, new0, new1])
    inside = (pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1)
    degree = np.bincount(seg.edges.ravel(), minlength=n)
    used = np.zeros(len(all_pts), dtype=bool)
    used[u] = used[v] = True
    used[:n] |= inside & (degree == 0)  # isolated vertices inside the window stay
    new_id = np.cumsum(used) - 1
    return Segments(all_pts[used], np.stack([new_id[u], new_id[v]], axis=1).astype(np.int64))
