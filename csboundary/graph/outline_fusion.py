"""The roadway frames the graph: where the road-surface map is sure, its outline, placed on the
boundary map, replaces the AfANet edges along it (an inference option).

On dense-urban photographs the surface map is often cleaner than the boundary map: the boundary
map fires on roofs, parapets and rows of parked cars, while the roadway's outline runs along the
curb and stays connected through intersections. Where the surface head is unsure (lawns and
roofs it half calls roadway, on suburban imagery) the outline is wrong, so it is only used where
the surface map is sure and the boundary map agrees:

1. the surface map is smoothed (a Gaussian of ``sigma_px``) and thresholded at ``level``; roadway
   pieces and holes under ``min_piece_px`` pixels that do not reach the window's border are
   dropped and filled (a lot mistaken for roadway, a car on it);
2. the roadway's 1 px inner outline is kept where the smoothed surface is sure on both sides
   (at least ``sure`` within ``side_px`` on one side, at most ``1 - sure`` on the other) and
   the boundary map reaches ``support`` within ``support_px`` of it, and the surface map is clear
   around it (at most ``max_unsure`` of the pixels within ``clear_px`` between 0.25 and 0.75,
   :func:`clear_surface`); unsure stretches shorter
   than ``bridge_px`` between kept ones are kept too, and kept stretches shorter than
   ``min_length_px`` are dropped;
3. the parts of the graph's edges within ``cover_px`` of a kept stretch are cut away (pieces
   left shorter than ``keep_px`` go too), and the stretches become edges of kind ``outline``: their
   points moved along the normal onto the boundary map's ridge (at most ``place_px``, the moves
   median-smoothed so the line does not zigzag, the ends fixed), simplified by ``simplify_px``,
   free ends joined to graph vertices within ``snap_px``, and the ends the cuts left joined to
   the nearest outline within ``cover_px + 4``.

In a city the outline is traced on the whole window and its lines are cut where they cross the
sides of the window's core: the neighbouring window, which sees the same stitched maps, traces
the same pixels there and cuts them at the same point, where the two halves meet. Coordinates are
continuous (x, y) pixels, pixel [r, c] centred at (c + 0.5, r + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from shapely.geometry import LineString
from shapely.geometry import box as shapely_box
from skimage.morphology import skeletonize

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.disc_filter import disc_max, disc_min
from csboundary.graph.end_attachment import attach_ends
from csboundary.graph.polyline import dense_samples, polyline_length
from csboundary.graph.skeleton_fill import long_stretches, merged_stretches, snap_targets, stretch_graph
from csboundary.graph.surface_gate import roadway_pieces_kept

OUTLINE = "outline"  # the kind of an edge traced from the roadway's outline


@dataclass(frozen=True)
class OutlineConfig:
    sure: float = 0.0  # surface probability the roadway side must reach (and 1 - sure the other); 0 = off
    sigma_px: float = 4.0  # Gaussian smoothing of the surface map before it is thresholded
    level: float = 0.5  # smoothed surface probability that counts as roadway
    min_piece_px: int = 1500  # roadway pieces and holes smaller than this, away from the window's border, are dropped
    side_px: float = 8.0  # how far to each side of the outline the surface is read
    support: float = 0.3  # boundary probability that must be reached within support_px of a kept outline pixel
    support_px: float = 4.0
    clear_px: float = 100.0  # the surface map's sureness is judged over a square this far to each side ...
    max_unsure: float = 0.15  # ... which may hold at most this share of unsure pixels (0.25-0.75); 1 = not judged
    bridge_px: float = 60.0  # unsure stretches of the outline shorter than this between kept ones are kept too
    min_length_px: float = 40.0  # kept outline stretches shorter than this are dropped
    cover_px: float = 8.0  # the parts of graph edges this close to a kept stretch are replaced by it ...
    keep_px: float = 20.0  # ... and what is left of an edge shorter than this goes too
    place_px: float = 4.0  # how far an outline point may move along its normal onto the boundary map's ridge
    place_level: float = 0.3  # the ridge must reach this boundary probability for a point to move
    simplify_px: float = 3.0  # Douglas-Peucker tolerance of the outline edges
    snap_px: float = 12.0  # a free end this close to a graph vertex is joined to it
    split_px: float = 200.0  # outline stretches are cut into edges about this long

    @property
    def active(self) -> bool:
        return self.sure > 0

    def __post_init__(self) -> None:
        if not (
            0 <= self.sure <= 1
            and 0 < self.level < 1
            and self.sigma_px >= 0
            and self.min_piece_px >= 0
            and self.side_px >= 1
            and 0 <= self.support <= 1
            and self.support_px >= 0
            and self.clear_px >= 0
            and 0 <= self.max_unsure <= 1
            and self.bridge_px >= 0
            and self.min_length_px >= 0
            and self.cover_px >= 0
            and self.keep_px >= 0
            and self.place_px >= 0
            and self.simplify_px >= 0
            and self.snap_px >= 0
        ):
            raise ValueError(f"outline settings out of range: {self}")


def smoothed_roadway(surface: np.ndarray, config: OutlineConfig) -> tuple[np.ndarray, np.ndarray]:
    """The smoothed surface map (float32) and the roadway mask (bool) of step 1."""
    smooth = np.asarray(surface, np.float32)
    if config.sigma_px > 0:
        smooth = cv2.GaussianBlur(smooth, (0, 0), config.sigma_px, borderType=cv2.BORDER_REPLICATE)
    road = roadway_pieces_kept(smooth, config.level, config.min_piece_px)
    holes = ~roadway_pieces_kept((~road).astype(np.float32), 0.5, config.min_piece_px)
    return smooth, road | holes


def kept_outline(surface: np.ndarray, boundary: np.ndarray, config: OutlineConfig) -> np.ndarray:
    """(H, W) bool: the outline pixels of step 2, before the length filter."""
    smooth, road = smoothed_roadway(surface, config)
    road8 = road.astype(np.uint8)
    outline = road & (cv2.erode(road8, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE) == 0)
    side = max(int(round(config.side_px)), 1)
    sure = (disc_max(smooth, side) >= config.sure) & (disc_min(smooth, side) <= 1.0 - config.sure)
    supported = (
        disc_max(np.asarray(boundary, np.float32), max(int(round(config.support_px)), 0)) >= config.support
        if config.support_px >= 1
        else np.asarray(boundary) >= config.support
    )
    return bridged(outline, outline & sure & supported & clear_surface(smooth, config), config.bridge_px)


def clear_surface(smooth: np.ndarray, config: OutlineConfig) -> np.ndarray:
    """(H, W) bool: where at most ``max_unsure`` of the square of side ``2 * clear_px + 1``
    around a pixel has a smoothed surface probability between 0.25 and 0.75. Why: a surface map
    that is grey over lawns, drives and roofs (suburban imagery unlike the training worlds) is
    sure nowhere in particular, and its outline there wanders into every drive; on streets it
    separates (about 10 % unsure on a dense-urban patch, 60 % on a suburban crop)."""
    if config.max_unsure >= 1:
        return np.ones(smooth.shape, bool)
    unsure = (np.abs(smooth - np.float32(0.5)) < np.float32(0.25)).astype(np.float32)
    side = 2 * max(int(round(config.clear_px)), 0) + 1
    return cv2.blur(unsure, (side, side), borderType=cv2.BORDER_REPLICATE) <= config.max_unsure


def bridged(outline: np.ndarray, kept: np.ndarray, bridge_px: float) -> np.ndarray:
    """``kept`` plus the stretches of ``outline`` between kept pixels that are shorter than
    ``bridge_px`` (a parked car or a tree that makes the surface unsure for a few metres should
    not break a curb into pieces that connect to nothing)."""
    if bridge_px <= 0 or not kept.any():
        return kept
    n, labels, stats, _ = cv2.connectedComponentsWithStats((outline & ~kept).astype(np.uint8), connectivity=8)
    if n <= 1:
        return kept
    near_kept = cv2.dilate(kept.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    touching = np.zeros(n, np.int64)
    np.add.at(touching, labels[near_kept & (labels > 0)], 1)
    short = (stats[:, cv2.CC_STAT_AREA] < bridge_px) & (touching >= 2)
    short[0] = False
    return kept | short[labels]


def cut_along(graph: BoundaryGraph, mask: np.ndarray, config: OutlineConfig) -> BoundaryGraph:
    """``graph`` without the parts of its edges within ``cover_px`` of a pixel of ``mask`` (points
    every 2 px): an edge that runs along the outline for a stretch is cut there, its pieces of at
    least ``keep_px`` kept (new ends are vertices of kind ``cut``), so the graph stays connected up
    to where the outline takes over."""
    if graph.n_edges == 0 or not mask.any():
        return graph
    distance = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
    h, w = mask.shape
    n = graph.n_vertices
    vertices, vertex_kinds = list(graph.vertices), list(graph.vertex_kinds or ["isolated"] * n)
    kinds = graph.edge_kinds or ["normal"] * graph.n_edges
    scores = graph.edge_scores if graph.edge_scores is not None else np.ones(graph.n_edges)
    edges, edge_kinds, lines, edge_scores, changed = [], [], [], [], False
    for k, (u, v) in enumerate(graph.edges):
        line = graph.edge_polyline(k)
        points, _ = dense_samples(line, 2.0)
        cols = np.clip(np.floor(points[:, 0]).astype(int), 0, w - 1)
        rows = np.clip(np.floor(points[:, 1]).astype(int), 0, h - 1)
        free = distance[rows, cols] > config.cover_px
        if free.all():
            edges.append((u, v)), edge_kinds.append(kinds[k]), lines.append(line), edge_scores.append(scores[k])
            continue
        changed = True
        bounds = np.flatnonzero(np.diff(np.r_[0, free.astype(np.int8), 0]))
        for i0, i1 in zip(bounds[::2], bounds[1::2] - 1):
            piece = points[i0 : i1 + 1]
            if len(piece) < 2 or polyline_length(piece) < config.keep_px:
                continue
            ends = []
            for at, end in ((i0, u), (i1, v)):
                if at in (0, len(points) - 1):
                    ends.append(int(end))
                else:
                    ends.append(len(vertices))
                    vertices.append(points[at])
                    vertex_kinds.append("cut")
            simple = np.asarray(LineString(piece).simplify(0.5).coords) if len(piece) > 2 else piece
            edges.append(tuple(ends)), edge_kinds.append(kinds[k]), lines.append(simple), edge_scores.append(scores[k])
    if not changed:
        return graph
    return BoundaryGraph(
        np.array(vertices, float).reshape(-1, 2),
        np.array(edges, np.int64).reshape(-1, 2),
        vertex_kinds=vertex_kinds,
        edge_kinds=edge_kinds,
        edge_polylines=lines,
        edge_scores=np.array(edge_scores, float),
        transform=graph.transform,
        crs=graph.crs,
    )


def placed_on_ridge(line: np.ndarray, boundary: np.ndarray, config: OutlineConfig) -> np.ndarray:
    """``line`` resampled every 2 px, each inner point moved along the line's normal to the
    boundary map's largest value within ``place_px`` (when it reaches ``place_level``), the moves
    median-smoothed over 31 points (60 px: a line moved whole, not a zigzag); the ends stay
    where they are; then simplified."""
    line = np.asarray(line, float)
    points, _ = dense_samples(line, 2.0)
    if config.place_px >= 1 and len(points) >= 5:
        tangent = np.gradient(points, axis=0)
        tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
        normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
        offsets = np.arange(-int(config.place_px), int(config.place_px) + 1, dtype=float)
        probe = points[:, None, :] + offsets[None, :, None] * normal[:, None, :]
        h, w = boundary.shape
        cols = np.clip(np.floor(probe[..., 0]).astype(int), 0, w - 1)
        rows = np.clip(np.floor(probe[..., 1]).astype(int), 0, h - 1)
        values = np.asarray(boundary)[rows, cols]
        best = values.argmax(axis=1)
        shift = np.where(values.max(axis=1) >= config.place_level, offsets[best], 0.0)
        padded = np.pad(shift, 15, mode="edge")
        shift = np.median(np.lib.stride_tricks.sliding_window_view(padded, 31), axis=1)
        shift[0] = shift[-1] = 0.0
        points = points + shift[:, None] * normal
    if len(points) > 2 and config.simplify_px > 0:
        points = np.asarray(LineString(points).simplify(config.simplify_px).coords)
    return points


def clipped_to_box(found: BoundaryGraph, box: tuple[float, float, float, float]) -> tuple[BoundaryGraph, np.ndarray]:
    """``found``'s polylines cut to ``box`` (x0, y0, x1, y1, continuous pixels): the pieces inside,
    their ends the lines' own ends or the points where they cross the box's sides (exact, so two
    windows that trace the same pixels across a seam cut them at the same point), and (V,) bool
    for the vertices made by a cut."""
    x0, y0, x1, y1 = box
    frame = shapely_box(x0, y0, x1, y1)
    index: dict[tuple[float, float], int] = {}
    points, cut, edges, lines = [], [], [], []

    def vertex(p: np.ndarray, made_by_cut: bool) -> int:
        key = (round(float(p[0]), 6), round(float(p[1]), 6))
        if key not in index:
            index[key] = len(points)
            points.append(np.asarray(p, float))
            cut.append(made_by_cut)
        return index[key]

    for k in range(found.n_edges):
        line = found.edge_polyline(k)
        inside = LineString(line).intersection(frame)
        parts = [
            g
            for g in getattr(inside, "geoms", [inside])
            if g.geom_type == "LineString" and not g.is_empty and g.length > 0
        ]
        for part in parts:
            piece = np.asarray(part.coords, float)
            ends = []
            for p in (piece[0], piece[-1]):
                own = np.any(np.all(np.isclose(line[[0, -1]], p, atol=1e-9), axis=1))
                ends.append(vertex(p, not own))
            edges.append(ends)
            lines.append(piece)
    graph = BoundaryGraph(
        np.array(points, float).reshape(-1, 2),
        np.array(edges, np.int64).reshape(-1, 2),
        edge_kinds=[OUTLINE] * len(edges),
        edge_polylines=lines,
        edge_scores=np.ones(len(edges)),
    )
    return graph, np.array(cut, bool)


def fused_with_outline(
    graph: BoundaryGraph,
    maps_surface: np.ndarray,
    boundary: np.ndarray,
    config: OutlineConfig,
    region: tuple[int, int, int, int] | None = None,
) -> BoundaryGraph:
    """``graph`` with the roadway's sure outline in place of the edges along it (see the module
    docstring). ``region`` (row0, row1, col0, col1: a window's core and one pixel beyond) limits
    the added lines to the core, cut exactly where they cross its sides; edges are cut wherever
    the window's outline covers them. Returns ``graph`` itself when nothing is kept."""
    if not config.active:
        return graph
    kept = long_stretches(skeletonize(kept_outline(maps_surface, boundary, config)), config.min_length_px)
    if not kept.any():
        return graph
    base = cut_along(graph, kept, config)
    found = stretch_graph(
        kept, 0.0
    )  # traced on the whole window, so two windows trace the same pixels across their seam
    made_by_cut = np.zeros(found.n_vertices, bool)
    if region is not None:
        r0, r1, c0, c1 = region
        found, made_by_cut = clipped_to_box(found, (c0, r0, c1 - 1, r1 - 1))
    if found.n_edges == 0:
        return base
    found.edge_polylines = [placed_on_ridge(found.edge_polyline(k), boundary, config) for k in range(found.n_edges)]
    target = snap_targets(found, base, config.snap_px)
    target[made_by_cut] = -1  # the neighbouring window ends its piece at the same point
    fused = merged_stretches(base, found, target, boundary, config.split_px, kind=OUTLINE)
    return with_cut_ends_attached(fused, config)


def with_cut_ends_attached(graph: BoundaryGraph, config: OutlineConfig) -> BoundaryGraph:
    """``graph`` with every dangling end that :func:`cut_along` made joined to the nearest line of
    another piece within ``cover_px + 4`` (the outline that took over from it). Why: left
    dangling, the city graph's end attachment joins it to whatever lies ahead, often a chord
    across the road."""
    kinds = graph.vertex_kinds or []
    degree = np.bincount(graph.edges.ravel(), minlength=graph.n_vertices)
    ends = np.array([v for v, kind in enumerate(kinds) if kind == "cut" and degree[v] == 1], np.int64)
    return attach_ends(graph, ends, config.cover_px + 4.0, OUTLINE) if len(ends) else graph
