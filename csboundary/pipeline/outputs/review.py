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
from csboundary.data.folder_lock import folder_lock, locked_folder
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.graph.boundaries import Boundary, graph_boundaries
from csboundary.graph.chains import edge_line
from csboundary.graph.layer_edits import boundary_layer_edits, layer_edits
from csboundary.graph.review_edits import EditError, apply_edits
from csboundary.metrics.review_time import ReviewCosts, review_draft
from csboundary.pipeline.outputs.lanelet2_export import LANELET2_MAP, PROJECTOR_INFO, read_origin, write_lanelet2
from csboundary.pipeline.outputs.prediction_files import (
    EDGES_LAYER,
    graph_units,
    imagery_extent,
    metres_per_px,
    read_district,
    write_graph_outputs,
)
from csboundary.viz.review_page import write_review_page

REVIEW_LOG = "review.json"
COMPLETE_LAYER = "complete"  # polygons a person marked complete, beside the edited boundary layers
DRAFT_LAYER = "boundaries"  # the review draft's boundaries, least sure first (review --gpkg)
HELD_BACK_LAYER = "held_back"  # the boundaries not worth a look (review --gpkg; hidden in the QGIS plugin)


def graph_metres_per_px(graph: BoundaryGraph, costs: ReviewCosts = ReviewCosts()) -> float:
    """Ground size of the graph's pixels (the costs' assumed size when the graph has no CRS)."""
    return (
        metres_per_px(graph_units(graph), graph.transform, costs)
        if graph.transform is not None
        else costs.assumed_metres_per_px
    )


def review_boundaries(
    graph: BoundaryGraph, costs: ReviewCosts = ReviewCosts()
) -> tuple[list[Boundary], np.ndarray, float]:
    """What a reviewer acts on: the graph's boundaries, which of them are in the review draft
    (:func:`csboundary.metrics.review_time.review_draft`), and the metres per pixel that priced them."""
    metres_per_px = graph_metres_per_px(graph, costs)
    boundaries = graph_boundaries(graph)
    return boundaries, review_draft(boundaries, costs, metres_per_px), metres_per_px


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


def write_review(
    prediction: Path,
    out: Path | None = None,
    ground_truth: Path | None = None,
    progress: bool = True,
    bounds: tuple[float, float, float, float] | None = None,
) -> dict:
    """The review page of ``prediction`` in ``out`` (default ``prediction/review``), with
    ``ground_truth`` (default: the city's own) as a toggle; returns page, edges, ground truth.

    ``bounds`` (MINX, MINY, MAXX, MAXY in the prediction's CRS) makes the page of one district:
    its imagery and the edges meeting it, read from the GeoPackage's spatial index, so a city of
    any size is reviewed a district at a time; the edits it exports name the city's edges and
    vertices, and ``apply-review`` merges them into the whole city."""
    inputs = prediction_inputs(prediction)
    ground_truth = ground_truth or city_ground_truth(inputs)
    out = Path(out) if out else prediction / "review"
    with contextlib.ExitStack() as stack:
        stack.enter_context(locked_folder(out))  # two pages written into one folder at once would mix their tiles
        mosaic = stack.enter_context(Mosaic.open(inputs))
        ids = None
        if bounds is None:
            graph = BoundaryGraph.read_json(prediction / "graph.json")
        else:
            try:
                mosaic = stack.enter_context(mosaic.crop(mosaic.window_from_bounds(*bounds)))
            except ValueError:
                raise InputError(
                    prediction, f"--bounds {','.join(map(str, bounds))} lies outside the imagery {mosaic.bounds}"
                ) from None
            district = read_district(prediction, bounds)
            graph, ids = district.graph, (district.edge_ids, district.vertex_ids)
        lines = (
            list(read_ground_truth(ground_truth, mosaic.crs, bbox=bounds).geometry) if ground_truth is not None else []
        )
        boundaries, draft, metres_per_px = review_boundaries(graph)
        rows = [
            {
                "edges": b.edges.tolist(),
                "score": b.confidence if np.isfinite(b.confidence) else None,
                "draft": bool(keep),
                "length_m": b.length_px * metres_per_px,
            }
            for b, keep in zip(boundaries, draft)
        ]
        page = write_review_page(
            graph,
            mosaic,
            out,
            lines,
            progress=progress,
            fingerprint=graph_fingerprint(prediction),
            ids=ids,
            review_costs=ReviewCosts().to_dict(),
            boundaries=rows,
            metres_per_px=metres_per_px,
        )
    return {
        "page": page,
        "edges": graph.n_edges,
        "boundaries": len(boundaries),
        "draft": int(draft.sum()),
        "ground_truth": ground_truth if lines else None,
    }


def write_review_layers(prediction: Path, path: Path) -> dict:
    """A GeoPackage to review ``prediction`` in a GIS, a boundary per feature: the review draft's
    boundaries (layer ``boundaries``, the least sure first, so the attribute table opens in
    review order), the boundaries held back from it (``held_back``: not worth a look, in
    expectation), each with its ``edge_ids``, ``confidence`` and ``length_m``, and an empty
    ``complete`` polygon layer in the same CRS for the areas checked. ``apply-review PREDICTION
    path`` reads them back (:func:`gpkg_edits`); a boundary missing from both layers is a deleted
    boundary, so the layers are never one district's."""
    import geopandas as gpd
    import pyogrio
    from shapely.geometry import LineString

    prediction_inputs(prediction)  # a finished prediction, or one line saying it is not
    if path.resolve() == (prediction / "boundaries.gpkg").resolve():
        raise InputError(path, "is the prediction's own GeoPackage, which apply-review rewrites: give another file")
    graph = BoundaryGraph.read_json(prediction / "graph.json")
    if graph.transform is None:
        raise InputError(prediction / "graph.json", "has no transform: a GIS layer needs world coordinates")
    boundaries, draft, metres_per_px = review_boundaries(graph)
    crs = graph.crs

    def frame(keep: bool):
        picked = [b for b, d in zip(boundaries, draft) if d == keep]
        picked.sort(key=lambda b: (not np.isfinite(b.confidence), b.confidence if np.isfinite(b.confidence) else 0.0))
        world = [graph.to_world(b.polyline) for b in picked]
        return gpd.GeoDataFrame(
            {
                "edge_ids": np.array([";".join(map(str, b.edges.tolist())) for b in picked], dtype=object),
                "n_edges": np.array([len(b.edges) for b in picked], dtype=np.int64),
                "confidence": np.array([b.confidence for b in picked], dtype=float),
                "length_m": np.array([b.length_px * metres_per_px for b in picked], dtype=float),
            },
            geometry=gpd.GeoSeries([LineString(line) for line in world], crs=crs),
            crs=crs,
        )

    complete = gpd.GeoDataFrame({"note": np.array([], dtype=object)}, geometry=gpd.GeoSeries([], crs=crs), crs=crs)
    with atomic_path(path) as tmp:
        # GeoPackage 1.2: what the GDAL of older GIS releases (QGIS 3.22's 3.6) edits without a warning
        pyogrio.write_dataframe(
            frame(True),
            tmp,
            layer=DRAFT_LAYER,
            driver="GPKG",
            geometry_type="LineString",
            dataset_options={"VERSION": "1.2"},
        )
        pyogrio.write_dataframe(
            frame(False), tmp, layer=HELD_BACK_LAYER, driver="GPKG", geometry_type="LineString", append=True
        )
        pyogrio.write_dataframe(
            complete, tmp, layer=COMPLETE_LAYER, driver="GPKG", geometry_type="Polygon", append=True
        )
    return {"gpkg": path, "boundaries": int(draft.sum()), "held_back": int((~draft).sum()), "edges": graph.n_edges}


def graph_fingerprint(prediction: Path) -> str:
    """sha256 of the prediction's graph.json: the review page writes it into the edits it
    exports, so edits are applied only to the graph they were made on."""
    return hashlib.sha256((prediction / "graph.json").read_bytes()).hexdigest()


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
