"""A reviewer's edits applied to a predicted graph (``csboundary apply-review``).

The review page exports its edits as a GeoJSON FeatureCollection in the graph's CRS; each
feature's ``action`` property says what a person did:

* ``delete`` (``edge``: the edge's index in graph.json, LineString geometry: the edge as the
  page drew it): the edge goes;
* ``accept`` (``edge``, its geometry): the edge stays and is recorded as checked;
* ``move`` (``vertex``: its index, Point geometry): the vertex moves, and so do the ends of
  the edges at it;
* ``add`` (LineString geometry): a new edge, kind ``manual``, score 1; its ends join existing
  vertices within ``snap_px`` pixels, else become new vertices;
* ``complete`` (Polygon geometry): the reviewer vouches that inside it every boundary is drawn and
  every drawn edge is right, so the reviewed graph there is a label (fine-tuning trains on it and
  treats the rest as unknown). The graph does not change. The polygon must cover imagery, not
  only the margin around it that other edits may reach.

Nothing is taken on trust: an edge's index must come with that edge's geometry (its two ends
within ``match_px``), and every coordinate must be a pair of finite numbers inside ``extent``
(the imagery, in graph pixels), so edits meant for another graph, in another CRS or damaged in
transit are refused (:class:`EditError`) instead of changing the wrong edge.

:func:`apply_edits` is pure: it returns the new graph and a record of what changed, with the
old and new edge indices of every edge that was kept.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from shapely.geometry import Polygon, box

from csboundary.data.windows import world_to_pixel
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import edge_line

ACTIONS = ("delete", "accept", "move", "add", "complete")
MANUAL = "manual"


class EditError(ValueError):
    """An edit that does not fit the graph (unknown action, edge or vertex; bad geometry)."""


@dataclass
class ReviewRecord:
    deleted: list[int] = field(default_factory=list)  # old edge indices
    accepted: list[int] = field(default_factory=list)  # new edge indices
    moved: list[int] = field(default_factory=list)  # vertex indices
    added: list[int] = field(default_factory=list)  # new edge indices
    kept: dict[int, int] = field(default_factory=dict)  # old edge index -> new edge index
    complete_areas: list[list[list[float]]] = field(default_factory=list)  # closed rings in the graph's CRS

    def to_dict(self) -> dict:
        return {
            "deleted_edges": self.deleted,
            "accepted_edges": self.accepted,
            "moved_vertices": self.moved,
            "added_edges": self.added,
            "edge_index_map": {str(k): v for k, v in self.kept.items()},
            "complete_areas": self.complete_areas,
        }


EXTENT_MARGIN_PX = 100.0  # edits may reach this far beyond the imagery


def apply_edits(
    graph: BoundaryGraph,
    features: list[dict],
    snap_px: float = 1.0,
    extent: tuple[float, float, float, float] | None = None,
    match_px: float = 1.0,
) -> tuple[BoundaryGraph, ReviewRecord]:
    """``graph`` with the edits of ``features`` (GeoJSON features in the graph's CRS).
    ``extent`` (col0, row0, col1, row1 in graph pixels; default: the graph's vertices, 1000 px
    around) is where edits may lie, :data:`EXTENT_MARGIN_PX` beyond it."""
    if graph.transform is None:
        raise EditError("the graph has no transform: world coordinates of the edits cannot be placed")
    if extent is None:
        low, high = (
            (graph.vertices.min(axis=0), graph.vertices.max(axis=0)) if graph.n_vertices else (np.zeros(2), np.zeros(2))
        )
        extent = (low[0] - 1000, low[1] - 1000, high[0] + 1000, high[1] + 1000)
    vertices = graph.vertices.copy()
    n_edges = graph.n_edges
    kinds = list(graph.edge_kinds or ["normal"] * n_edges)
    polylines = list(graph.edge_polylines or [None] * n_edges)
    scores = np.asarray(graph.edge_scores if graph.edge_scores is not None else np.full(n_edges, np.nan), float).copy()
    patches = np.asarray(
        graph.edge_patches if graph.edge_patches is not None else np.full((n_edges, 2), -1), np.int64
    ).copy()
    vertex_kinds = list(graph.vertex_kinds or ["vertex"] * graph.n_vertices)
    edges = [tuple(int(x) for x in e) for e in graph.edges]
    deleted, accepted, moved = set(), set(), []
    added: list[np.ndarray] = []
    areas: list[list[list[float]]] = []

    def pixels(coordinates, what: str, points: bool = True) -> np.ndarray:
        """(N, 2) graph pixels of GeoJSON positions (a Point's one position when not ``points``)."""
        rows = coordinates if points else [coordinates]
        try:
            if not isinstance(rows, list) or not all(isinstance(p, list) and len(p) >= 2 for p in rows):
                raise ValueError
            xy = np.array(
                [[float(p[0]), float(p[1])] for p in rows if not any(isinstance(v, bool) for v in p[:2])], float
            )
            if len(xy) != len(rows):
                raise ValueError
        except (TypeError, ValueError):
            raise EditError(f"{what}: coordinates are not two numbers per position") from None
        if not np.isfinite(xy).all():
            raise EditError(f"{what}: coordinates are not finite")
        cols, rows_px = world_to_pixel(graph.transform, xy[:, 0], xy[:, 1])
        px = np.stack([np.asarray(cols, float), np.asarray(rows_px, float)], axis=-1)
        m = EXTENT_MARGIN_PX
        inside = (
            (px[:, 0] >= extent[0] - m)
            & (px[:, 0] <= extent[2] + m)
            & (px[:, 1] >= extent[1] - m)
            & (px[:, 1] <= extent[3] + m)
        )
        if not (np.isfinite(px).all() and inside.all()):
            crs = f" ({graph.crs})" if graph.crs else ""
            raise EditError(f"{what}: coordinates lie outside the imagery: are they in the prediction's CRS{crs}?")
        return px

    def edge_index(props: dict, geometry: dict, what: str) -> int:
        k = props.get("edge")
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < n_edges:
            raise EditError(f"{what}: edge {k!r} is not an edge of the graph (0..{n_edges - 1})")
        if geometry.get("type") != "LineString":
            raise EditError(
                f"{what}: no geometry of edge {k} to check it against (export the edits from the review page)"
            )
        line = pixels(geometry.get("coordinates"), what)
        if len(line) < 2:
            raise EditError(f"{what}: the geometry of edge {k} needs at least 2 positions")
        ends = edge_line(graph, k)[[0, -1]]
        gap = min(np.abs(line[[0, -1]] - ends).max(), np.abs(line[[-1, 0]] - ends).max())
        if gap > match_px:
            raise EditError(
                f"{what}: its geometry does not match edge {k} (ends {gap:.1f} px apart): "
                "the edits were made on another graph"
            )
        return k

    for number, feature in enumerate(features):
        if not isinstance(feature, dict):
            raise EditError(f"edit {number}: not a GeoJSON feature")
        props = feature.get("properties") or {}
        geometry = feature.get("geometry") or {}
        if not isinstance(props, dict) or not isinstance(geometry, dict):
            raise EditError(f"edit {number}: properties and geometry must be objects")
        action = props.get("action")
        what = f"edit {number} ({action})"
        if action == "delete":
            deleted.add(edge_index(props, geometry, what))
        elif action == "accept":
            accepted.add(edge_index(props, geometry, what))
        elif action == "move":
            i = props.get("vertex")
            if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(vertices):
                raise EditError(f"{what}: vertex {i!r} is not a vertex of the graph")
            if geometry.get("type") != "Point":
                raise EditError(f"{what}: needs a Point geometry")
            vertices[i] = pixels(geometry.get("coordinates"), what, points=False)[0]
            moved.append(i)
        elif action == "add":
            if geometry.get("type") != "LineString":
                raise EditError(f"{what}: needs a LineString geometry")
            line = pixels(geometry.get("coordinates"), what)
            if len(line) < 2:
                raise EditError(f"{what}: needs a LineString of at least 2 positions")
            added.append(line)
        elif action == "complete":
            areas.append(_complete_ring(geometry, what, pixels, extent))
        else:
            raise EditError(f"{what}: unknown action (one of {', '.join(ACTIONS)})")

    # moved vertices carry the ends of their edges' polylines
    for k, (u, v) in enumerate(edges):
        if polylines[k] is not None and (u in moved or v in moved):
            line = np.asarray(polylines[k], float).copy()
            line[0], line[-1] = vertices[u], vertices[v]
            polylines[k] = line

    record = ReviewRecord(deleted=sorted(deleted), moved=sorted(set(moved)), complete_areas=areas)
    new_edges, new_kinds, new_lines, new_scores, new_patches = [], [], [], [], []
    for k in range(n_edges):
        if k in deleted:
            continue
        record.kept[k] = len(new_edges)
        new_edges.append(edges[k])
        new_kinds.append(kinds[k])
        new_lines.append(polylines[k])
        new_scores.append(scores[k])
        new_patches.append(patches[k])
    record.accepted = sorted(record.kept[k] for k in accepted if k in record.kept)

    def vertex_at(point: np.ndarray) -> int:
        nonlocal vertices
        if len(vertices):
            d = np.linalg.norm(vertices - point, axis=1)
            if d.min() <= snap_px:
                return int(d.argmin())
        vertices = np.vstack([vertices, point[None]])
        vertex_kinds.append(MANUAL)
        return len(vertices) - 1

    for line in added:
        u, v = vertex_at(line[0]), vertex_at(line[-1])
        if u == v:
            raise EditError("an added edge starts and ends on the same vertex")
        line = line.copy()
        line[0], line[-1] = vertices[u], vertices[v]
        record.added.append(len(new_edges))
        new_edges.append((u, v))
        new_kinds.append(MANUAL)
        new_lines.append(line if len(line) > 2 else None)
        new_scores.append(1.0)
        new_patches.append(np.array([-1, -1]))

    result = BoundaryGraph(
        vertices,
        np.array(new_edges, np.int64).reshape(-1, 2),
        vertex_kinds=vertex_kinds,
        edge_kinds=new_kinds,
        edge_polylines=new_lines,
        edge_scores=np.array(new_scores, float),
        edge_patches=np.array(new_patches, np.int64).reshape(-1, 2),
        transform=graph.transform,
        crs=graph.crs,
    )
    return result, record


def _complete_ring(geometry: dict, what: str, pixels, extent: tuple[float, float, float, float]) -> list[list[float]]:
    """The outer ring of a ``complete`` edit's Polygon in world coordinates, closed, checked to
    lie on the imagery (``pixels`` raises otherwise), to enclose an area and to cover at least a
    pixel of the imagery itself, not only the margin around it (fine-tuning labels nothing there)."""
    rings = geometry.get("coordinates") if geometry.get("type") == "Polygon" else None
    if not isinstance(rings, list) or not rings:
        raise EditError(f"{what}: needs a Polygon geometry")
    ring = pixels(rings[0], what)
    if len(ring) < 3 or not Polygon(ring).is_valid or Polygon(ring).area < 1.0:
        raise EditError(
            f"{what}: the polygon needs 3 corners around an area of at least one pixel, without crossing itself"
        )
    if Polygon(ring).intersection(box(*extent)).area < 1.0:
        raise EditError(f"{what}: the polygon covers no pixel of the imagery, only the margin around it")
    world = [[float(x), float(y)] for x, y in (p[:2] for p in rings[0])]
    return world if world[0] == world[-1] else [*world, world[0]]
