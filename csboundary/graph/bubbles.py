"""Bubbles: two short chains between the same two vertices, one of them dropped.

Where patch graphs are stitched at a seam (and where noding splits lines that run together), a
boundary often comes out as two short parallel routes between the same two vertices: a bubble
a few pixels wide. It adds nothing to the map, but it makes both vertices junctions, so the
boundary through it is cut into three chains, and a reviewer who checks a boundary at a time
(:mod:`csboundary.metrics.review_time`) pays for three looks and a stray route. Of the chains
sharing both ends, all no longer than ``max_px``, the shortest stays (the straighter route); the
others go, and the boundary through them is one chain again.

Pure: a graph in, a graph out (:meth:`BoundaryGraph.edge_subgraph`).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import chains

BUBBLE_PX = 60.0  # 9 m at 0.152 m: the seam bubbles of the synthetic test cities are 5-50 px long


def drop_bubbles(graph: BoundaryGraph, max_px: float = BUBBLE_PX, rounds: int = 3) -> BoundaryGraph:
    """``graph`` without the longer routes of its bubbles (module docstring); repeated up to
    ``rounds`` times, as a bubble inside a bubble shows once the inner one is gone."""
    if max_px <= 0:
        return graph
    for _ in range(rounds):
        if graph.n_edges == 0:
            return graph
        found = chains(graph.n_vertices, graph.edges)
        lengths = graph.edge_lengths()
        groups: dict[tuple[int, int], list[tuple[float, int]]] = defaultdict(list)
        for c, (verts, path) in enumerate(zip(found.vertices, found.edges)):
            if verts[0] != verts[-1]:
                groups[(min(verts[0], verts[-1]), max(verts[0], verts[-1]))].append((float(lengths[path].sum()), c))
        keep = np.ones(graph.n_edges, bool)
        for routes in groups.values():
            if len(routes) < 2:
                continue
            short = sorted(r for r in routes if r[0] <= max_px)
            if len(short) < 2:
                continue
            for _, c in short[1:]:
                keep[found.edges[c]] = False
        if keep.all():
            return graph
        graph = graph.edge_subgraph(keep)
    return graph
