"""A prediction's ``edges`` layer as a person edited it in a GIS (QGIS's own editing tools), turned
into the edits the review page exports (:mod:`csboundary.graph.review_edits`), so that both go
through the same checks and the same record.

What each change to the layer means:

* a feature deleted: its edge is deleted;
* an end of a feature moved (a vertex dragged): the graph vertex at that end moves, with the ends
  of every edge at it; two features moving one vertex to two places is refused;
* a feature's line changed between its ends (vertices added, moved or removed inside it): the
  edge is replaced by the line as drawn (a deletion and an added edge);
* a feature drawn (no ``edge_id``, or one already used by another feature): an added edge; a
  feature whose line was only reversed is unchanged;
* a polygon in the ``complete`` layer: an area marked complete.

The review layers ``review --gpkg`` writes hold boundaries, not edges: :func:`boundary_layer_edits`
turns their changes into the same edits, a boundary at a time.

Features keep their ``edge_id`` and the ``u`` and ``v`` of the graph they were written from; a
layer whose ``u``/``v`` disagree with the graph's was written for another prediction and is
refused, rather than read as a set of moves.
"""

from __future__ import annotations

import numpy as np

from csboundary.data.windows import pixel_to_world, world_to_pixel
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import edge_line
from csboundary.graph.review_edits import EditError

# a position that moved less than this (graph pixels) did not move: coordinates round-trip through the layer's floats
SAME_PX = 0.01
AGREE_PX = 0.5  # two features moving one vertex must put it within this of each other


def layer_edits(
    graph: BoundaryGraph,
    rows: list[tuple[int | None, int | None, int | None, np.ndarray]],
    areas: list[list[list[float]]] = (),
) -> list[dict]:
    """The review page's edit features (GeoJSON, the graph's CRS) equivalent to an edited
    ``edges`` layer: ``rows`` are its features as (edge_id, u, v, (N, 2) world coordinates),
    ``edge_id``/``u``/``v`` None for a drawn feature; ``areas`` are the exterior rings (world
    coordinates) of the ``complete`` layer's polygons."""
    if graph.transform is None:
        raise EditError("the graph has no transform: the layer's world coordinates cannot be placed")
    original = {k: edge_line(graph, k) for k in range(graph.n_edges)}
    kept: dict[int, np.ndarray] = {}
    drawn: list[np.ndarray] = []
    for number, (edge_id, u, v, coords) in enumerate(rows):
        line = _pixels(graph, coords)
        if len(line) < 2:
            raise EditError(f"feature {number} of the edges layer: a line needs at least 2 positions")
        if edge_id is None or edge_id in kept:
            drawn.append(line)
            continue
        if not 0 <= edge_id < graph.n_edges:
            raise EditError(
                f"feature {number} of the edges layer: edge_id {edge_id} is not an edge of the graph (0..{graph.n_edges - 1})"
            )
        if (u, v) != tuple(int(x) for x in graph.edges[edge_id]):
            raise EditError(
                f"feature {number} of the edges layer: edge {edge_id} joins vertices {u} and {v} there but "
                f"{graph.edges[edge_id][0]} and {graph.edges[edge_id][1]} in graph.json: the layer was written "
                "for another prediction"
            )
        kept[edge_id] = line
    moves: dict[int, tuple[np.ndarray, int]] = {}
    replaced: list[int] = []
    for k, line in list(kept.items()):
        before = original[k]
        if np.abs(line[[0, -1]] - before[[-1, 0]]).max() <= SAME_PX < np.abs(line[[0, -1]] - before[[0, -1]]).max():
            kept[k] = line = line[::-1]  # the line's direction reversed in the GIS (QGIS: Reverse Line): the same edge
        for vertex, old, new in ((graph.edges[k][0], before[0], line[0]), (graph.edges[k][1], before[-1], line[-1])):
            if np.abs(new - old).max() <= SAME_PX:
                continue
            if vertex in moves and np.abs(moves[vertex][0] - new).max() > AGREE_PX:
                raise EditError(
                    f"vertex {vertex} is moved to two places, by edges {moves[vertex][1]} and {k}: move it once, "
                    "with both lines (QGIS: topological editing)"
                )
            moves[int(vertex)] = (new, k)
        inside_same = len(line) == len(before) and np.abs(line[1:-1] - before[1:-1]).max(initial=0.0) <= SAME_PX
        if not inside_same:
            replaced.append(k)
    features = [
        _feature("delete", _world(graph, original[k]), edge=k) for k in sorted(set(range(graph.n_edges)) - set(kept))
    ]
    features += [_feature("delete", _world(graph, original[k]), edge=k) for k in sorted(replaced)]
    features += [
        {
            "type": "Feature",
            "properties": {"action": "move", "vertex": vertex},
            "geometry": {"type": "Point", "coordinates": _world(graph, new[None])[0]},
        }
        for vertex, (new, _) in sorted(moves.items())
    ]
    features += [_feature("add", _world(graph, kept[k])) for k in sorted(replaced)]
    features += [_feature("add", _world(graph, line)) for line in drawn]
    features += [
        {
            "type": "Feature",
            "properties": {"action": "complete"},
            "geometry": {"type": "Polygon", "coordinates": [ring]},
        }
        for ring in areas
    ]
    return features


def _pixels(graph: BoundaryGraph, coords: np.ndarray) -> np.ndarray:
    cols, rows = world_to_pixel(graph.transform, coords[:, 0], coords[:, 1])
    return np.stack([np.asarray(cols, float), np.asarray(rows, float)], axis=-1)


def _world(graph: BoundaryGraph, line: np.ndarray) -> list[list[float]]:
    xs, ys = pixel_to_world(graph.transform, line[:, 0], line[:, 1])
    return [[float(x), float(y)] for x, y in zip(np.atleast_1d(xs), np.atleast_1d(ys))]


def _feature(action: str, coordinates: list[list[float]], **properties) -> dict:
    geometry = {"type": "LineString", "coordinates": coordinates}
    return {"type": "Feature", "properties": {"action": action, **properties}, "geometry": geometry}


def boundary_layer_edits(
    graph: BoundaryGraph,
    rows: list[tuple[list[int] | None, np.ndarray, bool]],
    areas: list[list[list[float]]] = (),
    held_back: frozenset[tuple[int, ...]] = frozenset(),
) -> list[dict]:
    """The review page's edit features equivalent to edited boundary layers (``review --gpkg``):
    ``rows`` are their features as (edge ids of the boundary, None for a drawn feature; (N, 2)
    world coordinates; True when the feature lies in the layer of the review draft, False in the
    layer of held-back boundaries). Per boundary of the graph (a chain,
    :func:`~csboundary.graph.boundaries.graph_boundaries`):

    * no feature names it: its edges are deleted;
    * one feature with its line unchanged (or only reversed; copies of one line count once):
      nothing changes; a boundary of ``held_back`` (its sorted edge ids) copied or moved into the
      draft's layer is accepted;
    * one feature whose two ends moved and nothing else: the vertices at its ends move;
    * otherwise (its line changed inside, or it was split into several features): its edges are
      deleted and each feature's line is added as drawn.

    Features without edge ids are added (after the replacements, in the layers' order); ``areas``
    are marked complete. The result goes through :func:`layer_edits`, and from there through the
    same checks as the page's edits."""
    from csboundary.graph.boundaries import graph_boundaries

    if graph.transform is None:
        raise EditError("the graph has no transform: the layer's world coordinates cannot be placed")
    boundaries = {tuple(sorted(b.edges.tolist())): b for b in graph_boundaries(graph)}
    by_edges: dict[tuple[int, ...], list[tuple[np.ndarray, bool]]] = {}
    drawn: list[np.ndarray] = []
    for number, (edge_ids, coords, in_draft) in enumerate(rows):
        if edge_ids is None:
            drawn.append(coords)
            continue
        key = tuple(sorted(edge_ids))
        if key not in boundaries:
            raise EditError(
                f"feature {number} of the boundaries layers: edges {';'.join(map(str, edge_ids))} are not one boundary of "
                "graph.json: the layer was written for another prediction"
            )
        by_edges.setdefault(key, []).append((coords, in_draft))
    edge_rows: list[tuple[int | None, int | None, int | None, np.ndarray]] = []
    accepted: list[int] = []
    replaced: list[np.ndarray] = []
    for key, boundary in boundaries.items():
        features = by_edges.get(key, [])
        lines = {k: edge_line(graph, k) for k in key}
        if not features:
            continue  # deleted: its edges are missing from the rows
        before = boundary.polyline
        distinct = [features[0]]
        for coords, in_draft in features[1:]:  # a copy of a line (copied into the other layer) is the same feature
            same = [
                d
                for d in distinct
                if len(d[0]) == len(coords)
                and min(np.abs(d[0] - coords).max(), np.abs(d[0][::-1] - coords).max()) <= 1e-9
            ]
            if same:
                distinct[distinct.index(same[0])] = (same[0][0], same[0][1] or in_draft)
            else:
                distinct.append((coords, in_draft))
        features = distinct
        if len(features) == 1:
            line = _pixels(graph, features[0][0])
            if (
                len(line) == len(before)
                and np.abs(line[[0, -1]] - before[[-1, 0]]).max() <= SAME_PX
                and np.abs(line - before[::-1]).max() > SAME_PX >= np.abs(line[::-1] - before).max()
            ):
                line = line[::-1]  # reversed in the GIS: the same boundary
            if len(line) == len(before) and np.abs(line[1:-1] - before[1:-1]).max(initial=0.0) <= SAME_PX:
                ends = {
                    int(v): new
                    for v, old, new in (
                        (_end(graph, boundary, 0), before[0], line[0]),
                        (_end(graph, boundary, -1), before[-1], line[-1]),
                    )
                    if np.abs(new - old).max() > SAME_PX
                }
                for k, piece in lines.items():
                    piece = piece.copy()
                    u, v = (int(x) for x in graph.edges[k])
                    if u in ends:
                        piece[0] = ends[u]
                    if v in ends:
                        piece[-1] = ends[v]
                    edge_rows.append((k, u, v, graph.to_world(piece)))
                if features[0][1] and key in held_back:
                    accepted.extend(key)
                continue
        replaced.extend(coords for coords, _ in features)  # changed inside, or split: replaced by what was drawn
    features = layer_edits(graph, edge_rows + [(None, None, None, coords) for coords in replaced + drawn], areas)
    return features + [_feature("accept", _world(graph, edge_line(graph, k)), edge=k) for k in sorted(accepted)]


def _end(graph: BoundaryGraph, boundary, at: int) -> int:
    """The vertex at the start (``at`` 0) or the end (-1) of a boundary's walk."""
    chain_first, chain_last = boundary.edges[0], boundary.edges[-1]
    if at == 0:
        u, v = graph.edges[chain_first]
        point = boundary.polyline[0]
    else:
        u, v = graph.edges[chain_last]
        point = boundary.polyline[-1]
    return int(u if np.abs(graph.vertices[u] - point).max() <= np.abs(graph.vertices[v] - point).max() else v)
