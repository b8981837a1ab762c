"""The review round trip of a prediction folder: the page a person checks it on, and their
edits merged back into every output (the CLI's ``review`` and ``apply-review``)."""

from __future__ import annotations

import json
import time
from pathlib import Path

from csboundary.data import city as layout
from csboundary.data.atomic import atomic_path
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.graph.review_edits import EditError, apply_edits
from csboundary.pipeline.lanelet2_export import LANELET2_MAP, PROJECTOR_INFO, read_origin, write_lanelet2
from csboundary.pipeline.outputs import write_graph_outputs
from csboundary.viz.review_page import write_review_page

REVIEW_LOG = "review.json"


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


def write_review(prediction: Path, out: Path | None = None, ground_truth: Path | None = None, progress: bool = True) -> dict:
    """The review page of ``prediction`` in ``out`` (default ``prediction/review``), with
    ``ground_truth`` (default: the city's own) as a toggle; returns page, edges, ground truth."""
    inputs = prediction_inputs(prediction)
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    ground_truth = ground_truth or city_ground_truth(inputs)
    with Mosaic.open(inputs) as mosaic:
        lines = list(read_ground_truth(ground_truth, mosaic.crs).geometry) if ground_truth is not None else []
        page = write_review_page(graph, mosaic, out or prediction / "review", lines, progress=progress)
    return {"page": page, "edges": graph.n_edges, "ground_truth": ground_truth if lines else None}


def apply_review(prediction: Path, edits: Path) -> dict:
    """Merge ``edits`` (the page's GeoJSON export) into the prediction's graph.json, GeoPackage,
    GeoJSON and map.osm (when present), and append the record to ``review.json``."""
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    try:
        collection = json.loads(edits.read_text())
        features = collection["features"]
    except FileNotFoundError as exc:
        raise InputError(edits, "file not found") from exc
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(edits, "not a GeoJSON FeatureCollection of edits") from exc
    crs = (collection.get("properties") or {}).get("crs")
    if crs is not None and graph.crs is not None and crs != graph.crs:
        raise InputError(edits, f"edits are in {crs}, the prediction in {graph.crs}")
    try:
        updated, record = apply_edits(graph, features)
    except EditError as exc:
        raise InputError(edits, str(exc)) from exc
    write_graph_outputs(updated, prediction)
    if (prediction / LANELET2_MAP).exists():
        info = prediction / PROJECTOR_INFO
        write_lanelet2(updated, prediction / LANELET2_MAP, read_origin(info) if info.exists() else None)
    entry = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "edits": str(edits), "edges_before": graph.n_edges,
             "edges_after": updated.n_edges, **record.to_dict()}
    log_path = prediction / REVIEW_LOG
    log = json.loads(log_path.read_text()) if log_path.exists() else {"reviews": []}
    log["reviews"].append(entry)
    with atomic_path(log_path) as tmp:
        tmp.write_text(json.dumps(log, indent=1) + "\n")
    return {**entry, "log": log_path}
