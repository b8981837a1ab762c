"""Graphs as the metrics see them: straight segments, chains resampled at a fixed spacing, and
seeded vertex pairs.

Every metric starts from :class:`Segments`, the graph flattened so that each polyline point is a
vertex and each edge a straight segment: topology comes from the graph's edges only, never from
coincident coordinates. Topology metrics then work on a :class:`SampledGraph`: the graph's
*chains* (maximal paths through vertices of degree 2, and closed loops) resampled so that the
vertex density no longer depends on how the input was digitised. A chain of arc length ``L`` is
cut into ``n = ceil(L / spacing)`` equal pieces (so every piece is at most ``spacing`` long and the
result does not depend on the chain's direction); the chain's end vertices (degree != 2) are kept.
Edge weights are the exact arc lengths along the original geometry, not the chords.

Shortest paths never run over the sampled vertices themselves: a chain is a single edge between
its two end vertices ("keys"), and a point on a chain reaches the rest of the graph through those
two keys (:class:`Locations`). Keys and sampled vertices are numbered component by component, so
the key graph's matrix is block diagonal and Dijkstra runs on small slices of it.

Each step has its own module: :mod:`.segments` (the flattened graph, its origin and clipping),
:mod:`.sampled_graph` (resampling and locations), :mod:`.pairs` (seeded vertex pairs) and
:mod:`.limits` (the size guard). This module gathers their names under one import.
"""

from csboundary.metrics.limits import MAX_SAMPLES, RasterTooLarge
from csboundary.metrics.pairs import boundary_pairs, component_pairs
from csboundary.metrics.sampled_graph import Locations, SampledGraph, resample
from csboundary.metrics.segments import Segments, clip, common_origin, flatten

__all__ = [
    "MAX_SAMPLES",
    "Locations",
    "RasterTooLarge",
    "SampledGraph",
    "Segments",
    "boundary_pairs",
    "clip",
    "common_origin",
    "component_pairs",
    "flatten",
    "resample",
]
