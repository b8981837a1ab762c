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
old and new edge indices of every edge that was kept. It takes three steps, so each can be read
(and tested) alone: :func:`parse_edit` reads a feature into an :class:`Edit`, :func:`check_edits`
checks the edits against the graph into :class:`CheckedEdits` (indices and graph pixels) and
:func:`apply_checked` makes the new graph from them.
"""

from __future__ import annotations

from collections.abc import Iterable
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


@dataclass(frozen=True)
class Edit:
    """One feature of the edit log as read: nothing in it is trusted yet (:func:`check_edits` does that)."""

    number: int  # its place in the log, to name it in errors
    action: object  # as given
    index: object  # the ``vertex`` property of a ``move``, the ``edge`` property of any other action, as given
    shape: object  # the geometry's ``type``
    coordinates: object  # the geometry's ``coordinates``, as given

    @property
    def what(self) -> str:
        return f"edit {self.number} ({self.action})"


@dataclass(frozen=True)
class CheckedEdits:
    """A log's edits once checked against the graph: indices that exist and positions in graph pixels."""

    deleted: frozenset[int] = frozenset()  # edge indices
    accepted: frozenset[int] = frozenset()  # edge indices
    moves: tuple[tuple[int, np.ndarray], ...] = ()  # (vertex, its new (2,) place), in log order: the last one wins
    added: tuple[np.ndarray, ...] = ()  # (N, 2) lines, N >= 2, in log order
    areas: tuple[list[list[float]], ...] = ()  # closed rings in the graph's CRS


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
    # parsed one at a time as they are checked, so the first bad feature of the log is the one refused
    edits = (parse_edit(number, feature) for number, feature in enumerate(features))
    checked = check_edits(graph, edits, _default_extent(graph) if extent is None else extent, match_px)
    return apply_checked(graph, checked, snap_px)


def _default_extent(graph: BoundaryGraph) -> tuple[float, float, float, float]:
    """The graph's vertices with 1000 px around: where edits may lie when the imagery is not known."""
    low, high = (
        (graph.vertices.min(axis=0), graph.vertices.max(axis=0)) if graph.n_vertices else (np.zeros(2), np.zeros(2))
    )
    return (low[0] - 1000, low[1] - 1000, high[0] + 1000, high[1] + 1000)


# --- parse: a feature read into an Edit ---


def parse_edit(number: int, feature: object) -> Edit:
    """The edit of the ``number``-th feature; only that it is a feature with object parts is
    checked here, its content is checked against the graph by :func:`check_edits`."""
    if not isinstance(feature, dict):
        raise EditError(f"edit {number}: not a GeoJSON feature")
    props = feature.get("properties") or {}
    geometry = feature.get("geometry") or {}
    if not isinstance(props, dict) or not isinstance(geometry, dict):
        raise EditError(f"edit {number}: properties and geometry must be objects")
    action = props.get("action")
    index = props.get("vertex" if action == "move" else "edge")
    return Edit(number, action, index, geometry.get("type"), geometry.get("coordinates"))


# --- check: the edits against the graph ---


def check_edits(
    graph: BoundaryGraph, edits: Iterable[Edit], extent: tuple[float, float, float, float], match_px: float = 1.0
) -> CheckedEdits:
    """``edits`` checked in log order (the first bad one raises :class:`EditError`); ``extent``
    and ``match_px`` as for :func:`apply_edits`. ``graph`` needs a transform."""
    found: dict[str, list] = {action: [] for action in ACTIONS}
    for edit in edits:
        if edit.action in ("delete", "accept"):
            found[edit.action].append(_checked_edge(edit, graph, extent, match_px))
        elif edit.action == "move":
            found["move"].append(_checked_move(edit, graph, extent))
        elif edit.action == "add":
            found["add"].append(_checked_line(edit, graph, extent))
        elif edit.action == "complete":
            found["complete"].append(_complete_ring(edit, graph, extent))
        else:
            raise EditError(f"{edit.what}: unknown action (one of {', '.join(ACTIONS)})")
    return CheckedEdits(
        deleted=frozenset(found["delete"]),
        accepted=frozenset(found["accept"]),
        moves=tuple(found["move"]),
        added=tuple(found["add"]),
        areas=tuple(found["complete"]),
    )


def _pixels(
    coordinates: object, what: str, graph: BoundaryGraph, extent: tuple[float, float, float, float]
) -> np.ndarray:
    """(N, 2) graph pixels of GeoJSON positions, refused unless each is two finite numbers that
    land on the imagery: a damaged file or one in another CRS must not move anything."""
    try:
        if not isinstance(coordinates, list) or not all(isinstance(p, list) and len(p) >= 2 for p in coordinates):
            raise ValueError
        xy = np.array(
            [[float(p[0]), float(p[1])] for p in coordinates if not any(isinstance(v, bool) for v in p[:2])], float
        )
        if len(xy) != len(coordinates):
            raise ValueError
    except (TypeError, ValueError):
        raise EditError(f"{what}: coordinates are not two numbers per position") from None
    if not np.isfinite(xy).all():
        raise EditError(f"{what}: coordinates are not finite")
    cols, rows = world_to_pixel(graph.transform, xy[:, 0], xy[:, 1])
    px = np.stack([np.asarray(cols, float), np.asarray(rows, float)], axis=-1)
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


def _checked_edge(edit: Edit, graph: BoundaryGraph, extent: tuple[float, float, float, float], match_px: float) -> int:
    """The edge a ``delete`` or ``accept`` names, once its geometry shows it is that edge of this
    graph (its ends within ``match_px``, either way round): an index alone could name any edge."""
    k, n_edges = edit.index, graph.n_edges
    if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < n_edges:
        raise EditError(f"{edit.what}: edge {k!r} is not an edge of the graph (0..{n_edges - 1})")
    if edit.shape != "LineString":
        raise EditError(
            f"{edit.what}: no geometry of edge {k} to check it against (export the edits from the review page)"
        )
    line = _pixels(edit.coordinates, edit.what, graph, extent)
    if len(line) < 2:
        raise EditError(f"{edit.what}: the geometry of edge {k} needs at least 2 positions")
    ends = edge_line(graph, k)[[0, -1]]
    gap = min(np.abs(line[[0, -1]] - ends).max(), np.abs(line[[-1, 0]] - ends).max())
    if gap > match_px:
        raise EditError(
            f"{edit.what}: its geometry does not match edge {k} (ends {gap:.1f} px apart): "
            "the edits were made on another graph"
        )
    return k


def _checked_move(
    edit: Edit, graph: BoundaryGraph, extent: tuple[float, float, float, float]
) -> tuple[int, np.ndarray]:
    """The vertex a ``move`` names and its new place in graph pixels."""
    i = edit.index
    if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(graph.vertices):
        raise EditError(f"{edit.what}: vertex {i!r} is not a vertex of the graph")
    if edit.shape != "Point":
        raise EditError(f"{edit.what}: needs a Point geometry")
    return i, _pixels([edit.coordinates], edit.what, graph, extent)[0]


def _checked_line(edit: Edit, graph: BoundaryGraph, extent: tuple[float, float, float, float]) -> np.ndarray:
    """The line of an ``add`` in graph pixels."""
    if edit.shape != "LineString":
        raise EditError(f"{edit.what}: needs a LineString geometry")
    line = _pixels(edit.coordinates, edit.what, graph, extent)
    if len(line) < 2:
        raise EditError(f"{edit.what}: needs a LineString of at least 2 positions")
    return line


def _complete_ring(edit: Edit, graph: BoundaryGraph, extent: tuple[float, float, float, float]) -> list[list[float]]:
    """The outer ring of a ``complete`` edit's Polygon in world coordinates, closed, checked to
    lie on the imagery, to enclose an area and to cover at least a pixel of the imagery itself,
    not only the margin around it (fine-tuning labels nothing there)."""
    rings = edit.coordinates if edit.shape == "Polygon" else None
    if not isinstance(rings, list) or not rings:
        raise EditError(f"{edit.what}: needs a Polygon geometry")
    ring = _pixels(rings[0], edit.what, graph, extent)
    if len(ring) < 3 or not Polygon(ring).is_valid or Polygon(ring).area < 1.0:
        raise EditError(
            f"{edit.what}: the polygon needs 3 corners around an area of at least one pixel, without crossing itself"
        )
    if Polygon(ring).intersection(box(*extent)).area < 1.0:
        raise EditError(f"{edit.what}: the polygon covers no pixel of the imagery, only the margin around it")
    world = [[float(x), float(y)] for x, y in (p[:2] for p in rings[0])]
    return world if world[0] == world[-1] else [*world, world[0]]


# --- apply: the checked edits make the new graph ---


def apply_checked(
    graph: BoundaryGraph, edits: CheckedEdits, snap_px: float = 1.0
) -> tuple[BoundaryGraph, ReviewRecord]:
    """The new graph and its record: kept edges first, in their old order, then the added ones in
    log order, whose ends join vertices within ``snap_px`` (earlier added ends included)."""
    vertices = graph.vertices.copy()
    for i, place in edits.moves:
        vertices[i] = place
    kept, (new_edges, new_kinds, new_lines, new_scores, new_patches) = _kept_edges(graph, vertices, edits)
    record = ReviewRecord(
        deleted=sorted(edits.deleted),
        accepted=sorted(kept[k] for k in edits.accepted if k in kept),
        moved=sorted({i for i, _ in edits.moves}),
        kept=kept,
        complete_areas=list(edits.areas),
    )
    vertices, added = _join_lines(vertices, edits.added, snap_px)
    for u, v, line in added:
        record.added.append(len(new_edges))
        new_edges.append((u, v))
        new_kinds.append(MANUAL)
        new_lines.append(line if len(line) > 2 else None)
        new_scores.append(1.0)
        new_patches.append(np.array([-1, -1]))
    result = BoundaryGraph(
        vertices,
        np.array(new_edges, np.int64).reshape(-1, 2),
        vertex_kinds=list(graph.vertex_kinds or ["vertex"] * graph.n_vertices)
        + [MANUAL] * (len(vertices) - len(graph.vertices)),
        edge_kinds=new_kinds,
        edge_polylines=new_lines,
        edge_scores=np.array(new_scores, float),
        edge_patches=np.array(new_patches, np.int64).reshape(-1, 2),
        transform=graph.transform,
        crs=graph.crs,
    )
    return result, record


def _kept_edges(graph: BoundaryGraph, vertices: np.ndarray, edits: CheckedEdits) -> tuple[dict[int, int], list[list]]:
    """The edges not deleted, in their old order: old -> new index, and their (u, v) pairs,
    kinds, polylines (whose ends follow moved ``vertices``), scores and patches."""
    n = graph.n_edges
    edges = [tuple(int(x) for x in e) for e in graph.edges]
    polylines = _follow_moves(list(graph.edge_polylines or [None] * n), edges, vertices, {i for i, _ in edits.moves})
    scores = np.asarray(graph.edge_scores if graph.edge_scores is not None else np.full(n, np.nan), float)
    patches = np.asarray(graph.edge_patches if graph.edge_patches is not None else np.full((n, 2), -1), np.int64)
    kinds = list(graph.edge_kinds or ["normal"] * n)
    kept = {k: new for new, k in enumerate(k for k in range(n) if k not in edits.deleted)}
    return kept, [[column[k] for k in kept] for column in (edges, kinds, polylines, scores, patches)]


def _with_ends(line: object, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """A float copy of ``line`` from ``start`` to ``end``: the caller's line stays as it was."""
    line = np.asarray(line, float).copy()
    line[0], line[-1] = start, end
    return line


def _follow_moves(
    polylines: list[np.ndarray | None], edges: list[tuple[int, int]], vertices: np.ndarray, moved: set[int]
) -> list[np.ndarray | None]:
    """``polylines`` whose ends follow the moved vertices of their edges (new arrays: the graph's stay)."""
    return [
        line if line is None or (u not in moved and v not in moved) else _with_ends(line, vertices[u], vertices[v])
        for line, (u, v) in zip(polylines, edges)
    ]


def _join_lines(
    vertices: np.ndarray, lines: tuple[np.ndarray, ...], snap_px: float
) -> tuple[np.ndarray, list[tuple[int, int, np.ndarray]]]:
    """``vertices`` with the new ends of ``lines``, and each line as (u, v, line with its ends on
    u and v); an end within ``snap_px`` of a vertex (an earlier line's new end included) joins it."""
    joined = []
    for line in lines:
        vertices, u = _vertex_at(vertices, line[0], snap_px)
        vertices, v = _vertex_at(vertices, line[-1], snap_px)
        if u == v:
            raise EditError("an added edge starts and ends on the same vertex")
        joined.append((u, v, _with_ends(line, vertices[u], vertices[v])))
    return vertices, joined


def _vertex_at(vertices: np.ndarray, point: np.ndarray, snap_px: float) -> tuple[np.ndarray, int]:
    """The nearest vertex within ``snap_px`` of ``point``, else ``vertices`` with ``point`` appended and its index."""
    if len(vertices):
        d = np.linalg.norm(vertices - point, axis=1)
        if d.min() <= snap_px:
            return vertices, int(d.argmin())
    return np.vstack([vertices, point[None]]), len(vertices)
