"""The city graph's edge confidence, from the maps a run kept of every patch core.

Once the city graph is stitched, each edge's evidence (:mod:`csboundary.graph.edge_evidence`) is
read from the stitched maps of the patch cores the run stored (uint8, one core at a time, so
memory does not grow with the city), and the bundle's confidence model
(:mod:`csboundary.models.confidence_model`) turns it into the probability that the edge is a true
boundary. That probability becomes the edge's ``score``: graph.json, the GeoPackage's
``confidence``, Lanelet2's attributes and the review page's order all follow it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from csboundary.data.grid import PatchGrid
from csboundary.graph import BoundaryGraph
from csboundary.graph.edge_evidence import Sampler
from csboundary.models.confidence_model import EdgeConfidence


def core_sampler(grid: PatchGrid, load_core, channels: int) -> Sampler:
    """Map values at pixel points of the mosaic (nearest pixel), from ``load_core(index)``:
    the (C, h, w) uint8 maps of a patch core (None: all zero). Points outside the mosaic read
    0, as the maps do where there is no imagery."""
    size = grid.config.core

    def sample(points: np.ndarray) -> np.ndarray:
        col = np.rint(points[:, 0]).astype(np.int64)
        row = np.rint(points[:, 1]).astype(np.int64)
        inside = (col >= 0) & (row >= 0) & (col < grid.width) & (row < grid.height)
        out = np.zeros((len(points), channels))
        key = np.where(inside, (row // size) * (grid.width // size + 2) + col // size, -1)
        for k in np.unique(key[inside]):
            pick = np.flatnonzero(key == k)
            r, c = int(row[pick[0]] // size), int(col[pick[0]] // size)
            core = load_core((r, c))
            if core is not None:
                out[pick] = np.asarray(core)[:channels, row[pick] - r * size, col[pick] - c * size].T / 255.0
        return out

    return sample


def scored_graph(graph: BoundaryGraph, confidence: EdgeConfidence, evidence: np.ndarray) -> BoundaryGraph:
    """``graph`` with every edge's score replaced by its calibrated confidence (from the edges'
    ``evidence``, :func:`~csboundary.graph.edge_evidence.edge_evidence`). The city graph drops
    the edges below ``GraphSettings.min_confidence`` itself, block by block
    (:mod:`csboundary.pipeline.prediction.city_blocks`)."""
    if graph.n_edges == 0:
        return graph
    return dataclasses.replace(graph, edge_scores=confidence.probability(evidence))
