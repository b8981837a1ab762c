"""The review round trip of a prediction folder: the page a person checks it on, and their
edits merged back into every output (the CLI's ``review`` and ``apply-review``)."""

from __future__ import annotations

import contextlib
import hashlib
import json
from pathlib import Path

import numpy as np

from csboundary.data import city_layout
from csboundary.data.atomic import atomic_path
from csboundary.data.folder_lock import locked_folder
from csboundary.data.ground_truth import read_ground_truth
from csboundary.data.raster import Mosaic
from csboundary.errors import InputError
from csboundary.graph import BoundaryGraph
from csboundary.graph.boundaries import Boundary, graph_boundaries
from csboundary.metrics.review_time import ReviewCosts, review_draft
from csboundary.pipeline.outputs.prediction_files import graph_units, metres_per_px
from csboundary.pipeline.outputs.prediction_reader import read_district
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
    path = city_layout.ground_truth_path(city_dir)
    return path if city_layout.is_city_dir(city_dir) and path.exists() else None


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
