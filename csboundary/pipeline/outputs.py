"""The georeferenced products of a city prediction, for GIS users and for re-evaluation.

``{stem}.gpkg`` holds two layers: ``road_boundaries`` (one LineString per boundary, i.e. per merged
chain of the graph, which is what a user means by "a boundary") and ``edges`` (the graph's edges
as predicted, to trace a boundary back to its edges, scores and source patches).
``{stem}.geojson`` repeats ``road_boundaries`` for tools without GeoPackage support, and
``graph.json`` keeps the graph itself (pixel and world coordinates) for the metrics.

Geometry is in the world coordinates of ``graph.crs`` (no reprojection, so the GeoJSON is in the
same CRS as the GeoPackage, not RFC 7946's WGS 84); ``length_m`` is true metres in every CRS
(:mod:`csboundary.data.units`: geodesic for degrees, the unit's size for feet). The boundaries layer is the ground-truth layer name, so
:func:`csboundary.data.ground_truth.read_ground_truth` reads the output back directly.
"""

from __future__ import annotations

import warnings
from contextlib import ExitStack
from pathlib import Path

import geopandas as gpd
import numpy as np
import pyogrio
from shapely.geometry import LineString

from csboundary.data.atomic import atomic_path
from csboundary.data.ground_truth import LAYER as BOUNDARIES_LAYER
from csboundary.data.units import GroundUnits, ground_units
from csboundary.data.windows import pixel_to_world
from csboundary.errors import InputError
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.graph.chains import edge_line, merge_chains

EDGES_LAYER = "edges"


def write_graph_outputs(graph: BoundaryGraph, out_dir: str | Path, stem: str = "boundaries", units: GroundUnits | None = None) -> dict[str, Path]:
    """Write ``{stem}.gpkg``, ``{stem}.geojson`` and ``graph.json`` into ``out_dir``.

    All three are written to temporary names first and renamed only once all of them are
    complete, so an interrupted run leaves either the previous files or none, never a partial
    one. Returns the paths under the keys ``gpkg``, ``geojson`` and ``graph_json``.
    """
    boundaries, edges = graph_frames(graph, units)
    out_dir = Path(out_dir)
    paths = {"gpkg": out_dir / f"{stem}.gpkg", "geojson": out_dir / f"{stem}.geojson", "graph_json": out_dir / "graph.json"}
    with ExitStack() as stack:
        tmp = {key: stack.enter_context(atomic_path(path)) for key, path in paths.items()}
        _write_layer(boundaries, tmp["gpkg"], BOUNDARIES_LAYER, "GPKG")
        _write_layer(edges, tmp["gpkg"], EDGES_LAYER, "GPKG")
        _write_layer(boundaries, tmp["geojson"], stem, "GeoJSON")  # the layer name is in the file: never the temporary's
        graph.write_json(tmp["graph_json"])
    return paths


def check_finite_geometry(graph: BoundaryGraph, source) -> None:
    """InputError naming ``source`` when a vertex or polyline point is not a finite number: a
    NaN would become a null geometry in the files written from the graph."""
    bad = not np.isfinite(graph.vertices).all()
    if not bad and graph.edge_polylines is not None:
        bad = any(line is not None and not np.isfinite(np.asarray(line, float)).all() for line in graph.edge_polylines)
    if bad:
        raise InputError(source, "the graph has a vertex or edge point that is not a finite number")


def graph_frames(graph: BoundaryGraph, units: GroundUnits | None = None) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame]:
    """The ``road_boundaries`` and ``edges`` tables of ``graph`` in world coordinates; lengths in
    metres through ``units`` (default: those of ``graph.crs``, or the CRS's units without one).

    Boundary confidence is the length-weighted mean of its edges' scores (a long confident edge
    should outweigh a short doubtful one), ignoring missing (NaN) scores; NaN if none is known.
    """
    if graph.transform is None:
        raise ValueError("graph has no transform: world coordinates are unknown")

    def world(line: np.ndarray) -> np.ndarray:
        return np.stack(pixel_to_world(graph.transform, line[:, 0], line[:, 1]), axis=1)

    if units is None:
        units = ground_units(graph.crs, _centre(graph)) or GroundUnits((1.0, 1.0), "unknown")
    n = graph.n_edges
    edge_lines = [world(edge_line(graph, k)) for k in range(n)]
    length = np.array([units.line_length_m(line) for line in edge_lines], dtype=float)
    score = np.full(n, np.nan) if graph.edge_scores is None else np.asarray(graph.edge_scores, dtype=float).reshape(n)
    kinds = np.array(graph.edge_kinds if graph.edge_kinds is not None else ["normal"] * n, dtype=object).reshape(n)
    corner = kinds == "corner"
    filled = kinds == "skeleton"  # added from the segmentation skeleton (graph/skeleton_fill.py)
    patch = np.full((n, 2), -1, dtype=np.int64) if graph.edge_patches is None else graph.edge_patches
    patch = np.where((patch >= 0).all(axis=1, keepdims=True), patch, -1)
    boundary_of_edge = np.full(n, -1, dtype=np.int64)

    rows: dict[str, list] = {key: [] for key in ("length_m", "n_edges", "confidence_mean", "confidence_min", "corner_edges", "skeleton_edges", "patches")}
    geometry = []
    for c, chain in enumerate(merge_chains(graph)):
        k = chain.edges
        boundary_of_edge[k] = c
        line = world(chain.polyline)
        known = np.isfinite(score[k])
        distinct = dict.fromkeys(map(tuple, patch[k][patch[k, 0] >= 0].tolist()))
        geometry.append(LineString(line))
        rows["length_m"].append(units.line_length_m(line))
        rows["n_edges"].append(len(k))
        rows["confidence_mean"].append(_weighted_mean(score[k][known], length[k][known]))
        rows["confidence_min"].append(float(score[k][known].min()) if known.any() else np.nan)
        rows["corner_edges"].append(int(corner[k].sum()))
        rows["skeleton_edges"].append(int(filled[k].sum()))
        rows["patches"].append(";".join(f"{r},{col}" for r, col in distinct))

    boundaries = gpd.GeoDataFrame(
        {
            "boundary_id": np.arange(len(geometry), dtype=np.int64),
            "length_m": np.array(rows["length_m"], dtype=float),
            "n_edges": np.array(rows["n_edges"], dtype=np.int64),
            "confidence_mean": np.array(rows["confidence_mean"], dtype=float),
            "confidence_min": np.array(rows["confidence_min"], dtype=float),
            "corner_edges": np.array(rows["corner_edges"], dtype=np.int64),
            "skeleton_edges": np.array(rows["skeleton_edges"], dtype=np.int64),
            "patches": np.array(rows["patches"], dtype=object),
        },
        geometry=gpd.GeoSeries(geometry, crs=graph.crs),
        crs=graph.crs,
    )
    edges = gpd.GeoDataFrame(
        {
            "edge_id": np.arange(n, dtype=np.int64),
            "boundary_id": boundary_of_edge,
            "u": graph.edges[:, 0].copy(),
            "v": graph.edges[:, 1].copy(),
            "confidence": score,
            "corner": corner,
            "kind": kinds.astype(str),
            "patch_row": patch[:, 0].copy(),
            "patch_col": patch[:, 1].copy(),
            "length_m": length,
        },
        geometry=gpd.GeoSeries([LineString(line) for line in edge_lines], crs=graph.crs),
        crs=graph.crs,
    )
    return boundaries, edges


def _write_layer(frame: gpd.GeoDataFrame, path: Path, layer: str | None, driver: str) -> None:
    """One layer into ``path`` (a GeoPackage gains a layer per call); the geometry type is given
    so that an empty layer still declares LineString."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="'crs' was not provided")  # a graph without CRS
        pyogrio.write_dataframe(frame, path, layer=layer, driver=driver, geometry_type="LineString")


def _centre(graph: BoundaryGraph) -> tuple[float, float] | None:
    if graph.n_vertices == 0 or graph.transform is None:
        return None
    xs, ys = pixel_to_world(graph.transform, graph.vertices[:, 0], graph.vertices[:, 1])
    return float(np.mean(xs)), float(np.mean(ys))


def _weighted_mean(values: np.ndarray, weights: np.ndarray) -> float:
    """Weighted mean; the plain mean when all weights are zero; NaN when there are no values."""
    if len(values) == 0:
        return float("nan")
    return float(np.average(values, weights=weights)) if weights.sum() > 0 else float(values.mean())
