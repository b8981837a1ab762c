"""The georeferenced products of a city prediction, for GIS users and for re-evaluation.

``{stem}.gpkg`` holds two layers: ``road_boundaries`` (one LineString per boundary, i.e. per merged
chain of the graph, which is what a user means by "a boundary") and ``edges`` (the graph's edges
as predicted, to trace a boundary back to its edges, scores and source patches).
``{stem}.geojson`` repeats ``road_boundaries`` for tools without GeoPackage support, and
``graph.json`` keeps the graph itself (pixel and world coordinates) for the metrics.

Geometry is in the world coordinates of ``graph.crs`` (no reprojection, so the GeoJSON is in the
same CRS as the GeoPackage, not RFC 7946's WGS 84); ``length_m`` is true metres in every CRS
(:mod:`csboundary.data.units`: geodesic for degrees, the unit's size for feet). The boundaries layer
is the ground-truth layer name, so
:func:`csboundary.data.ground_truth.read_ground_truth` reads the output back directly.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import warnings
from contextlib import ExitStack, suppress
from pathlib import Path

import geopandas as gpd
import numpy as np
import pyogrio
from shapely.geometry import LineString

from csboundary.data.atomic import atomic_path, naming_full_disk
from csboundary.data.ground_truth import LAYER as BOUNDARIES_LAYER
from csboundary.data.units import GroundUnits, geometric_mean, ground_units, pixel_size_m
from csboundary.data.windows import pixel_to_world
from csboundary.errors import InputError
from csboundary.graph.boundaries import weighted_mean
from csboundary.graph.boundary_graph import BoundaryGraph, edge_item, json_header, vertex_items
from csboundary.graph.graph_stream import GraphStream, StreamBoundary, StreamPiece
from csboundary.metrics.review_time import ReviewCosts, keeps_boundary

EDGES_LAYER = "edges"
TRANSFORM_KEY = "csboundary_transform"  # the graph's pixel -> world transform, in the edges layer's metadata


def write_graph_outputs(
    graph: BoundaryGraph, out_dir: str | Path, stem: str = "boundaries", units: GroundUnits | None = None
) -> dict[str, Path]:
    """Write ``{stem}.gpkg``, ``{stem}.geojson`` and ``graph.json`` of a whole graph into ``out_dir``.

    The graph goes through :class:`GraphWriter` as one piece (its vertices keep their order;
    two at exactly the same point become one). All three are written to temporary names first
    and renamed only once all of them are complete, so an interrupted run leaves either the
    previous files or none, never a partial one. Returns the paths under the keys ``gpkg``,
    ``geojson`` and ``graph_json``.
    """
    if graph.transform is None:
        raise ValueError("graph has no transform: world coordinates are unknown")
    out_dir = Path(out_dir)
    paths = {
        "gpkg": out_dir / f"{stem}.gpkg",
        "geojson": out_dir / f"{stem}.geojson",
        "graph_json": out_dir / "graph.json",
    }
    with ExitStack() as stack:
        tmp = {key: stack.enter_context(atomic_path(path)) for key, path in paths.items()}
        writer = GraphWriter(tmp, graph.crs, graph.transform, units or graph_units(graph), stem, shown=paths)
        stack.callback(writer.abort)
        stream = GraphStream()
        writer.add(stream.add(graph), [])
        writer.add(None, stream.finish())
        writer.close()
    return paths


def metres_per_px(units: GroundUnits, transform, costs: ReviewCosts) -> float:
    """Ground size of a pixel of ``transform`` in ``units``, the size the review costs assume
    where the units do not say it (no CRS, no stated pixel size)."""
    known = units.unit_name != "unknown" and not (units.unit_name == "pixel" and units.metres_per_unit == (1.0, 1.0))
    return geometric_mean(pixel_size_m(units, transform)) if known else costs.assumed_metres_per_px


def graph_units(graph: BoundaryGraph) -> GroundUnits:
    """Ground units of a graph's CRS around its middle (the CRS's own units without one)."""
    return ground_units(graph.crs, _centre(graph)) or GroundUnits((1.0, 1.0), "unknown")


class GraphWriter:
    """The GeoPackage (``road_boundaries`` and ``edges``), the GeoJSON and graph.json of a graph
    that arrives in pieces (:class:`~csboundary.graph.graph_stream.GraphStream`): each piece's
    vertices and edges go into graph.json as they come (the edges through a file beside it, as
    the vertices come first), each complete boundary and its edges are appended to the
    GeoPackage and the GeoJSON. Memory holds one piece. ``paths``: ``gpkg``, ``geojson``,
    ``graph_json``; ``shown``: their names in messages (a full disk names the file it could not
    write, by its final name rather than a temporary one; default ``paths``)."""

    def __init__(
        self,
        paths: dict[str, Path],
        crs: str | None,
        transform,
        units: GroundUnits,
        stem: str = "boundaries",
        shown: dict[str, Path] | None = None,
    ):
        if transform is None:
            raise ValueError("graph has no transform: world coordinates are unknown")
        self.paths, self.crs, self.transform, self.units, self.stem = paths, crs, transform, units, stem
        self.shown = shown or paths
        self.boundaries = 0
        self.counts = {"vertices": 0, "edges": 0, "kinds": {}, "boundary_m": 0.0}
        self._layers_started = False
        with ExitStack() as opened:  # a file that fails to open closes the ones opened before it
            with self._writing("geojson"):
                self._geojson = opened.enter_context(_GeoJSONWriter(paths["geojson"], stem, crs))
            with self._writing("graph_json"):
                self._json = opened.enter_context(open(paths["graph_json"], "w"))
                # gone however the run ends
                self._edges_part = opened.enter_context(tempfile.TemporaryFile("w+", dir=paths["graph_json"].parent))
                header = json.dumps({**json_header(crs, transform), "vertices": []})
                self._json.write(header[:-2])  # up to the open vertex list
            opened.pop_all()
        self._scored: bool | None = None
        self._first_vertex = self._first_edge = True

    def _writing(self, key: str):
        return naming_full_disk(self.shown[key])

    def add(self, piece: StreamPiece | None, boundaries: list[StreamBoundary]) -> None:
        if piece is not None:
            with self._writing("graph_json"):
                self._add_piece(piece)
        if boundaries:
            frames = boundary_frames(boundaries, self.boundaries, self.crs, self.transform, self.units)
            self.boundaries += len(boundaries)
            self._append(*frames)

    def close(self) -> dict:
        """Finish the files; returns the counts (edges, by kind, boundary metres, boundaries)."""
        if not self._layers_started:  # no boundary at all: the layers still exist, empty
            self._append(*boundary_frames([], 0, self.crs, self.transform, self.units))
        with self._writing("graph_json"):
            self._edges_part.seek(0)
            self._json.write('], "edges": [')
            shutil.copyfileobj(self._edges_part, self._json)
            self._json.write("]}")
            self._json.close()  # the buffer's last bytes reach the disk here: a full disk shows now
        with self._writing("geojson"):
            self._geojson.finish()
            self._geojson.close()
        self.abort()
        self.counts["boundaries"] = self.boundaries
        return self.counts

    def abort(self) -> None:
        """Close the files (the caller removes the unfinished ones); a buffer that cannot be
        written out on a full disk is dropped with them, the run's error already says why."""
        for file in (self._geojson, self._json, self._edges_part):
            with suppress(OSError):
                file.close()

    def _add_piece(self, piece: StreamPiece) -> None:
        world = (
            np.stack(pixel_to_world(self.transform, piece.vertices[:, 0], piece.vertices[:, 1]), axis=1)
            if len(piece.vertices)
            else None
        )
        self.counts["vertices"] += len(piece.vertices)
        for item in vertex_items(piece.vertices, world, piece.vertex_kinds):
            self._json.write(("" if self._first_vertex else ", ") + json.dumps(item))
            self._first_vertex = False
        if self._scored is None and piece.edges:
            self._scored = piece.edges[0].score is not None
        for e in piece.edges:
            item = edge_item(e.u, e.v, e.kind, e.polyline, e.score, bool(self._scored), e.patch)
            self._edges_part.write(("" if self._first_edge else ", ") + json.dumps(item))
            self._first_edge = False
            self.counts["edges"] += 1
            kind = e.kind or "normal"
            self.counts["kinds"][kind] = self.counts["kinds"].get(kind, 0) + 1

    def _append(self, boundaries: gpd.GeoDataFrame, edges: gpd.GeoDataFrame) -> None:
        self.counts["boundary_m"] += float(edges["length_m"].sum())
        append = self._layers_started
        with self._writing("gpkg"):
            _write_layer(boundaries, self.paths["gpkg"], BOUNDARIES_LAYER, "GPKG", append)
            _write_layer(
                edges,
                self.paths["gpkg"],
                EDGES_LAYER,
                "GPKG",
                append,
                None if append else {TRANSFORM_KEY: ",".join(repr(float(x)) for x in list(self.transform)[:6])},
            )
        with self._writing("geojson"):
            self._geojson.add(boundaries)
        self._layers_started = True


class _GeoJSONWriter:
    """A FeatureCollection written feature by feature (GDAL's GeoJSON driver rewrites the file
    to append to it, which grows with the file): named ``name`` (never the temporary file's),
    with the OGC URN of an EPSG CRS as GDAL writes it; NaN properties are null."""

    def __init__(self, path: Path, name: str, crs: str | None):
        self._file = open(path, "w")
        header = {"type": "FeatureCollection", "name": name}
        code = _epsg(crs)
        if code is not None:
            header["crs"] = {"type": "name", "properties": {"name": f"urn:ogc:def:crs:EPSG::{code}"}}
        self._file.write(json.dumps(header)[:-1] + ', "features": [\n')
        self._first = True

    def add(self, frame: gpd.GeoDataFrame) -> None:
        columns = [c for c in frame.columns if c != frame.geometry.name]
        for values, geometry in zip(frame[columns].itertuples(index=False, name=None), frame.geometry):
            properties = {c: _json_value(v) for c, v in zip(columns, values)}
            feature = {
                "type": "Feature",
                "properties": properties,
                "geometry": {"type": "LineString", "coordinates": np.asarray(geometry.coords)[:, :2].tolist()},
            }
            self._file.write(("" if self._first else ",\n") + json.dumps(feature))
            self._first = False

    def finish(self) -> None:
        self._file.write("\n]}\n")

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> "_GeoJSONWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _json_value(value):
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


def _epsg(crs: str | None) -> int | None:
    if crs is None:
        return None
    from pyproj import CRS

    try:
        return CRS.from_user_input(crs).to_epsg()
    except Exception:  # pyproj raises its own types for a CRS it cannot read
        return None


def check_finite_geometry(graph: BoundaryGraph, source) -> None:
    """InputError naming ``source`` when a vertex or polyline point is not a finite number: a
    NaN would become a null geometry in the files written from the graph."""
    bad = not np.isfinite(graph.vertices).all()
    if not bad and graph.edge_polylines is not None:
        bad = any(line is not None and not np.isfinite(np.asarray(line, float)).all() for line in graph.edge_polylines)
    if bad:
        raise InputError(source, "the graph has a vertex or edge point that is not a finite number")


def graph_frames(graph: BoundaryGraph, units: GroundUnits | None = None) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame]:
    """The ``road_boundaries`` and ``edges`` tables of a whole graph, as :class:`GraphWriter`
    writes them."""
    if graph.transform is None:
        raise ValueError("graph has no transform: world coordinates are unknown")
    stream = GraphStream()
    stream.add(graph)
    return boundary_frames(stream.finish(), 0, graph.crs, graph.transform, units or graph_units(graph))


def boundary_frames(
    boundaries: list[StreamBoundary], first_id: int, crs: str | None, transform, units: GroundUnits
) -> tuple[gpd.GeoDataFrame, gpd.GeoDataFrame]:
    """The ``road_boundaries`` rows of complete boundaries (numbered from ``first_id``) and the
    ``edges`` rows of their edges (by edge number), in world coordinates; lengths in metres.

    Boundary confidence is the length-weighted mean of its edges' scores (a long confident edge
    should outweigh a short doubtful one), ignoring missing (NaN) scores; NaN if none is known.
    ``review_draft`` says whether the boundary is in the review draft: whether its expected
    saving pays for a look (:func:`csboundary.metrics.review_time.keeps_boundary`).
    """

    def world(line: np.ndarray) -> np.ndarray:
        return np.stack(pixel_to_world(transform, line[:, 0], line[:, 1]), axis=1)

    rows: dict[str, list] = {
        key: []
        for key in (
            "length_m",
            "n_edges",
            "confidence_mean",
            "confidence_min",
            "review_draft",
            "corner_edges",
            "skeleton_edges",
            "patches",
        )
    }
    costs = ReviewCosts()
    pixel_m = metres_per_px(units, transform, costs)
    geometry, edge_rows = [], []
    for c, boundary in enumerate(boundaries, start=first_id):
        lines = [world(e.line) for e in boundary.edges]
        length = np.array([units.line_length_m(line) for line in lines], dtype=float)
        score = np.array([np.nan if e.score is None else e.score for e in boundary.edges], dtype=float)
        kinds = [e.kind or "normal" for e in boundary.edges]
        known = np.isfinite(score)
        line = world(boundary.polyline)
        geometry.append(LineString(line))
        rows["length_m"].append(units.line_length_m(line))
        rows["n_edges"].append(len(boundary.edges))
        rows["confidence_mean"].append(weighted_mean(score, length))
        rows["review_draft"].append(keeps_boundary(rows["confidence_mean"][-1], boundary.polyline, costs, pixel_m))
        rows["confidence_min"].append(float(score[known].min()) if known.any() else np.nan)
        rows["corner_edges"].append(kinds.count("corner"))
        rows["skeleton_edges"].append(
            kinds.count("skeleton")
        )  # added from the segmentation skeleton (graph/skeleton_fill.py)
        distinct = dict.fromkeys(e.patch for e in boundary.edges if e.patch is not None and min(e.patch) >= 0)
        rows["patches"].append(";".join(f"{r},{col}" for r, col in distinct))
        for e, edge_world, metres, kind in zip(boundary.edges, lines, length, kinds):
            patch = e.patch if e.patch is not None and min(e.patch) >= 0 else (-1, -1)
            edge_rows.append(
                (
                    e.id,
                    c,
                    e.u,
                    e.v,
                    np.nan if e.score is None else e.score,
                    kind == "corner",
                    kind,
                    *patch,
                    metres,
                    LineString(edge_world),
                )
            )
    edge_rows.sort(key=lambda row: row[0])
    boundaries_frame = gpd.GeoDataFrame(
        {
            "boundary_id": np.arange(first_id, first_id + len(geometry), dtype=np.int64),
            "length_m": np.array(rows["length_m"], dtype=float),
            "n_edges": np.array(rows["n_edges"], dtype=np.int64),
            "confidence_mean": np.array(rows["confidence_mean"], dtype=float),
            "confidence_min": np.array(rows["confidence_min"], dtype=float),
            "review_draft": np.array(rows["review_draft"], dtype=bool),
            "corner_edges": np.array(rows["corner_edges"], dtype=np.int64),
            "skeleton_edges": np.array(rows["skeleton_edges"], dtype=np.int64),
            "patches": np.array(rows["patches"], dtype=object),
        },
        geometry=gpd.GeoSeries(geometry, crs=crs),
        crs=crs,
    )
    columns = list(zip(*edge_rows)) if edge_rows else [[] for _ in range(11)]
    edges_frame = gpd.GeoDataFrame(
        {
            "edge_id": np.array(columns[0], dtype=np.int64),
            "boundary_id": np.array(columns[1], dtype=np.int64),
            "u": np.array(columns[2], dtype=np.int64),
            "v": np.array(columns[3], dtype=np.int64),
            "confidence": np.array(columns[4], dtype=float),
            "corner": np.array(columns[5], dtype=bool),
            "kind": np.array(columns[6], dtype=object).astype(str),
            "patch_row": np.array(columns[7], dtype=np.int64),
            "patch_col": np.array(columns[8], dtype=np.int64),
            "length_m": np.array(columns[9], dtype=float),
        },
        geometry=gpd.GeoSeries(list(columns[10]), crs=crs),
        crs=crs,
    )
    return boundaries_frame, edges_frame


def _write_layer(
    frame: gpd.GeoDataFrame,
    path: Path,
    layer: str | None,
    driver: str,
    append: bool = False,
    metadata: dict | None = None,
) -> None:
    """One layer into ``path`` (a GeoPackage gains a layer per call), or more rows into it with
    ``append``; the geometry type is given so that an empty layer still declares LineString."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="'crs' was not provided")  # a graph without CRS
        pyogrio.write_dataframe(
            frame, path, layer=layer, driver=driver, geometry_type="LineString", append=append, layer_metadata=metadata
        )


def _centre(graph: BoundaryGraph) -> tuple[float, float] | None:
    if graph.n_vertices == 0 or graph.transform is None:
        return None
    xs, ys = pixel_to_world(graph.transform, graph.vertices[:, 0], graph.vertices[:, 1])
    return float(np.mean(xs)), float(np.mean(ys))
