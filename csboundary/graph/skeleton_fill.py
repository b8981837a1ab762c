"""Boundary the graph missed, filled in from the segmentation's skeleton (an inference option).

AfANet can only join the vertices that vertex extraction found, and vertex extraction only finds
what the keypoint map lights up. On imagery unlike the training worlds the keypoint heat is weak
along straight real road edges while the segmentation still follows them, so whole boundaries
come out with no vertex and no edge. Here the skeleton of the thresholded boundary map is
compared with the patch graph: skeleton pixels farther than ``cover_px`` from every graph edge
are uncovered, connected uncovered stretches at least ``min_length_px`` long become edges of kind
``skeleton`` (their polylines through the pixel centres, simplified), and a free end of such an
edge within ``snap_px`` of a graph vertex is joined to it, so a stretch that bridges two pieces
of the graph connects them.

In a city the fill is restricted to the window's core plus one pixel row and column on its far
sides: the neighbouring window, which sees the same stitched maps, cuts the same skeleton at the
same pixel, so the two halves share that end vertex and stitch (graph/stitching.py keeps each
half from the core that holds it).

Coordinates are continuous (x, y) pixels of the map, pixel [r, c] centred at (c + 0.5, r + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial import cKDTree
from skimage.morphology import skeletonize

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.pixel_index import nonzero_pixels
from csboundary.graph.polyline import arc_lengths
from csboundary.graph.skeleton_graph import SkeletonConfig, skeleton_graph

SKELETON = "skeleton"  # the kind of a filled edge


@dataclass(frozen=True)
class FillConfig:
    min_length_px: float = 0.0  # shortest uncovered skeleton stretch filled in, px; 0 = off
    threshold: float = 0.5  # boundary probability of the skeletonised mask
    cover_px: float = 6.0  # a skeleton pixel this close to a graph edge is already covered
    snap_px: float = 12.0  # a filled edge's free end this close to a graph vertex is joined to it
    simplify_px: float = 1.0  # Douglas-Peucker tolerance of the filled polylines
    split_px: float = 200.0  # filled stretches are cut into edges about this long (see pieces())

    @property
    def active(self) -> bool:
        return self.min_length_px > 0

    def __post_init__(self) -> None:
        if not (
            self.min_length_px >= 0
            and 0 < self.threshold <= 1
            and self.cover_px >= 0
            and self.snap_px >= 0
            and self.simplify_px >= 0
            and self.split_px >= 0
        ):
            raise ValueError(
                f"need min_length_px, cover_px, snap_px, simplify_px, split_px >= 0 and 0 < threshold <= 1; got {self}"
            )


def uncovered_skeleton(boundary: np.ndarray, graph: BoundaryGraph, config: FillConfig) -> np.ndarray:
    """(h, w) bool: pixels of the skeleton of ``boundary >= threshold`` farther than ``cover_px``
    from every edge of ``graph`` (edges drawn along their polylines, ``2 * cover_px`` px
    thick: one drawing pass instead of a distance transform of the whole window)."""
    skeleton = skeletonize(np.asarray(boundary) >= config.threshold)
    if not skeleton.any() or graph.n_edges == 0:
        return skeleton
    covered = np.zeros(skeleton.shape, np.uint8)
    lines = [np.round((graph.edge_polyline(k) - 0.5) * 16).astype(np.int32) for k in range(graph.n_edges)]
    cv2.polylines(covered, lines, isClosed=False, color=1, thickness=max(1, int(round(2 * config.cover_px))), shift=4)
    return skeleton & (covered == 0)


def long_stretches(mask: np.ndarray, min_length_px: float) -> np.ndarray:
    """``mask`` without its 8-connected pieces of fewer than ``min_length_px`` pixels (a
    one-pixel-wide stretch has about one pixel per pixel of length)."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_length_px
    keep[0] = False
    out = np.zeros(mask.shape, bool)
    rows, cols = nonzero_pixels(labels)
    out[rows, cols] = keep[labels[rows, cols]]
    return out


def fill_from_skeleton(
    graph: BoundaryGraph, boundary: np.ndarray, config: FillConfig, region: tuple[int, int, int, int] | None = None
) -> BoundaryGraph:
    """``graph`` plus the uncovered skeleton stretches of ``boundary`` as ``skeleton`` edges (see
    the module docstring). ``region`` (row0, row1, col0, col1) limits the filled pixels to that
    block (a window's core and one pixel beyond). Returns ``graph`` itself when nothing is filled."""
    if not config.active:
        return graph
    mask = long_stretches(uncovered_skeleton(boundary, graph, config), config.min_length_px)
    if region is not None:
        r0, r1, c0, c1 = region
        inside = np.zeros_like(mask)
        inside[max(r0, 0) : r1, max(c0, 0) : c1] = True
        mask &= inside
    if not mask.any():
        return graph
    found = stretch_graph(mask, config.simplify_px)
    if found.n_edges == 0:
        return graph
    target = snap_targets(found, graph, config.snap_px)
    return merged_stretches(graph, found, target, boundary, config.split_px)


def stretch_graph(mask: np.ndarray, simplify_px: float) -> BoundaryGraph:
    """The graph of the stretches (:func:`skeleton_graph`, nothing pruned), worked out on the
    stretches' bounding box, not the whole window."""
    rows, cols = nonzero_pixels(mask)
    r0, c0 = rows.min(), cols.min()
    box = mask[r0 : rows.max() + 1, c0 : cols.max() + 1]
    found = skeleton_graph(
        np.pad(box, 1).astype(np.float32),
        SkeletonConfig(threshold=0.5, simplify_px=simplify_px, spur_px=0.0, min_length_px=0.0),
    )
    shift = np.array([c0 - 1, r0 - 1], float)
    return BoundaryGraph(
        found.vertices + shift,
        found.edges,
        edge_kinds=found.edge_kinds,
        edge_polylines=[line + shift for line in found.edge_polylines],
        edge_scores=found.edge_scores,
    )


def snap_targets(found: BoundaryGraph, graph: BoundaryGraph, snap_px: float) -> np.ndarray:
    """(n,) for each vertex of the filled graph: the graph vertex its free end joins, or -1."""
    target = np.full(found.n_vertices, -1)
    degree = np.bincount(found.edges.ravel(), minlength=found.n_vertices)
    free = np.flatnonzero(degree == 1)
    if graph.n_vertices == 0 or not len(free) or snap_px <= 0:
        return target
    distance, nearest = cKDTree(graph.vertices).query(found.vertices[free], distance_upper_bound=snap_px)
    hit = np.isfinite(distance)
    target[free[hit]] = nearest[hit]
    return target


def merged_stretches(
    graph: BoundaryGraph,
    found: BoundaryGraph,
    target: np.ndarray,
    boundary: np.ndarray,
    split_px: float,
    kind: str = SKELETON,
) -> BoundaryGraph:
    """One graph: ``graph``'s vertices and edges, then the filled ones of kind ``kind`` (free ends
    joined to their targets, the polyline extended to the target vertex), each cut into pieces
    (see :func:`pieces`) and scored by the mean of ``boundary`` along it."""
    n = graph.n_vertices
    new = np.flatnonzero(target < 0)
    index = np.where(target >= 0, target, 0)
    index[new] = n + np.arange(len(new))
    vertices = list(graph.vertices) + list(found.vertices[new])
    kinds = list(graph.vertex_kinds or ["isolated"] * n) + [kind] * len(new)
    edges, lines, scores = [], [], []
    for k, (a, b) in enumerate(found.edges):
        u, v = int(index[a]), int(index[b])
        line = np.concatenate([[vertices[u]], found.edge_polyline(k), [vertices[v]]])
        line = line[np.r_[True, np.any(line[1:] != line[:-1], axis=1)]]  # a new end vertex is the line's own end
        parts = pieces(line, split_px, closed=u == v)
        if not parts:
            continue  # both ends joined to one vertex with nothing between: no boundary
        ids = [u] + list(range(len(vertices), len(vertices) + len(parts) - 1)) + [v]
        for part in parts[:-1]:
            vertices.append(part[-1])
            kinds.append(kind)
        for i, j, part in zip(ids[:-1], ids[1:], parts):
            edges.append((i, j))
            lines.append(part)
            scores.append(_mean_along(boundary, part))
    if not edges:
        return graph
    n_old = graph.n_edges
    return BoundaryGraph(
        np.array(vertices, float).reshape(-1, 2),
        np.concatenate([graph.edges, np.array(edges, np.int64)]),
        vertex_kinds=kinds,
        edge_kinds=list(graph.edge_kinds or ["normal"] * n_old) + [kind] * len(edges),
        edge_polylines=list(graph.edge_polylines or [None] * n_old) + lines,
        edge_scores=np.concatenate([graph.edge_scores if graph.edge_scores is not None else np.ones(n_old), scores]),
        transform=graph.transform,
        crs=graph.crs,
    )


def pieces(line: np.ndarray, split_px: float, closed: bool = False) -> list[np.ndarray]:
    """A polyline cut into pieces about ``split_px`` long (equal arc lengths; the cut points
        interpolated on it), at least three for a closed line (its two ends one vertex), so no two
        of its edges join the same pair of vertices. Why cut at all: the city's stitching keeps one
        edge per pair of end vertices, and two windows can fill the two halves of a loop between the
        same two cut ends; edges with inner vertices of their own never collide. A line of length 0
    gives no piece."""
    along = arc_lengths(line)
    if along[-1] == 0:
        return []
    count = max(1, int(np.ceil(along[-1] / split_px)) if split_px > 0 else 1)
    if closed:
        count = max(count, 3)
    if count == 1:
        return [line]
    marks = along[-1] * np.arange(1, count) / count
    cut = np.stack([np.interp(marks, along, line[:, 0]), np.interp(marks, along, line[:, 1])], axis=1)
    ends = [line[0], *cut, line[-1]]
    bounds = [-np.inf, *marks, np.inf]
    out = []
    for k in range(count):  # the points strictly between two cuts (the line's own ends fall in the outer bounds)
        part = np.concatenate([[ends[k]], line[(along > bounds[k]) & (along < bounds[k + 1])], [ends[k + 1]]])
        out.append(part[np.r_[True, np.any(part[1:] != part[:-1], axis=1)]])
    return out


def _mean_along(boundary: np.ndarray, line: np.ndarray) -> float:
    """Mean boundary probability at the polyline's points (its score)."""
    h, w = boundary.shape
    cols = np.clip(np.floor(line[:, 0]).astype(int), 0, w - 1)
    rows = np.clip(np.floor(line[:, 1]).astype(int), 0, h - 1)
    return float(np.mean(boundary[rows, cols]))
