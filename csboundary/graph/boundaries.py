"""Boundaries: what a person checks as one when reviewing a draft.

A boundary is a maximal chain of the graph between junctions and ends
(:func:`~csboundary.graph.chains.merge_chains`), the line a mapper would draw in one go. Its
confidence is the length-weighted mean of its edges' calibrated scores: the expected share of
its length that is true. The review page, the GIS review layers, the prediction's
``road_boundaries`` layer and the simulated review (:mod:`csboundary.metrics.review_time`) all
use this unit, so they agree on what one look is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import merge_chains
from csboundary.graph.polyline import polyline_length


@dataclass(frozen=True, eq=False)
class Boundary:
    """What a reviewer checks as one: a chain's pixel ``polyline``, its ``edges`` and its
    ``confidence`` (NaN when none of its edges has a score)."""

    polyline: np.ndarray
    edges: np.ndarray
    confidence: float

    @property
    def length_px(self) -> float:
        return polyline_length(self.polyline)


def weighted_mean(scores: np.ndarray, lengths: np.ndarray) -> float:
    """Mean of the finite ``scores`` weighted by ``lengths`` (plain mean if they are all 0);
    NaN when no score is known."""
    known = np.isfinite(scores)
    if not known.any():
        return float("nan")
    w = lengths[known]
    return float(np.dot(scores[known], w) / w.sum()) if w.sum() > 0 else float(scores[known].mean())


def graph_boundaries(graph: BoundaryGraph) -> list[Boundary]:
    """The graph's boundaries (its chains, :func:`~csboundary.graph.chains.merge_chains`), each
    with the length-weighted mean of its edges' scores, ignoring missing ones: a long sure edge
    outweighs a short doubtful one, and the mean of calibrated scores is the expected share of
    the boundary's length that is true."""
    scores = np.asarray(graph.edge_scores if graph.edge_scores is not None else np.full(graph.n_edges, np.nan), float)
    lengths = graph.edge_lengths() if graph.n_edges else np.zeros(0)
    return [
        Boundary(chain.polyline, chain.edges, weighted_mean(scores[chain.edges], lengths[chain.edges]))
        for chain in merge_chains(graph)
    ]
