"""The ground-truth graph of one patch (paper IV-B/IV-C): keypoints as vertices, consecutive
keypoints along a boundary as edges, each gathered run as one "corner" edge with its polyline.
"""

from __future__ import annotations

import numpy as np

from csboundary.data.grid import Patch
from csboundary.data.windows import PixelWindow
from csboundary.graph import BoundaryGraph
from csboundary.labels.keypoints import BoundaryKeypoints
from csboundary.labels.select import inside, near_window

NORMAL_EDGE = "normal"
CORNER_EDGE = "corner"


def window_graph(
    keypoints: list[BoundaryKeypoints], bounds: np.ndarray, window: PixelWindow
) -> tuple[BoundaryGraph, list[tuple[int, int]]]:
    """Graph of the keypoints inside ``window`` (closed), in the window's local pixels.

    An edge joins consecutive keypoints of a boundary when the boundary between them stays in
    the window; patch windows are bounded by keypoint lines, so nothing inside is lost.
    Returns the graph and, per vertex, its global id (boundary index, keypoint index).
    """
    origin = np.array([window.col_off, window.row_off], dtype=float)
    ids: dict[tuple[int, int], int] = {}
    points: list[np.ndarray] = []
    kinds: list[str] = []
    edges: list[tuple[int, int]] = []
    edge_kinds: list[str] = []
    polylines: list[np.ndarray | None] = []
    seen: set[tuple[int, int]] = set()

    def vertex(b: int, k: int, kp: BoundaryKeypoints, xy: np.ndarray) -> int:
        key = (b, k)
        if key not in ids:
            ids[key] = len(points)
            points.append(xy[k] - origin)
            kinds.append(kp.kinds[k])
        return ids[key]

    for b in near_window(bounds, window):
        kp = keypoints[b]
        xy = kp.points
        ok = inside(xy, window)
        for k in np.flatnonzero(ok):
            vertex(int(b), int(k), kp, xy)
        for i, j in kp.stretches():
            if not (ok[i] and ok[j]) or i == j:
                continue
            stretch = kp.boundary.between(kp.s[i], kp.s[j])
            if not inside(stretch, window).all():
                continue
            u, v = vertex(int(b), i, kp, xy), vertex(int(b), j, kp, xy)
            if u == v or (min(u, v), max(u, v)) in seen:  # a ring of two keypoints: one edge
                continue
            seen.add((min(u, v), max(u, v)))
            corner = kp.in_run(kp.stretch_midpoint(i, j))
            edges.append((u, v))
            edge_kinds.append(CORNER_EDGE if corner else NORMAL_EDGE)
            polylines.append(stretch - origin if corner else None)
    order = sorted(ids, key=ids.get)
    graph = BoundaryGraph(
        np.array(points).reshape(-1, 2),
        np.array(edges, dtype=np.int64).reshape(-1, 2),
        vertex_kinds=kinds,
        edge_kinds=edge_kinds,
        edge_polylines=polylines,
    )
    return graph, order


def patch_graph(
    keypoints: list[BoundaryKeypoints], bounds: np.ndarray, patch: Patch, crs: str | None = None
) -> BoundaryGraph:
    """The ground-truth graph of ``patch``'s expanded window, georeferenced by the patch."""
    graph, _ = window_graph(keypoints, bounds, patch.expanded)
    graph.transform = patch.transform
    graph.crs = crs
    return graph
