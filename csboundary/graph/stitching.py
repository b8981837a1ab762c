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
  (docs/city-inference.md).

Coordinates are mosaic pixels (col, row), the frame of ``grid.transform``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from csboundary.data.grid import Patch, PatchGrid
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.polyline import (
    arc_lengths,
    dense_samples,
    nearest_on_polyline,
    split_polyline,
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

    def __post_init__(self) -> None:
        if not (self.merge_px > 0 and self.border_px >= 0 and self.snap_px >= 0 and self.mend_px >= 0):
            raise ValueError(f"need merge_px > 0, border_px >= 0, snap_px >= 0, mend_px >= 0; got {self}")


def to_mosaic(graph: BoundaryGraph, patch: Patch) -> BoundaryGraph:
    """A patch graph (pixels of ``patch.expanded``) moved to mosaic pixels."""
    offset = np.array([patch.expanded.col_off, patch.expanded.row_off], float)
    lines = None if graph.edge_polylines is None else [None if p is None else np.asarray(p, float) + offset for p in graph.edge_polylines]
    return BoundaryGraph(graph.vertices + offset, graph.edges, vertex_kinds=graph.vertex_kinds, edge_kinds=graph.edge_kinds,
                         edge_polylines=lines, edge_scores=graph.edge_scores, crs=graph.crs)


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
    cum = arc_lengths(points)
    if len(points) < 2 or cum[-1] == 0:
        return points[0]
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)  # exact segment lengths (a difference of sums is not)
    half = cum[-1] / 2
    k = min(int(np.searchsorted(cum, half, side="right")) - 1, len(steps) - 1)
    t = (half - cum[k]) / steps[k] if steps[k] > 0 else 0.0
    return points[k] + t * (points[k + 1] - points[k])


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


def stitch_patch_graphs(graphs: Mapping[Index, BoundaryGraph], grid: PatchGrid, config: StitchConfig = StitchConfig(),
                        crs: str | None = None) -> BoundaryGraph:
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
    if config.mend_px > 0:
        _mend_seam_ends(kept, registry, grid, config)
    edges = list(kept.values())
    return BoundaryGraph(
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
            out.append(_Candidate(
                line, kinds[u], kinds[v],
                graph.edge_kinds[k] if graph.edge_kinds is not None else "normal",
                float(graph.edge_scores[k]) if graph.edge_scores is not None else np.nan,
                shaped, index, bool(x0 <= mx < x1 and y0 <= my < y1), bool(away[u] and away[v]),
            ))
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


def _edge_line(edge: dict, registry: _VertexRegistry) -> np.ndarray:
    """An output edge's polyline from u to v (its two ends when it has no shape)."""
    if edge["polyline"] is not None:
        return np.asarray(edge["polyline"], float)
    return np.array([registry.points[edge["u"]], registry.points[edge["v"]]], float)


def _components(kept: dict, n_vertices: int) -> np.ndarray:
    """Connected-piece label of every output vertex."""
    pairs = np.array(list(kept), dtype=np.int64).reshape(-1, 2)
    adjacency = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n_vertices, n_vertices))
    return connected_components(adjacency, directed=False)[1]


def _mend_seam_ends(kept: dict, registry: _VertexRegistry, grid: PatchGrid, config: StitchConfig) -> None:
    """Join the ends cut by a window border to the edge of another piece they lie on (module
    docstring, "Seam mending"); edits ``kept`` and ``registry`` in place."""
    n = len(registry.points)
    degree = np.zeros(n, int)
    only_edge: dict[int, tuple[int, int]] = {}
    for key, e in kept.items():
        for x in (e["u"], e["v"]):
            degree[x] += 1
            only_edge[x] = key
    points = np.array(registry.points).reshape(-1, 2)
    ends = [x for x in np.flatnonzero(degree == 1)
            if border_distance(points[x:x + 1], grid.patch(*kept[only_edge[x]]["patch"]), grid)[0] < config.border_px]
    if not ends:
        return
    joins = {x: (kept[only_edge[x]]["score"], kept[only_edge[x]]["patch"]) for x in ends}  # a seam edge's score and patch: its end's edge's
    keys = list(kept)
    lines = [_edge_line(kept[k], registry) for k in keys]
    step = 4.0  # largest spacing of the samples that find an end's candidate edges
    samples = [dense_samples(line, step)[0] for line in lines]
    owner = [np.full(len(s), i) for i, s in enumerate(samples)]
    tree, owner = cKDTree(np.concatenate(samples)), np.concatenate(owner)
    piece = _components(kept, n)
    cuts: dict[int, list[tuple[float, np.ndarray, int]]] = {}  # edge -> (arc position of the foot, foot, end)
    for x, near in zip(ends, tree.query_ball_point(points[ends], config.mend_px + step)):
        best = None
        for i in set(owner[near].tolist()):
            key = keys[i]
            if piece[key[0]] == piece[x]:
                continue
            distance, k, foot = nearest_on_polyline(lines[i], points[x])
            if distance <= config.mend_px and (best is None or distance < best[0]):
                best = (distance, i, k, foot)
        if best is not None:
            _, i, k, foot = best
            position = arc_lengths(lines[i])[k] + float(np.hypot(*(foot - lines[i][k])))
            cuts.setdefault(i, []).append((position, foot, x))
    for i, hits in cuts.items():
        edge = kept.pop(keys[i])
        rest, start = lines[i], edge["u"]
        for _, foot, x in sorted(hits, key=lambda h: h[0]):
            cut = registry.add(foot, SEAM)
            if cut != start:
                head, rest = split_polyline(rest, nearest_on_polyline(rest, foot)[1], foot)
                _put(kept, {**edge, "u": start, "v": cut, "polyline": _shaped(edge, head, registry, start, cut)})
            start = cut
            if cut != x:
                _put(kept, {"u": x, "v": cut, "kind": SEAM, "score": joins[x][0], "polyline": None, "patch": joins[x][1]})
        if start != edge["v"]:
            _put(kept, {**edge, "u": start, "v": edge["v"], "polyline": _shaped(edge, rest, registry, start, edge["v"])})


def _shaped(edge: dict, line: np.ndarray, registry: _VertexRegistry, u: int, v: int) -> np.ndarray | None:
    """A piece's polyline (ends on its vertices) when the split edge had a shape."""
    if edge["polyline"] is None:
        return None
    line = np.array(line, float)
    line[0], line[-1] = registry.points[u], registry.points[v]
    return line


def _better(new: dict, old: dict) -> bool:
    """Between two edges joining the same vertices, a corner edge (it has the curb's shape) wins,
    then the more confident one."""
    if (new["kind"] == "corner") != (old["kind"] == "corner"):
        return new["kind"] == "corner"
    return np.nan_to_num(new["score"], nan=-1) > np.nan_to_num(old["score"], nan=-1)


def _safe_vertices(graphs: Mapping[Index, BoundaryGraph], grid: PatchGrid, config: StitchConfig) -> dict[Index, np.ndarray]:
    """Per patch, its vertices that lie at least ``border_px`` from its window's inner border."""
    out = {}
    for index, graph in graphs.items():
        far = border_distance(graph.vertices, grid.patch(*index), grid) >= config.border_px
        out[index] = graph.vertices[far]
    return out


def _snapped(graph: BoundaryGraph, patch: Patch, grid: PatchGrid, safe: Mapping[Index, np.ndarray], config: StitchConfig) -> np.ndarray:
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
