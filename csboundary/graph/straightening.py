"""Boundaries drawn as a mapper draws them: detours off a straight curb flattened.

Along a row of parked cars or under a tree, the predicted boundary bulges round each car and
wiggles a pixel or two either side of the curb, where a mapper draws one straight run. Each
bulge is a detour off a straight line that runs on before and after it. Every point of a chain
(the points of its edges' polylines and its degree-2 vertices; the chain's own ends stay) whose
context is straight is moved onto the chord through the line ``half_px`` before and after it:
the context is straight when the line ``half_px`` to ``2 half_px`` before and after the point
heads along that chord (within ``max_turn_deg``) and lies within ``line_px`` of it. A corner, a
curve tighter than a few hundred pixels of radius, or a line that really turns away fails the
test and keeps its shape, as does a detour deeper than ``max_shift_px``. The edges' polylines
are then simplified (Douglas-Peucker, ``simplify_px``), so vertices remain where the direction
changes.

Moved vertices are rounded to 1/1024 px: the city graph is made block by block and a vertex two
blocks share must come out of both at exactly the same point. Pure geometry on pixel
coordinates; the graph keeps its vertices and edges, only their positions change.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import shapely

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import edge_line, merge_chains
from csboundary.graph.polyline import arc_lengths

GRID = 1024.0  # moved vertices land on multiples of 1/GRID px


@dataclass(frozen=True)
class StraightenConfig:
    # chosen on the 16-patch seed-7 city, the NYC patch and the Ottawa crops together (docs/experiments.md)
    half_px: float = 30.0  # 4.6 m at 0.152 m: about a parked car's length
    max_turn_deg: float = 30.0
    line_px: float = 6.0
    max_shift_px: float = 30.0
    simplify_px: float = 0.5
    rounds: int = 2


def straightened_line(line: np.ndarray, config: StraightenConfig = StraightenConfig()) -> np.ndarray:
    """``line`` (n, 2) with every point whose context is straight moved onto its chord (module
    docstring); its two ends stay. Same shape as ``line``."""
    line = np.asarray(line, float).reshape(-1, 2).copy()
    h = config.half_px
    for _ in range(config.rounds):
        if len(line) < 3:
            return line
        cum = arc_lengths(line)
        if cum[-1] < 4 * h:
            return line
        s = cum[1:-1]
        ok = (s - 2 * h >= 0) & (s + 2 * h <= cum[-1])

        def at(t, cum=cum, line=line):
            return np.stack([np.interp(t, cum, line[:, 0]), np.interp(t, cum, line[:, 1])], axis=1)

        a2, a, b, b2 = at(s - 2 * h), at(s - h), at(s + h), at(s + 2 * h)
        chord = b - a
        norm = np.linalg.norm(chord, axis=1)
        ok &= norm > h
        u = chord / np.maximum(norm, 1e-12)[:, None]
        normal = np.stack([-u[:, 1], u[:, 0]], axis=1)
        cos_turn = np.cos(np.radians(config.max_turn_deg))
        for before, after in ((a2, a), (b, b2)):
            d = after - before
            ok &= (d * u).sum(axis=1) >= cos_turn * np.maximum(np.linalg.norm(d, axis=1), 1e-12)
        ok &= np.abs(((a2 - a) * normal).sum(axis=1)) <= config.line_px
        ok &= np.abs(((b2 - a) * normal).sum(axis=1)) <= config.line_px
        p = line[1:-1]
        shift = ((p - a) * normal).sum(axis=1)
        ok &= np.abs(shift) <= config.max_shift_px
        if not ok.any():
            return line
        line[1:-1][ok] = p[ok] - shift[ok, None] * normal[ok]
    return line


def straighten(graph: BoundaryGraph, config: StraightenConfig | None = StraightenConfig()) -> BoundaryGraph:
    """``graph`` with every chain straightened (:func:`straightened_line`) and its edges'
    polylines simplified; ``None`` leaves the graph as it is."""
    if config is None or graph.n_edges == 0:
        return graph
    vertices = graph.vertices.copy()
    polylines = [None] * graph.n_edges
    for chain in merge_chains(graph):
        # where each edge's piece starts in the chain's points (consecutive pieces share a point)
        sizes = np.array([len(edge_line(graph, k)) for k in chain.edges.tolist()])
        starts = np.concatenate([[0], np.cumsum(sizes - 1)])
        line = straightened_line(chain.polyline, config)
        for j, k in enumerate(chain.edges.tolist()):
            piece = line[starts[j] : starts[j + 1] + 1]
            if chain.reversed[j]:
                piece = piece[::-1]
            polylines[k] = piece
        for j, v in enumerate(chain.vertices[1:-1].tolist(), start=1):
            vertices[v] = np.round(line[starts[j]] * GRID) / GRID
    out = []
    for k, piece in enumerate(polylines):
        if piece is None:
            out.append(graph.edge_polylines[k] if graph.edge_polylines is not None else None)
            continue
        u, v = graph.edges[k]
        piece = piece.copy()
        piece[0], piece[-1] = vertices[u], vertices[v]
        if len(piece) > 2 and config.simplify_px > 0:
            piece = shapely.get_coordinates(
                shapely.simplify(shapely.LineString(piece), config.simplify_px, preserve_topology=False)
            )
        out.append(piece)
    return dataclasses.replace(graph, vertices=vertices, edge_polylines=out)
