"""Dangling ends joined across short gaps the boundary map supports.

A road boundary is a long line, but a predicted patch graph often stops and restarts along it:
a vertex the keypoint map missed, an AfANet pair below its threshold, a stretch under a tree.
Each such break costs the graph's connectivity (APLS counts every route through it as lost)
for a few pixels of missing line. Here the ends of the graph (vertices with fewer than two
edges) are joined to each other when the join is short, continues the direction each end was
heading in, and runs over boundary (the same mean-support and longest-gap tests as AfANet's
edges, :mod:`csboundary.graph.edge_support`). Closest pairs first, until a vertex has two
edges (a vertex without edges may join two ends and link them). An end still dangling then
may join the nearest point of another piece's line ahead of it (``attach_px``; the line is
split there, :func:`~csboundary.graph.end_attachment.attach_ends`) when the map backs that join
the same way: the city graph's unvetted attachment must stay short (it bridges curbs the model
never saw), while a backed one can reach across a longer gap under a tree.

Pure geometry on pixel (col, row) coordinates; the new edges are of kind ``join`` and ``attach``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.edge_support import segment_stats, widened
from csboundary.graph.end_attachment import ATTACH, attach_ends, dangling_ends

JOIN = "join"


@dataclass(frozen=True)
class EndJoinConfig:
    max_px: float = 0.0  # longest join; 0 = off
    attach_px: float = (
        0.0  # an end left dangling joins the nearest backed point of another piece's line this close; 0 = off
    )
    max_turn_deg: float = 45.0  # largest angle between an end's heading and its join
    min_support: float = 0.3  # mean boundary probability along the join (map max-filtered over radius_px)
    max_gap_px: float = 10.0  # longest stretch of the join below gap_level
    gap_level: float = 0.3
    radius_px: int = 2

    @property
    def active(self) -> bool:
        return self.max_px > 0 or self.attach_px > 0

    def __post_init__(self) -> None:
        if not (
            self.max_px >= 0
            and self.attach_px >= 0
            and 0 <= self.max_turn_deg <= 180
            and 0 <= self.min_support <= 1
            and self.max_gap_px >= 0
            and 0 <= self.gap_level <= 1
            and self.radius_px >= 0
        ):
            raise ValueError(
                f"need max_px, attach_px, max_gap_px, radius_px >= 0, 0 <= max_turn_deg <= 180 and levels in [0, 1]; got "
                f"{self}"
            )


def end_headings(graph: BoundaryGraph) -> tuple[np.ndarray, np.ndarray]:
    """(ends (K,), headings (K, 2)): the vertices with fewer than two edges and the unit direction
    each one's line was heading in when it stopped (:func:`~csboundary.graph.end_attachment.dangling_ends`);
    (0, 0) for a vertex without edges, which may be joined from any side."""
    degree = np.bincount(graph.edges.ravel(), minlength=graph.n_vertices)
    ends = np.flatnonzero(degree < 2)
    heading = np.zeros((len(ends), 2))
    dangling, _, directions = dangling_ends(graph)
    heading[np.searchsorted(ends, dangling)] = directions
    return ends, heading


def join_candidates(graph: BoundaryGraph, config: EndJoinConfig) -> np.ndarray:
    """(K, 2) pairs of ends (closest first) within ``max_px`` of each other, not already joined by
    an edge, each within ``max_turn_deg`` of the heading of every end that has one."""
    ends, heading = end_headings(graph)
    if len(ends) < 2:
        return np.zeros((0, 2), np.int64)
    points = graph.vertices[ends]
    pairs = np.array(sorted(cKDTree(points).query_pairs(config.max_px)), np.int64).reshape(-1, 2)
    if not len(pairs):
        return pairs
    a, b = pairs[:, 0], pairs[:, 1]
    step = points[b] - points[a]
    length = np.linalg.norm(step, axis=1)
    direction = step / np.maximum(length, 1e-9)[:, None]
    cos_turn = np.cos(np.radians(config.max_turn_deg)) - 1e-9  # a turn of exactly the limit passes
    ok = length > 0
    has_a, has_b = np.any(heading[a] != 0, axis=1), np.any(heading[b] != 0, axis=1)
    ok &= ~has_a | (np.sum(heading[a] * direction, axis=1) >= cos_turn)
    ok &= ~has_b | (np.sum(heading[b] * -direction, axis=1) >= cos_turn)
    existing = {tuple(sorted(map(int, e))) for e in graph.edges}
    joined = np.array(
        [
            (int(ends[i]), int(ends[j])) not in existing and (int(ends[j]), int(ends[i])) not in existing
            for i, j in pairs
        ]
    )
    ok &= joined
    order = np.argsort(length[ok], kind="stable")
    return np.stack([ends[a[ok]], ends[b[ok]]], axis=1)[order]


def join_ends(graph: BoundaryGraph, boundary: np.ndarray, config: EndJoinConfig) -> BoundaryGraph:
    """``graph`` plus ``join`` edges between its ends, then (``attach_px``) the ends still
    dangling joined to the line ahead (module docstring); ``graph`` itself when nothing is
    joined. ``boundary`` is the (h, w) boundary probability map of the graph's frame."""
    if not config.active or graph.n_vertices < 2:
        return graph
    support = widened(boundary, config.radius_px)
    if config.max_px > 0:
        graph = _joined(graph, support, config)
    if config.attach_px <= 0:
        return graph
    ends, _, headings = dangling_ends(graph)
    return attach_ends(
        graph,
        ends,
        config.attach_px,
        ATTACH,
        headings,
        config.max_turn_deg,
        accept=lambda starts, stops: backing(support, starts, stops, config)[0],
    )


def backing(
    support: np.ndarray, starts: np.ndarray, stops: np.ndarray, config: EndJoinConfig
) -> tuple[np.ndarray, np.ndarray]:
    """(backed (K,) bool, mean support (K,)) of the segments ``starts`` -> ``stops``: backed when the
    mean reaches ``min_support`` and no stretch below ``gap_level`` is longer than ``max_gap_px``."""
    mean, gap = segment_stats(support, starts, stops, config.gap_level)
    return (mean >= config.min_support) & (gap <= config.max_gap_px), mean


def _joined(graph: BoundaryGraph, support: np.ndarray, config: EndJoinConfig) -> BoundaryGraph:
    """``graph`` plus the ``join`` edges between pairs of its ends that ``support`` backs."""
    pairs = join_candidates(graph, config)
    if not len(pairs):
        return graph
    starts, stops = graph.vertices[pairs[:, 0]], graph.vertices[pairs[:, 1]]
    supported, mean = backing(support, starts, stops, config)
    degree = np.bincount(graph.edges.ravel(), minlength=graph.n_vertices)
    chosen, scores = [], []
    for (u, v), score in zip(pairs[supported], mean[supported]):
        if degree[u] < 2 and degree[v] < 2:
            chosen.append((int(u), int(v)))
            scores.append(float(score))
            degree[u] += 1
            degree[v] += 1
    if not chosen:
        return graph
    n_old = graph.n_edges
    return BoundaryGraph(
        graph.vertices,
        np.concatenate([graph.edges, np.array(chosen, np.int64)]),
        vertex_kinds=graph.vertex_kinds,
        edge_kinds=list(graph.edge_kinds or ["normal"] * n_old) + [JOIN] * len(chosen),
        edge_polylines=list(graph.edge_polylines or [None] * n_old) + [None] * len(chosen),
        edge_scores=np.concatenate([graph.edge_scores if graph.edge_scores is not None else np.ones(n_old), scores]),
        edge_patches=None
        if graph.edge_patches is None
        else np.concatenate([graph.edge_patches, np.zeros((len(chosen), 2), np.int64)]),
        transform=graph.transform,
        crs=graph.crs,
    )
