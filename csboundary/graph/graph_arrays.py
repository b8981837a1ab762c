"""A boundary graph as plain arrays, for ``.npz`` files: exact (float64 coordinates and scores,
kinds as strings) and loadable without pickles, so the run store keeps patch graphs in them."""

from __future__ import annotations

import numpy as np
from affine import Affine

from csboundary.graph.boundary_graph import BoundaryGraph


def graph_arrays(graph: BoundaryGraph) -> dict[str, np.ndarray]:
    """A graph as plain arrays (exact: float64 coordinates and scores; kinds as strings);
    polylines concatenated with per-edge offsets, -1 for an edge without one."""
    arrays = {"vertices": np.asarray(graph.vertices, np.float64), "edges": np.asarray(graph.edges, np.int64)}
    if graph.vertex_kinds is not None:
        arrays["vertex_kinds"] = np.array(graph.vertex_kinds, dtype=str).reshape(-1)
    if graph.edge_kinds is not None:
        arrays["edge_kinds"] = np.array(graph.edge_kinds, dtype=str).reshape(-1)
    if graph.edge_scores is not None:
        arrays["edge_scores"] = np.asarray(graph.edge_scores, np.float64)
    if graph.edge_patches is not None:
        arrays["edge_patches"] = np.asarray(graph.edge_patches, np.int64)
    if graph.edge_polylines is not None:
        starts, points = [], []
        total = 0
        for line in graph.edge_polylines:
            if line is None:
                starts.append((-1, 0))
                continue
            line = np.asarray(line, np.float64).reshape(-1, 2)
            starts.append((total, len(line)))
            points.append(line)
            total += len(line)
        arrays["polyline_spans"] = np.array(starts, np.int64).reshape(-1, 2)
        arrays["polyline_points"] = np.concatenate(points) if points else np.zeros((0, 2))
    if graph.crs is not None:
        arrays["crs"] = np.array(graph.crs)
    if graph.transform is not None:
        arrays["transform"] = np.array(list(graph.transform)[:6], np.float64)
    return arrays


def graph_from_arrays(arrays) -> BoundaryGraph:
    """Inverse of :func:`graph_arrays`."""
    names = set(arrays.keys()) if hasattr(arrays, "keys") else set(arrays.files)
    polylines = None
    if "polyline_spans" in names:
        points = arrays["polyline_points"]
        polylines = [None if start < 0 else points[start : start + n] for start, n in arrays["polyline_spans"]]
    return BoundaryGraph(
        arrays["vertices"],
        arrays["edges"],
        vertex_kinds=arrays["vertex_kinds"].tolist() if "vertex_kinds" in names else None,
        edge_kinds=arrays["edge_kinds"].tolist() if "edge_kinds" in names else None,
        edge_polylines=polylines,
        edge_scores=arrays["edge_scores"] if "edge_scores" in names else None,
        edge_patches=arrays["edge_patches"] if "edge_patches" in names else None,
        transform=Affine(*arrays["transform"]) if "transform" in names else None,
        crs=str(arrays["crs"]) if "crs" in names else None,
    )
