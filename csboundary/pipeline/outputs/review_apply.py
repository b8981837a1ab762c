"""A reviewer's edits merged back into the prediction (``csboundary apply-review``): the edits
from the review page's GeoJSON or from the edited GeoPackage layers (read and checked here), the
graph rewritten, and every review logged in review.json with the graph's fingerprint before and
after."""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np

from csboundary.data.atomic import atomic_path, check_output_dir
from csboundary.data.folder_lock import folder_lock
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.graph.boundaries import Boundary
from csboundary.graph.chains import edge_line
from csboundary.graph.layer_edits import boundary_layer_edits, layer_edits
from csboundary.graph.review_edits import EditError, apply_edits
from csboundary.pipeline.outputs.lanelet2_export import LANELET2_MAP, PROJECTOR_INFO, read_origin, write_lanelet2
from csboundary.pipeline.outputs.prediction_files import EDGES_LAYER, write_graph_outputs
from csboundary.pipeline.outputs.prediction_reader import imagery_extent
from csboundary.pipeline.outputs.review import (
    COMPLETE_LAYER,
    DRAFT_LAYER,
    HELD_BACK_LAYER,
    REVIEW_LOG,
    graph_fingerprint,
    review_boundaries,
)


def apply_review(prediction: Path, edits: Path) -> dict:
    """Merge ``edits`` into the prediction's graph.json, GeoPackage, GeoJSON and map.osm (when
    present), and append the record to ``review.json``. Boundaries held back from the review draft
    that lie untouched inside an area marked complete are deleted with them
    (:func:`held_back_deletions`). ``edits`` is the page's GeoJSON export,
    or a GeoPackage whose ``edges`` layer (a copy of the prediction's) a person edited in a GIS,
    with an optional ``complete`` polygon layer (:mod:`csboundary.graph.layer_edits`). Edits
    made on another version of graph.json are refused; a file applied before changes nothing
    (the result then has ``already_applied``: that earlier record)."""
    if not prediction.is_dir():
        raise InputError(prediction, "not a prediction folder")
    check_output_dir(prediction)  # a folder that cannot be written is named, before its lock file is tried
    with folder_lock(prediction):  # two reviews applied at once: the second waits for nobody, it is refused
        return _apply_review(prediction, edits)


def _apply_review(prediction: Path, edits: Path) -> dict:
    """:func:`apply_review` under the prediction folder's lock."""
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    reviewed = review_boundaries(graph)  # what the reviewer saw, for the GIS layers and the held-back boundaries alike
    try:
        raw = edits.read_bytes()
    except FileNotFoundError as exc:
        raise InputError(edits, "file not found") from exc
    if edits.suffix.lower() == ".gpkg":
        collection = {"properties": {}, "features": gpkg_edits(graph, edits, reviewed)}
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
        raise InputError(
            edits,
            "made on another version of graph.json (its fingerprint differs): "
            "write the review page again (csboundary review) and redo the edits there",
        )
    held = held_back_deletions(graph, features, reviewed)
    try:
        updated, record = apply_edits(graph, features + held, extent=imagery_extent(prediction))
    except EditError as exc:
        raise InputError(edits, str(exc)) from exc
    check_output_dir(prediction)  # a folder that cannot be written is named, not the first temporary file in it
    write_graph_outputs(updated, prediction)
    if (prediction / LANELET2_MAP).exists():
        info = prediction / PROJECTOR_INFO
        write_lanelet2(updated, prediction / LANELET2_MAP, read_origin(info) if info.exists() else None)
    entry = {
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "edits": str(edits),
        "edits_sha256": edits_sha,
        "graph_sha256_before": before,
        "graph_sha256_after": graph_fingerprint(prediction),
        "edges_before": graph.n_edges,
        "edges_after": updated.n_edges,
        "held_back_deleted": [f["properties"]["edge"] for f in held],
        **record.to_dict(),
    }
    log["reviews"].append(entry)
    with atomic_path(log_path) as tmp:
        tmp.write_text(json.dumps(log, indent=1) + "\n")
    return {**entry, "log": log_path}


def gpkg_edits(
    graph: BoundaryGraph, path: Path, reviewed: tuple[list[Boundary], np.ndarray, float] | None = None
) -> list[dict]:
    """The page's edit features equivalent to ``path``: the review GeoPackage ``review --gpkg``
    wrote (its ``boundaries`` and ``held_back`` layers as a person edited them,
    :func:`~csboundary.graph.layer_edits.boundary_layer_edits`), or a copy of the prediction's
    GeoPackage whose ``edges`` layer a person edited; either with an optional ``complete``
    polygon layer."""
    import pyogrio

    try:
        layers = {name for name, _ in pyogrio.list_layers(path)}
        boundary_route = DRAFT_LAYER in layers
        names = (DRAFT_LAYER, HELD_BACK_LAYER) if boundary_route else (EDGES_LAYER,)
        frames = {name: pyogrio.read_dataframe(path, layer=name) for name in names if name in layers}
        complete = pyogrio.read_dataframe(path, layer=COMPLETE_LAYER) if COMPLETE_LAYER in layers else None
    except Exception as exc:  # GDAL's errors for a file that is not a GeoPackage
        raise InputError(path, f"not a readable GeoPackage ({' '.join(str(exc).split())[:200]})") from None
    if not frames:
        raise InputError(
            path,
            f"has no {DRAFT_LAYER} or {EDGES_LAYER} layer: edit the file csboundary review --gpkg writes, "
            "or a copy of the prediction's boundaries.gpkg",
        )
    needed = ("edge_ids",) if boundary_route else ("edge_id", "u", "v")
    for name, frame in frames.items():
        missing = [c for c in needed if c not in frame.columns]
        if missing:
            raise InputError(path, f"its {name} layer lacks {', '.join(missing)} (not a csboundary review layer)")
    for name, frame in (*frames.items(), (COMPLETE_LAYER, complete)):
        if frame is not None and graph.crs is not None and frame.crs is not None and not frame.crs.equals(graph.crs):
            raise InputError(path, f"its {name} layer is in {frame.crs.to_string()}, the prediction in {graph.crs}")
    areas = []
    for number, geometry in enumerate([] if complete is None else complete.geometry):
        for polygon in getattr(geometry, "geoms", [geometry]):
            if polygon is None or polygon.geom_type != "Polygon":
                raise InputError(
                    path,
                    f"its {COMPLETE_LAYER} layer holds a {getattr(polygon, 'geom_type', 'missing')} geometry; "
                    "draw polygons there",
                )
            if polygon.is_empty:
                raise InputError(
                    path,
                    f"feature {number} of its {COMPLETE_LAYER} layer is an empty polygon: draw the area, or delete "
                    "the feature",
                )
            areas.append([[float(x), float(y)] for x, y, *_ in polygon.exterior.coords])
    features_in = sum(len(frame) for frame in frames.values())
    if features_in == 0 and graph.n_edges:
        raise InputError(
            path,
            f"its {', '.join(frames)} layer{'s hold' if len(frames) > 1 else ' holds'} no feature: applied, that "
            f"would delete all {graph.n_edges} edges; to start the map afresh, delete graph.json's edges on "
            "purpose (review page: Delete below over the whole city)",
        )
    try:
        if boundary_route:
            rows = [
                (_edge_ids(value, path, name, number), line, name == DRAFT_LAYER)
                for name, frame in frames.items()
                for number, (value, line) in enumerate(zip(frame["edge_ids"], _lines(frame, path, name)))
            ]
            boundaries, draft, _ = reviewed or review_boundaries(graph)
            held = frozenset(tuple(sorted(b.edges.tolist())) for b, d in zip(boundaries, draft) if not d)
            return boundary_layer_edits(graph, rows, areas, held)
        edges = frames[EDGES_LAYER]
        rows = []
        for number, (edge_id, u, v, line) in enumerate(
            zip(edges["edge_id"], edges["u"], edges["v"], _lines(edges, path, EDGES_LAYER))
        ):
            known = [
                _whole(value, path, number, name) for value, name in ((edge_id, "edge_id"), (u, "u"), (v, "v"))
            ]  # NULL: drawn
            rows.append((*(known if known[0] is not None else (None, None, None)), line))
        return layer_edits(graph, rows, areas)
    except EditError as exc:
        raise InputError(path, str(exc)) from exc


def _lines(frame, path: Path, layer: str) -> list[np.ndarray]:
    """Each feature's world coordinates (N, 2): one LineString per feature, or one line saying which is not."""
    out = []
    for number, geometry in enumerate(frame.geometry):
        lines = [] if geometry is None else list(getattr(geometry, "geoms", [geometry]))
        if len(lines) != 1 or lines[0].geom_type != "LineString":
            raise InputError(path, f"feature {number} of its {layer} layer is not one line")
        out.append(np.asarray(lines[0].coords, float)[:, :2])
    return out


def _whole(value, path: Path, number: int, column: str) -> int | None:
    """A whole number of the edges layer (None for NULL: a drawn feature), or one line naming the feature."""
    if value is None or (isinstance(value, float) and value != value):
        return None
    try:
        number_value = float(value)
        if number_value == int(number_value):
            return int(number_value)
    except (TypeError, ValueError, OverflowError):
        pass
    raise InputError(
        path, f"feature {number} of its {EDGES_LAYER} layer: {column} {str(value)[:40]!r} is not a whole number"
    )


def _edge_ids(value, path: Path, layer: str, number: int) -> list[int] | None:
    """A feature's ``edge_ids`` ("3;4;5"); None (NULL or empty) for a line the reviewer drew."""
    if value is None or (isinstance(value, float) and value != value) or str(value).strip() == "":
        return None
    try:
        return [int(part) for part in str(value).split(";")]
    except ValueError:
        raise InputError(
            path,
            f"feature {number} of its {layer} layer: edge_ids {str(value)[:40]!r} is not a list of edge "
            "numbers (3;4;5)",
        ) from None


def held_back_deletions(
    graph: BoundaryGraph, features: list[dict], reviewed: tuple[list[Boundary], np.ndarray, float] | None = None
) -> list[dict]:
    """Delete edits for the boundaries held back from the review draft that lie inside an area the
    edits mark complete (their middle inside it) and that no edit touches: the reviewer vouches for
    what the page or the GIS showed there, and fine-tuning must not learn them as curbs."""
    from shapely.geometry import Point, Polygon

    areas = [
        Polygon(f["geometry"]["coordinates"][0])
        for f in features
        if f.get("properties", {}).get("action") == "complete" and f.get("geometry", {}).get("type") == "Polygon"
    ]
    if not areas or graph.transform is None:
        return []
    touched = {
        f["properties"].get("edge") for f in features if f.get("properties", {}).get("action") in ("delete", "accept")
    }
    moved = {f["properties"].get("vertex") for f in features if f.get("properties", {}).get("action") == "move"}
    boundaries, draft, _ = reviewed or review_boundaries(graph)
    out = []
    for boundary, shown in zip(boundaries, draft):
        edges = boundary.edges.tolist()
        if shown or touched.intersection(edges) or moved.intersection(graph.edges[edges].ravel().tolist()):
            continue
        middle = boundary.polyline[len(boundary.polyline) // 2]
        x, y = graph.to_world(middle)[0]
        if any(area.contains(Point(x, y)) for area in areas):
            for k in edges:
                line = graph.to_world(edge_line(graph, k))
                out.append(
                    {
                        "type": "Feature",
                        "properties": {"action": "delete", "edge": int(k)},
                        "geometry": {"type": "LineString", "coordinates": line.tolist()},
                    }
                )
    return out


def read_log(path: Path) -> dict:
    """The prediction's review log (``{"reviews": [...]}``; empty when there is none)."""
    if not path.exists():
        return {"reviews": []}
    try:
        log = json.loads(path.read_text())
        if not isinstance(log, dict) or not isinstance(log.get("reviews"), list):
            raise ValueError
    except ValueError as exc:
        raise InputError(path, 'damaged review log (not {"reviews": [...]}): move it aside to continue') from exc
    return log
