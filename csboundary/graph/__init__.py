"""Road-boundary graphs: the in-memory graph, its JSON format, and (later) stitching."""

from csboundary.graph.boundary_graph import BoundaryGraph

__all__ = ["BoundaryGraph"]
