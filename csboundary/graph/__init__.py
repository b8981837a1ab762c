"""Road-boundary graphs: the in-memory graph and its JSON format (``BoundaryGraph``), the settings
from a patch's maps to the city graph (``settings``), and the steps between: vertex extraction,
edge checks, filling, joining, stitching, noding and streaming."""

from csboundary.graph.boundary_graph import BoundaryGraph

__all__ = ["BoundaryGraph"]
