"""Adjacency labels for any vertex set, ground-truth or predicted (paper Section V-B).

Paper: "The adjacency matrix label can be calculated by using graph vertices and ground-truth
road-boundary binary label maps." Rule used here: each vertex snaps to the nearest ground-truth
boundary within ``snap_tolerance_px``; two vertices are adjacent when they are consecutive along
the same boundary and the boundary between them stays inside the window; a vertex that snaps to
nothing has no edges. On the ground-truth keypoints of a patch this is exactly its patch graph.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry import LineString

from csboundary.data.windows import PixelWindow
from csboundary.labels.boundaries import Boundary
from csboundary.labels.select import inside, near_window


def snap_to_boundaries(
    vertices: np.ndarray, boundaries: list[Boundary], candidates: np.ndarray, tolerance: float
) -> tuple[np.ndarray, np.ndarray]:
    """For each vertex: index of the nearest boundary within ``tolerance`` (-1 if none) and the
    arc length of its projection on that boundary."""
    m = len(vertices)
    which = np.full(m, -1, dtype=int)
    where = np.zeros(m)
    if m == 0 or len(candidates) == 0:
        return which, where
    lines = np.array([LineString(boundaries[c].points) for c in candidates], dtype=object)
    tree = shapely.STRtree(lines)
    pts = shapely.points(vertices)
    (src, dst), _dist = tree.query_nearest(pts, max_distance=tolerance, return_distance=True, all_matches=False)
    which[src] = candidates[dst]
    where[src] = shapely.line_locate_point(lines[dst], pts[src])
    return which, where


def adjacency_label(
    vertices: np.ndarray, boundaries: list[Boundary], bounds: np.ndarray, window: PixelWindow, tolerance: float = 10.0
) -> np.ndarray:
    """(M, M) uint8 symmetric adjacency of ``vertices`` (global pixels) inside ``window``."""
    vertices = np.asarray(vertices, dtype=float).reshape(-1, 2)
    m = len(vertices)
    adjacency = np.zeros((m, m), dtype=np.uint8)
    candidates = near_window(bounds, window, pad=tolerance)
    which, where = snap_to_boundaries(vertices, boundaries, candidates, tolerance)
    for b in np.unique(which[which >= 0]):
        members = np.flatnonzero(which == b)
        members = members[np.argsort(where[members], kind="stable")]
        boundary = boundaries[b]
        pairs = list(zip(members[:-1], members[1:]))
        if boundary.closed and len(members) >= 3:
            pairs.append((members[-1], members[0]))
        for u, v in pairs:
            if _stays_inside(boundary, where[u], where[v], window) or (
                boundary.closed and len(members) == 2 and _stays_inside(boundary, where[v], where[u], window)
            ):
                adjacency[u, v] = adjacency[v, u] = 1
    return adjacency


def _stays_inside(boundary: Boundary, s0: float, s1: float, window: PixelWindow) -> bool:
    return bool(inside(boundary.between(s0, s1), window).all())
