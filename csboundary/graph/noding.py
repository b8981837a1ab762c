"""Edges whose polylines run through the same point meet there.

Corner edges follow the keypoint skeleton pixel by pixel, so a keypoint blob cut by a window
border gives the patch that sees part of it a corner edge that runs along the same pixels as
the neighbour's corner edge over the whole blob, for a stretch, then stops. Both are kept (each
patch owns the edge whose midpoint is in its core), but without a shared vertex the graph has
two pieces lying on top of each other: APLS counts every route across as lost. On the seed-7
test city 44 pairs of edges shared 520 polyline points this way.

:func:`node_shared_points` first puts the points where two lines cross or touch between their
own points into both polylines (the same coordinates in both), then cuts every edge at the points
it shares with another edge where the two do not run on together (an overlap starts or ends,
the lines cross, one of them ends there), so overlapping stretches end on the same vertices; a
stretch that two edges follow point for point is kept once (the corner edge, else the more
confident). Points are compared exactly (to 1e-6 px): windows are shifted by whole pixels, so
the same skeleton pixel has the same coordinates in every patch. A line crossing itself is not
cut at the crossing.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
from shapely import STRtree
from shapely.geometry import LineString

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.end_attachment import better_edge
from csboundary.graph.polyline import nearest_on_polyline

NODE = "node"  # the kind of a vertex added where edges meet mid-line
_KEY_SCALE = 1e6  # points equal to 1e-6 px are the same point (BoundaryGraph.from_polylines's default)


def _keys(line: np.ndarray) -> list[tuple[int, int]]:
    return list(map(tuple, np.rint(np.asarray(line, float).reshape(-1, 2) * _KEY_SCALE).astype(np.int64).tolist()))


def _cut_points(keys: list[list[tuple[int, int]]]) -> set[tuple[int, int]]:
    """The points of the polylines (point keys) where edges meet rather than run together: a
    point on two or more edges where they do not all pass from the same point to the same point
    (an overlap starts or ends, lines cross, or one of them ends there)."""
    ways: dict[tuple[int, int], set] = defaultdict(
        set
    )  # point -> the (unordered) neighbours each edge passes it between
    count: dict[tuple[int, int], int] = defaultdict(int)
    for line_keys in keys:
        for k, key in enumerate(line_keys):
            count[key] += 1
            inner = 0 < k < len(line_keys) - 1
            ways[key].add(frozenset((line_keys[k - 1], line_keys[k + 1])) if inner else ("end", id(line_keys), k))
    return {key for key, n in count.items() if n > 1 and len(ways[key]) > 1}


def _crossing_points(geometry) -> list[tuple[float, float]]:
    """The points of an intersection: its points, and the ends of any stretch two lines share."""
    parts = getattr(geometry, "geoms", [geometry])
    out = []
    for part in parts:
        if part.is_empty:
            continue
        coords = np.asarray(part.coords)
        out += [tuple(coords[0]), tuple(coords[-1])] if part.geom_type == "LineString" else [tuple(c) for c in coords]
    return out


def _with_crossings(lines: list[np.ndarray]) -> list[np.ndarray]:
    """The polylines with the points where two of them cross (or touch between their own points)
    inserted into both, at the same coordinates."""
    strings = [LineString(line) for line in lines]
    first, second = STRtree(strings).query(strings, predicate="intersects")
    extra: dict[int, list[tuple[float, float]]] = defaultdict(list)
    for i, j in zip(first.tolist(), second.tolist()):
        if i < j:
            for point in _crossing_points(strings[i].intersection(strings[j])):
                extra[i].append(point)
                extra[j].append(point)
    out = list(lines)
    for e, points in extra.items():
        line = np.asarray(lines[e], float)
        present = set(_keys(line))
        for point, key in zip(points, _keys(points)):
            if key in present:
                continue
            _, segment, _ = nearest_on_polyline(line, np.asarray(point))
            line = np.insert(line, segment + 1, point, axis=0)
            present.add(key)
        out[e] = line
    return out


def node_shared_points(graph: BoundaryGraph) -> BoundaryGraph:
    """``graph`` with its edges cut where their polylines share points (module docstring);
    ``graph`` itself when no two edges share an interior point."""
    lines = _with_crossings([graph.edge_polyline(e) for e in range(graph.n_edges)]) if graph.n_edges > 1 else []
    keys = [_keys(line) for line in lines]
    # every edge through a cut point is cut there, so two edges that run together are cut at the
    # same points and their common stretch is the same piece
    cut_keys = _cut_points(keys)
    cuts = [[k for k in range(1, len(line_keys) - 1) if line_keys[k] in cut_keys] for line_keys in keys]
    if not any(cuts):
        return graph

    vertex_of = {key: v for v, key in enumerate(_keys(graph.vertices))}
    points, kinds = list(graph.vertices), list(graph.vertex_kinds or ["isolated"] * graph.n_vertices)
    scores = graph.edge_scores if graph.edge_scores is not None else np.ones(graph.n_edges)
    edge_kinds = graph.edge_kinds or ["normal"] * graph.n_edges
    pieces: dict[tuple, dict] = {}  # the piece's point keys, first point first in canonical order -> piece
    for e, line in enumerate(lines):
        bounds = [0, *cuts[e], len(line) - 1]
        for start, stop in zip(bounds, bounds[1:]):
            ids = []
            for k in (start, stop):
                key = keys[e][k]
                if key not in vertex_of:
                    vertex_of[key] = len(points)
                    points.append(line[k])
                    kinds.append(NODE)
                ids.append(vertex_of[key])
            if ids[0] == ids[1] and stop - start < 2:
                continue
            span = tuple(keys[e][start : stop + 1])
            canonical = min(span, span[::-1])
            piece = {
                "u": ids[0],
                "v": ids[1],
                "line": line[start : stop + 1],
                "shaped": graph.edge_polylines is not None and graph.edge_polylines[e] is not None,
                "kind": edge_kinds[e],
                "score": scores[e],
                "patch": None if graph.edge_patches is None else graph.edge_patches[e],
            }
            old = pieces.get(canonical)
            if old is None or better_edge(piece["kind"], piece["score"], old["kind"], old["score"]):
                pieces[canonical] = piece
    kept = list(pieces.values())
    return BoundaryGraph(
        np.array(points, float).reshape(-1, 2),
        np.array([[p["u"], p["v"]] for p in kept], np.int64).reshape(-1, 2),
        vertex_kinds=kinds,
        edge_kinds=[p["kind"] for p in kept],
        edge_polylines=[np.array(p["line"], float) if p["shaped"] else None for p in kept],
        edge_scores=np.array([p["score"] for p in kept], float),
        edge_patches=None
        if graph.edge_patches is None
        else np.array([p["patch"] for p in kept], np.int64).reshape(-1, 2),
        transform=graph.transform,
        crs=graph.crs,
    )
