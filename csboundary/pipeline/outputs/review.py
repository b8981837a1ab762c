"""The review round trip of a prediction folder: the page a person checks it on, and their
edits merged back into every output (the CLI's ``review`` and ``apply-review``)."""

from __future__ import annotations

import contextlib
import hashlib
import json
import time
from pathlib import Path

import numpy as np

from csboundary.data import city as layout
from csboundary.data.atomic import atomic_path, check_output_dir
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.graph.layer_edits import layer_edits
from csboundary.graph.review_edits import EditError, apply_edits
from csboundary.pipeline.outputs.lanelet2_export import LANELET2_MAP, PROJECTOR_INFO, read_origin, write_lanelet2
from csboundary.pipeline.outputs.prediction_files import EDGES_LAYER, imagery_extent, read_district, write_graph_outputs
from csboundary.metrics.review_time import ReviewCosts
from csboundary.viz.review_page import write_review_page

REVIEW_LOG = "review.json"
COMPLETE_LAYER = "complete"  # polygons a person marked complete, beside the edited edges layer


def prediction_inputs(prediction: Path) -> list[Path]:
    """The imagery a finished prediction was made from (its summary's inputs)."""
    summary = prediction / "summary.json"
    if not summary.exists():
        raise InputError(prediction, "not a finished prediction (no summary.json)")
    try:
        return [Path(p) for p in json.loads(summary.read_text())["inputs"]]
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(summary, "damaged summary (no list of inputs)") from exc


def city_ground_truth(inputs: list[Path]) -> Path | None:
    """The ground truth of the city whose tiles these are, when they are a city's."""
    if not inputs:
        return None
    city_dir = inputs[0].parent.parent
    path = layout.ground_truth_path(city_dir)
    return path if layout.is_city_dir(city_dir) and path.exists() else None


def write_review(prediction: Path, out: Path | None = None, ground_truth: Path | None = None, progress: bool = True,
                 bounds: tuple[float, float, float, float] | None = None) -> dict:
    """The review page of ``prediction`` in ``out`` (default ``prediction/review``), with
    ``ground_truth`` (default: the city's own) as a toggle; returns page, edges, ground truth.

    ``bounds`` (MINX, MINY, MAXX, MAXY in the prediction's CRS) makes the page of one district:
    its imagery and the edges meeting it, read from the GeoPackage's spatial index, so a city of
    any size is reviewed a district at a time; the edits it exports name the city's edges and
    vertices, and ``apply-review`` merges them into the whole city."""
    inputs = prediction_inputs(prediction)
    ground_truth = ground_truth or city_ground_truth(inputs)
    with contextlib.ExitStack() as stack:
        mosaic = stack.enter_context(Mosaic.open(inputs))
        ids = None
        if bounds is None:
            graph = BoundaryGraph.read_json(prediction / "graph.json")
        else:
            try:
                mosaic = stack.enter_context(mosaic.crop(mosaic.window_from_bounds(*bounds)))
            except ValueError:
                raise InputError(prediction, f"--bounds {','.join(map(str, bounds))} lies outside the imagery {mosaic.bounds}") from None
            district = read_district(prediction, bounds)
            graph, ids = district.graph, (district.edge_ids, district.vertex_ids)
        lines = list(read_ground_truth(ground_truth, mosaic.crs, bbox=bounds).geometry) if ground_truth is not None else []
        page = write_review_page(graph, mosaic, out or prediction / "review", lines, progress=progress,
                                 fingerprint=graph_fingerprint(prediction), ids=ids, review_costs=ReviewCosts().to_dict())
    return {"page": page, "edges": graph.n_edges, "ground_truth": ground_truth if lines else None}


def write_review_layers(prediction: Path, path: Path) -> dict:
    """A GeoPackage to review ``prediction`` in a GIS: a copy of its whole ``edges`` layer (the
    least sure edges first) to edit, and an empty ``complete`` polygon layer in the same CRS for
    the areas checked. ``apply-review PREDICTION path`` reads the two back (:func:`gpkg_edits`);
    an edge missing from the layer is a deleted edge, so the layer is never one district's."""
    import geopandas as gpd
    import pyogrio

    prediction_inputs(prediction)  # a finished prediction, or one line saying it is not
    source = prediction / "boundaries.gpkg"
    if path.resolve() == source.resolve():
        raise InputError(path, "is the prediction's own GeoPackage, which apply-review rewrites: give another file")
    edges = pyogrio.read_dataframe(source, layer=EDGES_LAYER)
    edges = edges.sort_values("confidence", kind="stable", na_position="last")  # the least sure first, as a reviewer takes them
    complete = gpd.GeoDataFrame({"note": np.array([], dtype=object)}, geometry=gpd.GeoSeries([], crs=edges.crs), crs=edges.crs)
    with atomic_path(path) as tmp:
        # GeoPackage 1.2: what the GDAL of older GIS releases (QGIS 3.22's 3.6) edits without a warning
        pyogrio.write_dataframe(edges, tmp, layer=EDGES_LAYER, driver="GPKG", geometry_type="LineString",
                                dataset_options={"VERSION": "1.2"})
        pyogrio.write_dataframe(complete, tmp, layer=COMPLETE_LAYER, driver="GPKG", geometry_type="Polygon", append=True)
    return {"gpkg": path, "edges": len(edges)}


def graph_fingerprint(prediction: Path) -> str:
    """sha256 of the prediction's graph.json: the review page writes it into the edits it
    exports, so edits are applied only to the graph they were made on."""
    return hashlib.sha256((prediction / "graph.json").read_bytes()).hexdigest()


def apply_review(prediction: Path, edits: Path) -> dict:
    """Merge ``edits`` into the prediction's graph.json, GeoPackage, GeoJSON and map.osm (when
    present), and append the record to ``review.json``. ``edits`` is the page's GeoJSON export,
    or a GeoPackage whose ``edges`` layer (a copy of the prediction's) a person edited in a GIS,
    with an optional ``complete`` polygon layer (:mod:`csboundary.graph.layer_edits`). Edits
    made on another version of graph.json are refused; a file applied before changes nothing
    (the result then has ``already_applied``: that earlier record)."""
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    try:
        raw = edits.read_bytes()
    except FileNotFoundError as exc:
        raise InputError(edits, "file not found") from exc
    if edits.suffix.lower() == ".gpkg":
        collection = {"properties": {}, "features": gpkg_edits(graph, edits)}
    else:
        try:
            collection = json.loads(raw)
            if not isinstance(collection["features"], list):
                raise TypeError
        except (ValueError, KeyError, TypeError) as exc:
            raise InputError(edits, "not a GeoJSON FeatureCollection of edits") from exc
    features = collection["features"]
    edits_sha = hashlib.sha256(raw).hexdigest()
    log_path = prediction / REVIEW_LOG
    log = read_log(log_path)
    earlier = [entry for entry in log["reviews"] if entry.get("edits_sha256") == edits_sha]
    if earlier:
        return {"already_applied": earlier[-1], "log": log_path}
    props = collection.get("properties") if isinstance(collection.get("properties"), dict) else {}
    crs = props.get("crs")
    if crs is not None and graph.crs is not None and crs != graph.crs:
        raise InputError(edits, f"edits are in {crs}, the prediction in {graph.crs}")
    before = graph_fingerprint(prediction)
    made_on = props.get("graph_sha256")
    if made_on is not None and made_on != before:
        raise InputError(edits, "made on another version of graph.json (its fingerprint differs): "
                                "write the review page again (csboundary review) and redo the edits there")
    try:
        updated, record = apply_edits(graph, features, extent=imagery_extent(prediction))
    except EditError as exc:
        raise InputError(edits, str(exc)) from exc
    check_output_dir(prediction)  # a folder that cannot be written is named, not the first temporary file in it
    write_graph_outputs(updated, prediction)
    if (prediction / LANELET2_MAP).exists():
        info = prediction / PROJECTOR_INFO
        write_lanelet2(updated, prediction / LANELET2_MAP, read_origin(info) if info.exists() else None)
    entry = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "edits": str(edits), "edits_sha256": edits_sha, "graph_sha256_before": before,
             "graph_sha256_after": graph_fingerprint(prediction), "edges_before": graph.n_edges, "edges_after": updated.n_edges,
             **record.to_dict()}
    log["reviews"].append(entry)
    with atomic_path(log_path) as tmp:
        tmp.write_text(json.dumps(log, indent=1) + "\n")
    return {**entry, "log": log_path}



def gpkg_edits(graph: BoundaryGraph, path: Path) -> list[dict]:
    """The page's edit features equivalent to ``path``: a GeoPackage with the prediction's
    ``edges`` layer as a person edited it, and optionally a ``complete`` polygon layer."""
    import pyogrio

    try:
        layers = {name for name, _ in pyogrio.list_layers(path)}
        edges = pyogrio.read_dataframe(path, layer=EDGES_LAYER) if EDGES_LAYER in layers else None
        complete = pyogrio.read_dataframe(path, layer=COMPLETE_LAYER) if COMPLETE_LAYER in layers else None
    except Exception as exc:  # GDAL's errors for a file that is not a GeoPackage
        raise InputError(path, f"not a readable GeoPackage ({' '.join(str(exc).split())[:200]})") from None
    if edges is None:
        raise InputError(path, f"has no {EDGES_LAYER} layer: edit a copy of the prediction's boundaries.gpkg")
    missing = [c for c in ("edge_id", "u", "v") if c not in edges.columns]
    if missing:
        raise InputError(path, f"its {EDGES_LAYER} layer lacks {', '.join(missing)} (not a csboundary prediction's layer)")
    for name, frame in ((EDGES_LAYER, edges), (COMPLETE_LAYER, complete)):
        if frame is not None and graph.crs is not None and frame.crs is not None and not frame.crs.equals(graph.crs):
            raise InputError(path, f"its {name} layer is in {frame.crs.to_string()}, the prediction in {graph.crs}")
    areas = []
    for geometry in [] if complete is None else complete.geometry:
        for polygon in getattr(geometry, "geoms", [geometry]):
            if polygon is None or polygon.geom_type != "Polygon":
                raise InputError(path, f"its {COMPLETE_LAYER} layer holds a {getattr(polygon, 'geom_type', 'missing')} geometry; "
                                       "draw polygons there")
            areas.append([[float(x), float(y)] for x, y, *_ in polygon.exterior.coords])
    rows = []
    for number, (edge_id, u, v, geometry) in enumerate(zip(edges["edge_id"], edges["u"], edges["v"], edges.geometry)):
        lines = [] if geometry is None else list(getattr(geometry, "geoms", [geometry]))
        if len(lines) != 1 or lines[0].geom_type != "LineString":
            raise InputError(path, f"feature {number} of its {EDGES_LAYER} layer is not one line")
        known = [None if value is None or value != value else int(value) for value in (edge_id, u, v)]  # NULL: a drawn feature
        rows.append((*(known if known[0] is not None else (None, None, None)), np.asarray(lines[0].coords, float)[:, :2]))
    try:
        return layer_edits(graph, rows, areas)
    except EditError as exc:
        raise InputError(path, str(exc)) from exc


def read_log(path: Path) -> dict:
    """The prediction's review log (``{"reviews": [...]}``; empty when there is none)."""
    if not path.exists():
        return {"reviews": []}
    try:
        log = json.loads(path.read_text())
        if not isinstance(log, dict) or not isinstance(log.get("reviews"), list):
            raise ValueError
    except ValueError as exc:
        raise InputError(path, "damaged review log (not {\"reviews\": [...]}): move it aside to continue") from exc
    return log
