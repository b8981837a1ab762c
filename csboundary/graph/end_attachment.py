"""Dangling ends joined to the nearest point of another connected piece's line.

A boundary that stops a few metres short of another one is a broken graph for every route
through it: a curb that reaches a cross street's curb under a tree, a cul-de-sac mouth, a
boundary cut by a window border. Here such an end is joined to the nearest point of an edge of
another connected piece within a radius; that edge is split at the point (a new vertex, unless
an existing one lies within ``merge_px``) and a straight edge of the given kind joins the end to
it. Where ``headings`` are given, the point must lie ahead of the end (within ``max_turn_deg``
of the direction its line was going), so a line is not bent back across the road.

Three users: seam mending in :mod:`csboundary.graph.stitching` (ends cut by a window border, no
heading), the city graph's attachment of every other end (``city_graph`` in
:mod:`csboundary.pipeline.prediction.city`, the bundle's ``attach_ends``, ``--attach-ends``), and the
window's attachment where the boundary map backs the join (:mod:`csboundary.graph.end_joining`,
``attach_backed``, ``--attach-backed``; the ``accept`` test).
Pure geometry on pixel (col, row) coordinates.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.spatial import cKDTree
from shapely import STRtree, points
from shapely.geometry import LineString

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.fragments import fragment_lengths
from csboundary.graph.polyline import (
    arc_lengths,
    nearest_on_polyline,
    split_polyline,
)

ATTACH = "attach"  # the kind of the city graph's edge from a dangling end to the line ahead of it


def better_edge(new_kind: str, new_score: float, old_kind: str, old_score: float) -> bool:
    """Between two edges joining the same vertices, a corner edge (it has the curb's shape) wins,
    then the more confident one."""
    if (new_kind == "corner") != (old_kind == "corner"):
        return new_kind == "corner"
    return np.nan_to_num(new_score, nan=-1) > np.nan_to_num(old_score, nan=-1)


def dangling_ends(graph: BoundaryGraph) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ends (K,), their edges (K,), headings (K, 2)): the vertices with exactly one edge, that
    edge, and the unit direction the edge's line was going when it reached the end ((0, 0) for
    a zero-length last step)."""
    degree = np.bincount(graph.edges.ravel(), minlength=graph.n_vertices)
    ends = np.flatnonzero(degree == 1)
    edge_of = np.full(graph.n_vertices, -1)
    for e, (u, v) in enumerate(graph.edges):
        edge_of[u], edge_of[v] = e, e
    headings = np.zeros((len(ends), 2))
    for k, x in enumerate(ends):
        line = graph.edge_polyline(edge_of[x])
        step = graph.vertices[x] - (line[1] if graph.edges[edge_of[x], 0] == x else line[-2])
        norm = np.hypot(*step)
        if norm > 0:
            headings[k] = step / norm
    return ends, edge_of[ends], headings


def attach_ends(
    graph: BoundaryGraph,
    ends: np.ndarray,
    radius: np.ndarray,
    kind: str,
    headings: np.ndarray | None = None,
    max_turn_deg: float = 60.0,
    merge_px: float = 1.0,
    accept: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> BoundaryGraph:
    """``graph`` with each of ``ends`` (vertices with one edge) joined to the nearest point within
    its ``radius`` of an edge in another connected piece (ahead of it when ``headings`` are given;
    a zero heading accepts any direction); ``graph`` itself when no end finds one. Pieces are
    those of ``graph`` before any join. New edges take ``kind`` and the score and patch of the
    end's own edge. ``accept(starts (K, 2), feet (K, 2)) -> (K,) bool``, when given, vets the
    joins (e.g. the boundary map must back them): an end takes its nearest accepted point."""
    ends, radius = np.asarray(ends, np.int64), np.broadcast_to(np.asarray(radius, float), (len(ends),))
    if not len(ends) or graph.n_edges == 0:
        return graph
    lines = [graph.edge_polyline(e) for e in range(graph.n_edges)]
    ends_at, near_edges = STRtree([LineString(line) for line in lines]).query(
        points(graph.vertices[ends]), predicate="dwithin", distance=radius
    )
    near = [near_edges[ends_at == k] for k in range(len(ends))]
    edge_piece, _ = fragment_lengths(graph)
    vertex_piece = np.full(graph.n_vertices, -1)
    vertex_piece[graph.edges[:, 0]], vertex_piece[graph.edges[:, 1]] = edge_piece, edge_piece
    cos_turn = np.cos(np.radians(max_turn_deg)) - 1e-9
    candidates = []  # (end index, distance, edge, segment, foot), nearest first per end
    for k, x in enumerate(ends):
        point, found = graph.vertices[x], []
        heading = None if headings is None or not np.any(headings[k]) else headings[k]
        for e in sorted(near[k].tolist()):
            if edge_piece[e] == vertex_piece[x]:
                continue
            distance, segment, foot = nearest_on_polyline(lines[e], point)
            ahead = heading is None or distance == 0 or np.dot(foot - point, heading) >= cos_turn * distance
            if distance <= radius[k] and ahead:
                found.append((k, distance, e, segment, foot))
        candidates += sorted(found, key=lambda c: c[1])  # stable: the lower edge index wins a tie
    if accept is not None and candidates:
        ok = np.asarray(
            accept(graph.vertices[ends[[c[0] for c in candidates]]], np.array([c[4] for c in candidates])), bool
        )
        candidates = [c for c, good in zip(candidates, ok) if good]
    cuts: dict[int, list[tuple[float, np.ndarray, int]]] = {}  # edge -> (arc position of the foot, foot, end)
    taken: set[int] = set()
    for k, _, e, segment, foot in candidates:
        if k in taken:
            continue
        taken.add(k)
        position = arc_lengths(lines[e])[segment] + float(np.hypot(*(foot - lines[e][segment])))
        cuts.setdefault(e, []).append((position, foot, int(ends[k])))
    if not cuts:
        return graph
    return _with_cuts(graph, lines, cuts, kind, merge_px)


def _with_cuts(
    graph: BoundaryGraph,
    lines: list[np.ndarray],
    cuts: dict[int, list[tuple[float, np.ndarray, int]]],
    kind: str,
    merge_px: float,
) -> BoundaryGraph:
    """The graph with every cut edge split at its feet and each end joined to its foot."""
    vertices, kinds = [p for p in graph.vertices], list(graph.vertex_kinds or ["isolated"] * graph.n_vertices)
    tree = cKDTree(graph.vertices)
    added: dict[tuple[int, int], list[int]] = {}  # new vertices by merge_px cell

    def vertex_at(foot: np.ndarray) -> int:
        """The vertex nearest to ``foot`` closer than ``merge_px``, else a new one there."""
        distance, nearest = tree.query(foot, distance_upper_bound=merge_px)
        best = (distance, int(nearest)) if distance < merge_px else (np.inf, -1)
        cx, cy = int(np.floor(foot[0] / merge_px)), int(np.floor(foot[1] / merge_px))
        for i in (i for dx in (-1, 0, 1) for dy in (-1, 0, 1) for i in added.get((cx + dx, cy + dy), ())):
            d = float(np.hypot(*(vertices[i] - foot)))
            if d < merge_px and d < best[0]:
                best = (d, i)
        if best[1] >= 0:
            return best[1]
        vertices.append(np.asarray(foot, float))
        kinds.append(kind)
        added.setdefault((cx, cy), []).append(len(vertices) - 1)
        return len(vertices) - 1

    scores = graph.edge_scores if graph.edge_scores is not None else np.ones(graph.n_edges)
    edge_kinds = graph.edge_kinds or ["normal"] * graph.n_edges
    patches = graph.edge_patches
    shaped = [graph.edge_polylines is not None and graph.edge_polylines[e] is not None for e in range(graph.n_edges)]
    own_edge = {int(x): e for e, pair in enumerate(graph.edges) for x in pair}
    kept: dict[tuple[int, int], dict] = {}

    def put(u: int, v: int, line: np.ndarray | None, e: int, edge_kind: str) -> None:
        if u == v:
            return
        if line is not None:
            line = np.array(line, float)
            line[0], line[-1] = vertices[u], vertices[v]
        new = {
            "u": u,
            "v": v,
            "line": line,
            "kind": edge_kind,
            "score": float(scores[e]),
            "patch": None if patches is None else patches[e],
        }
        key = (min(u, v), max(u, v))
        if key not in kept or better_edge(new["kind"], new["score"], kept[key]["kind"], kept[key]["score"]):
            kept[key] = new

    for e, (u, v) in enumerate(graph.edges):
        if e not in cuts:
            put(int(u), int(v), lines[e] if shaped[e] else None, e, edge_kinds[e])
            continue
        rest, start = lines[e], int(u)
        for _, foot, x in sorted(cuts[e], key=lambda hit: hit[0]):
            cut = vertex_at(foot)
            if cut != start:
                head, rest = split_polyline(rest, nearest_on_polyline(rest, foot)[1], foot)
                put(start, cut, head if shaped[e] else None, e, edge_kinds[e])
            start = cut
            put(x, cut, None, own_edge[x], kind)
        put(start, int(v), rest if shaped[e] else None, e, edge_kinds[e])
    edges = list(kept.values())
    return BoundaryGraph(
        np.array(vertices, float).reshape(-1, 2),
        np.array([[d["u"], d["v"]] for d in edges], np.int64).reshape(-1, 2),
        vertex_kinds=kinds,
        edge_kinds=[d["kind"] for d in edges],
        edge_polylines=[d["line"] for d in edges],
        edge_scores=np.array([d["score"] for d in edges], float),
        edge_patches=None if patches is None else np.array([d["patch"] for d in edges], np.int64).reshape(-1, 2),
        transform=graph.transform,
        crs=graph.crs,
    )
