"""A boundary graph from a binary mask: threshold -> skeleton -> graph, the segmentation family's
post-processing (e.g. OrientationRefine, Batra et al. 2019).

The skeleton's pixels are joined to their 8-neighbours, leaving out a diagonal step when an
orthogonal path around it exists (graph/skeleton_pixels.py). The maximal chains of that pixel graph (between ends and
junctions, or closed loops) become edges whose polylines run through the pixel centres,
simplified by Douglas-Peucker; end spurs shorter than ``spur_px`` and pieces shorter than
``min_length_px`` are dropped. Coordinates: continuous (col, row) in the mask's pixel frame,
pixel [r, c] centred at (c + 0.5, r + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString
from skimage.morphology import skeletonize

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import chains
from csboundary.graph.polyline import polyline_length
from csboundary.graph.skeleton_pixels import skeleton_pixel_links


@dataclass(frozen=True)
class SkeletonConfig:
    threshold: float = 0.5  # probability at or above which a pixel is boundary
    simplify_px: float = 1.0  # Douglas-Peucker tolerance of the edge polylines
    spur_px: float = 10.0  # end branches shorter than this (skeleton noise) are removed
    min_length_px: float = 20.0  # connected pieces shorter than this are dropped


def skeleton_graph(probability: np.ndarray, config: SkeletonConfig = SkeletonConfig()) -> BoundaryGraph:
    """The graph of a (h, w) boundary probability map; edges carry their polylines."""
    mask = np.asarray(probability) >= config.threshold
    if not mask.any():
        return BoundaryGraph(edge_kinds=[], edge_polylines=[])
    pixels, links, _ = skeleton_pixel_links(skeletonize(mask), corner_diagonals=False)
    points = pixels[:, ::-1].astype(float) + 0.5
    found = chains(len(points), links)
    lines = [points[seq] for seq in found.vertices]
    ends = [(seq[0], seq[-1]) for seq in found.vertices]
    lines, ends = _prune(lines, ends, config)
    vertices: dict[int, int] = {}
    edges, polylines = [], []
    for line, (a, b) in zip(lines, ends):
        for v in (a, b):
            vertices.setdefault(v, len(vertices))
        simple = np.asarray(LineString(line).simplify(config.simplify_px).coords) if len(line) > 2 else line
        edges.append((vertices[a], vertices[b]))
        polylines.append(simple)
    xy = np.zeros((len(vertices), 2))
    for pixel, k in vertices.items():
        xy[k] = points[pixel]
    return BoundaryGraph(
        xy,
        np.array(edges, dtype=np.int64).reshape(-1, 2),
        edge_kinds=["normal"] * len(edges),
        edge_polylines=polylines,
        edge_scores=np.ones(len(edges)),
    )


def _prune(lines: list[np.ndarray], ends: list[tuple[int, int]], config: SkeletonConfig):
    """Drop short end spurs (a chain with one free end and one junction) and short pieces."""
    degree: dict[int, int] = {}
    for a, b in ends:
        degree[a] = degree.get(a, 0) + 1
        degree[b] = degree.get(b, 0) + 1
    keep = []
    for line, (a, b) in zip(lines, ends):
        spur = (degree[a] == 1) != (degree[b] == 1) and max(degree[a], degree[b]) >= 3
        keep.append(not (spur and polyline_length(line) < config.spur_px))
    lines = [line for line, k in zip(lines, keep) if k]
    ends = [e for e, k in zip(ends, keep) if k]
    # connected pieces by union-find over chain ends
    parent: dict[int, int] = {}

    def root(v: int) -> int:
        while parent.setdefault(v, v) != v:
            v = parent[v]
        return v

    for a, b in ends:
        parent[root(a)] = root(b)
    total: dict[int, float] = {}
    for line, (a, _) in zip(lines, ends):
        total[root(a)] = total.get(root(a), 0.0) + polyline_length(line)
    long_enough = [total[root(a)] >= config.min_length_px for a, _ in ends]
    return [line for line, k in zip(lines, long_enough) if k], [e for e, k in zip(ends, long_enough) if k]
