"""Patch graphs -> one city graph, through the vertices neighbouring patches share (paper IV-E).

Each patch's graph is predicted on its 1100 px window of the stitched (averaged) maps, so where
two windows overlap they see the same keypoint map and extract the same vertices there: "the
graph of the two adjacent image patches could be stitched together easily by connecting
exclusive vertices of two patches with the shared vertices". The paper leaves the details open;
the rules here:

* **Edge ownership.** Both patches predict the edges inside their overlap, not always alike.
  Each edge is kept from exactly one patch: the one whose core holds the edge's midpoint (half
  its arc length along its polyline). Cores tile the mosaic, so there are no duplicates, and
  every edge is judged by the patch that sees at least ``margin`` px of context around it.
  Patches on the mosaic border own everything beyond it on that side too.
* **Shared vertices.** Vertices closer than ``merge_px`` become one (the first seen keeps its
  position). Shared vertices are bit-identical, so merging only has to absorb float noise; the
  radius also guarantees that no two output vertices are closer than ``merge_px``.
* **Cut pieces.** A keypoint blob cut by a window's border gives that patch a vertex that its
  neighbour, which sees the whole blob, puts elsewhere. A vertex within ``border_px`` of its
  window's inner border (one with a neighbour behind it) is therefore moved onto the nearest
  vertex within ``snap_px`` that a neighbour extracted away from its own border.
* **Repair** (``repair``, on by default). Where the owner saw no edge between two ends that it
  left dangling but a neighbour, which has both in view, did, the neighbour's edge is added (at
  most once per end, most confident first): otherwise the boundary stays broken at the seam. On
  the demo city this lifts city-scale APLS from 0.79 to 0.82 at unchanged precision. "In view"
  means both ends at least ``border_px`` from the neighbour's window border: an edge between two
  points where boundaries leave the window runs along its border, across the road.
* **Seam mending** (``mend_px``, 15 by default; 0 = off). A boundary that crosses a window's
  border is cut there in that patch's graph: its edge ends on a vertex the neighbour, which sees
  the boundary run on, never extracted (it has no keypoint there), so snapping finds nothing and
  the end dangles on top of the neighbour's edge. An end left dangling within ``border_px`` of
  the inner border of the window its edge came from, and within ``mend_px`` of an edge of another
  connected piece, is joined to that edge: the edge is split at the nearest point and a short
  ``seam`` edge joins the end to it. On the seed-7 test city 52 of 197 interior dangling ends
  lay on a window border (Lite2 FPN); a border ring holds about 3 % of the area. The end of a
  blob cut by the border sits up to ~15 px off the curb the neighbour sees whole, so the radius
  is 15 px: 5 px left the suburb test city's APLS at 0.432, 15 px gives 0.513
  (docs/city-inference.md). The join itself is :func:`csboundary.graph.end_attachment.attach_ends`,
  which the city graph also uses for every other dangling end (``city_graph`` in
  :mod:`csboundary.pipeline.prediction.city`, after noding: :mod:`csboundary.graph.noding`).

Coordinates are mosaic pixels (col, row), the frame of ``grid.transform``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.spatial import cKDTree

from csboundary.data.grid import Patch, PatchGrid
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import edge_line
from csboundary.graph.end_attachment import attach_ends, better_edge, dangling_ends
from csboundary.graph.polyline import (
    arc_lengths,
)

Index = tuple[int, int]
SEAM = "seam"  # the kind of an edge that joins an end cut by a window border to the edge it lies on


@dataclass(frozen=True)
class StitchConfig:
    """Distances in pixels; see the module docstring."""

    merge_px: float = 1.0
    border_px: float = 8.0  # the ring of a window where pieces may be cut by its border
    snap_px: float = 5.0
    repair: bool = True
    mend_px: float = 15.0  # farthest edge a dangling end cut by its window's border is joined to (0 = off)
    node_shared: bool = True  # city graph: lines that touch, cross or run together meet at a vertex (graph/noding.py)

    def __post_init__(self) -> None:
        if not (self.merge_px > 0 and self.border_px >= 0 and self.snap_px >= 0 and self.mend_px >= 0):
            raise ValueError(f"need merge_px > 0, border_px >= 0, snap_px >= 0, mend_px >= 0; got {self}")


def to_mosaic(graph: BoundaryGraph, patch: Patch) -> BoundaryGraph:
    """A patch graph (pixels of ``patch.expanded``) moved to mosaic pixels."""
    offset = np.array([patch.expanded.col_off, patch.expanded.row_off], float)
    lines = (
        None
        if graph.edge_polylines is None
        else [None if p is None else np.asarray(p, float) + offset for p in graph.edge_polylines]
    )
    return BoundaryGraph(
        graph.vertices + offset,
        graph.edges,
        vertex_kinds=graph.vertex_kinds,
        edge_kinds=graph.edge_kinds,
        edge_polylines=lines,
        edge_scores=graph.edge_scores,
        crs=graph.crs,
    )


def owner_bounds(patch: Patch, grid: PatchGrid) -> tuple[float, float, float, float]:
    """(x0, y0, x1, y1) of the region whose edges ``patch`` keeps: its core, unbounded on the
    sides where the mosaic ends."""
    core = patch.core
    x0 = -np.inf if patch.col == 0 else core.col_off
    y0 = -np.inf if patch.row == 0 else core.row_off
    x1 = np.inf if patch.col == grid.n_cols - 1 else core.col_end
    y1 = np.inf if patch.row == grid.n_rows - 1 else core.row_end
    return x0, y0, x1, y1


def polyline_midpoint(points: np.ndarray) -> np.ndarray:
    """The point at half the arc length of a polyline."""
    points = np.asarray(points, float)
    if len(points) == 2:  # the general steps below, for the commonest line, give exactly this
        return points[0] + 0.5 * (points[1] - points[0]) if (points[0] != points[1]).any() else points[0]
    cum = arc_lengths(points)
    if len(points) < 2 or cum[-1] == 0:
        return points[0]
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)  # exact segment lengths (a difference of sums is not)
    half = cum[-1] / 2
    k = min(int(np.searchsorted(cum, half, side="right")) - 1, len(steps) - 1)
    t = (half - cum[k]) / steps[k] if steps[k] > 0 else 0.0
    return points[k] + t * (points[k + 1] - points[k])


def edge_midpoints(graph: BoundaryGraph) -> np.ndarray:
    """(E, 2) each edge's :func:`polyline_midpoint` along its line from u to v (the same
    numbers; straight edges, most of a graph, in one vectorised step)."""
    u, v = graph.edges[:, 0], graph.edges[:, 1]
    p0, p1 = graph.vertices[u], graph.vertices[v]
    out = np.where((p0 != p1).any(axis=1)[:, None], p0 + 0.5 * (p1 - p0), p0).reshape(-1, 2)
    if graph.edge_polylines is not None:
        for k, line in enumerate(graph.edge_polylines):
            if line is not None and len(line) > 2:
                out[k] = polyline_midpoint(edge_line(graph, k))
    return out


def owner_cores(graph: BoundaryGraph, grid: PatchGrid, mids: np.ndarray | None = None) -> np.ndarray:
    """(E, 2) the (row, col) of the patch core holding each edge's midpoint (half its arc length
    from u to v; ``mids`` when given), clamped to the grid: which core an edge of the city graph
    belongs to."""
    mids = edge_midpoints(graph) if mids is None else mids
    core = grid.config.core
    rows = np.clip(np.floor(mids[:, 1] / core), 0, grid.n_rows - 1).astype(np.int64)
    cols = np.clip(np.floor(mids[:, 0] / core), 0, grid.n_cols - 1).astype(np.int64)
    return np.stack([rows, cols], axis=1)


def border_distance(points: np.ndarray, patch: Patch, grid: PatchGrid) -> np.ndarray:
    """Distance of each point to the nearest side of ``patch``'s window that has a neighbour
    behind it (inf when every side is the mosaic's edge)."""
    win = patch.expanded
    x, y = points[:, 0], points[:, 1]
    sides = [
        (patch.col > 0, x - win.col_off),
        (patch.col < grid.n_cols - 1, win.col_end - x),
        (patch.row > 0, y - win.row_off),
        (patch.row < grid.n_rows - 1, win.row_end - y),
    ]
    out = np.full(len(points), np.inf)
    for has_neighbour, distance in sides:
        if has_neighbour:
            out = np.minimum(out, distance)
    return out


class _VertexRegistry:
    """Output vertices, each new point merged into an existing one closer than ``radius``."""

    def __init__(self, radius: float):
        self.radius = radius
        self.points: list[np.ndarray] = []
        self.kinds: list[str] = []
        self._cells: dict[tuple[int, int], list[int]] = {}

    def find(self, point: np.ndarray) -> int:
        """The output vertex closer than ``radius`` to ``point`` (the nearest), or -1."""
        cx, cy = int(np.floor(point[0] / self.radius)), int(np.floor(point[1] / self.radius))
        best, best_d = -1, self.radius
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for i in self._cells.get((cx + dx, cy + dy), ()):
                    d = float(np.hypot(*(self.points[i] - point)))
                    if d < best_d:
                        best, best_d = i, d
        return best

    def add(self, point: np.ndarray, kind: str) -> int:
        found = self.find(point)
        if found >= 0:
            return found
        self.points.append(np.asarray(point, float))
        self.kinds.append(kind)
        cell = (int(np.floor(point[0] / self.radius)), int(np.floor(point[1] / self.radius)))
        self._cells.setdefault(cell, []).append(len(self.points) - 1)
        return len(self.points) - 1


@dataclass
class _Candidate:
    """One patch's edge, with its ends already moved by snapping."""

    line: np.ndarray  # polyline from end a to end b, mosaic pixels
    a_kind: str
    b_kind: str
    kind: str
    score: float
    shaped: bool  # the polyline is the edge's shape (a corner arc), not just its two ends
    patch: Index
    owned: bool  # its midpoint lies in its patch's core
    in_view: bool = True  # both ends at least ``border_px`` from its window's inner border (not cut points)


def stitch_patch_graphs(
    graphs: Mapping[Index, BoundaryGraph],
    grid: PatchGrid,
    config: StitchConfig = StitchConfig(),
    crs: str | None = None,
) -> BoundaryGraph:
    """One city graph from per-patch graphs given in mosaic pixels (see :func:`to_mosaic`)."""
    candidates = _candidates(graphs, grid, config)
    registry = _VertexRegistry(config.merge_px)
    kept: dict[tuple[int, int], dict] = {}

    def keep(c: _Candidate) -> None:
        a, b = registry.add(c.line[0], c.a_kind), registry.add(c.line[-1], c.b_kind)
        if a == b:
            return
        polyline = None
        if c.shaped:
            polyline = c.line.copy()
            polyline[0], polyline[-1] = registry.points[a], registry.points[b]
        _put(kept, {"u": a, "v": b, "kind": c.kind, "score": c.score, "polyline": polyline, "patch": c.patch})

    for c in candidates:
        if c.owned:
            keep(c)
    if config.repair:
        for c in _repairs(candidates, registry, kept):
            keep(c)
    edges = list(kept.values())
    graph = BoundaryGraph(
        np.array(registry.points).reshape(-1, 2),
        np.array([[e["u"], e["v"]] for e in edges], dtype=np.int64).reshape(-1, 2),
        vertex_kinds=list(registry.kinds),
        edge_kinds=[e["kind"] for e in edges],
        edge_polylines=[e["polyline"] for e in edges],
        edge_scores=np.array([e["score"] for e in edges], dtype=float),
        edge_patches=np.array([e["patch"] for e in edges], dtype=np.int64).reshape(-1, 2),
        transform=grid.transform,
        crs=crs,
    )
    if config.mend_px > 0:
        graph = attach_ends(
            graph, seam_ends(graph, grid, config.border_px), config.mend_px, SEAM, merge_px=config.merge_px
        )
    return graph


def seam_ends(graph: BoundaryGraph, grid: PatchGrid, border_px: float) -> np.ndarray:
    """The dangling ends of a stitched graph within ``border_px`` of the inner border of the
    window their edge came from: where a window's border cut a boundary."""
    ends, edges, _ = dangling_ends(graph)
    if graph.edge_patches is None:
        return ends[:0]
    near = [
        border_distance(graph.vertices[x : x + 1], grid.patch(*graph.edge_patches[e]), grid)[0] < border_px
        for x, e in zip(ends, edges)
    ]
    return ends[np.array(near, bool)]


def _candidates(graphs: Mapping[Index, BoundaryGraph], grid: PatchGrid, config: StitchConfig) -> list[_Candidate]:
    """Every patch's edges in (row, col) order, snapped, with their ownership and cut flags."""
    safe = _safe_vertices(graphs, grid, config)
    out = []
    for index in sorted(graphs):
        graph, patch = graphs[index], grid.patch(*index)
        if graph.n_edges == 0:
            continue
        x0, y0, x1, y1 = owner_bounds(patch, grid)
        positions = _snapped(graph, patch, grid, safe, config)
        away = border_distance(graph.vertices, patch, grid) >= config.border_px
        kinds = graph.vertex_kinds or ["vertex"] * graph.n_vertices
        for k, (u, v) in enumerate(graph.edges):
            shaped = graph.edge_polylines is not None and graph.edge_polylines[k] is not None
            line = np.array(graph.edge_polyline(k), float)
            mx, my = polyline_midpoint(line)
            line[0], line[-1] = positions[u], positions[v]
            out.append(
                _Candidate(
                    line,
                    kinds[u],
                    kinds[v],
                    graph.edge_kinds[k] if graph.edge_kinds is not None else "normal",
                    float(graph.edge_scores[k]) if graph.edge_scores is not None else np.nan,
                    shaped,
                    index,
                    bool(x0 <= mx < x1 and y0 <= my < y1),
                    bool(away[u] and away[v]),
                )
            )
    return out


def _repairs(candidates: list[_Candidate], registry: _VertexRegistry, kept: dict) -> list[_Candidate]:
    """Edges from non-owners that join two ends the owners left dangling, most confident first.

    Where the owner saw no edge but the neighbour, with the same two vertices in view, did, the
    boundary would otherwise stay broken at the seam; an end can be mended once. An edge with an
    end on the neighbour's own window border is not taken: those ends are where two boundaries
    leave that window, and the edge between them runs along the border, across the road.
    """
    degree = np.zeros(len(registry.points), int)
    for e in kept.values():
        degree[e["u"]] += 1
        degree[e["v"]] += 1
    spare = sorted((c for c in candidates if not c.owned and c.in_view), key=lambda c: -np.nan_to_num(c.score, nan=0))
    out = []
    for c in spare:
        a, b = registry.find(c.line[0]), registry.find(c.line[-1])
        if a >= 0 and b >= 0 and a != b and degree[a] == 1 and degree[b] == 1 and (min(a, b), max(a, b)) not in kept:
            out.append(c)
            degree[a] += 1
            degree[b] += 1
    return out


def _put(kept: dict, edge: dict) -> None:
    """Keep ``edge`` unless a better one already joins the same two vertices."""
    key = (min(edge["u"], edge["v"]), max(edge["u"], edge["v"]))
    if key not in kept or _better(edge, kept[key]):
        kept[key] = edge


def _better(new: dict, old: dict) -> bool:
    return better_edge(new["kind"], new["score"], old["kind"], old["score"])


def _safe_vertices(
    graphs: Mapping[Index, BoundaryGraph], grid: PatchGrid, config: StitchConfig
) -> dict[Index, np.ndarray]:
    """Per patch, its vertices that lie at least ``border_px`` from its window's inner border."""
    out = {}
    for index, graph in graphs.items():
        far = border_distance(graph.vertices, grid.patch(*index), grid) >= config.border_px
        out[index] = graph.vertices[far]
    return out


def _snapped(
    graph: BoundaryGraph, patch: Patch, grid: PatchGrid, safe: Mapping[Index, np.ndarray], config: StitchConfig
) -> np.ndarray:
    """Vertex positions with the ones near the window border moved onto a neighbour's vertex."""
    positions = graph.vertices.copy()
    fragile = np.flatnonzero(border_distance(positions, patch, grid) < config.border_px)
    candidates = [safe[q.index] for q in grid.neighbours(patch) if q.index in safe and len(safe[q.index])]
    if not len(fragile) or config.snap_px == 0 or not candidates:
        return positions
    pool = np.concatenate(candidates)
    distance, nearest = cKDTree(pool).query(positions[fragile], distance_upper_bound=config.snap_px)
    hit = np.isfinite(distance)
    positions[fragile[hit]] = pool[nearest[hit]]
    return positions
