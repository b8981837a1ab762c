"""A prediction's files read back: the graph (from graph.json or the GeoPackage's edges layer), one
district of it within bounds, and the extents of the imagery and of the prediction, so review,
apply-review, evaluate and export-lanelet2 start from any of them."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyogrio
from affine import Affine

from csboundary.data.windows import pixel_to_world, world_to_pixel
from csboundary.errors import InputError
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.pipeline.outputs.prediction_files import EDGES_LAYER, TRANSFORM_KEY


def read_prediction_graph(source: str | Path, bounds: tuple[float, float, float, float] | None = None) -> BoundaryGraph:
    """The graph of a prediction (a predict output folder, its graph.json or its GeoPackage):
    from graph.json when there is one and no ``bounds``, else from the GeoPackage
    (:func:`read_district`)."""
    source = Path(source)
    if not source.exists():
        raise InputError(source, "not found")
    if source.is_file() and source.suffix.lower() not in (".json", ".gpkg"):
        raise InputError(source, "not a prediction: give its folder, its graph.json or its boundaries.gpkg")
    folder = source if source.is_dir() else source.parent
    if bounds is None and source.suffix != ".gpkg" and (source.suffix == ".json" or (folder / "graph.json").exists()):
        return BoundaryGraph.read_json(source if source.suffix == ".json" else folder / "graph.json")
    return read_district(source, bounds).graph


@dataclass
class District:
    """Part of a city graph: the graph (vertices numbered anew in the order of the city's
    numbers) and, for each of its edges and vertices, its number in the city's graph.json."""

    graph: BoundaryGraph
    edge_ids: np.ndarray
    vertex_ids: np.ndarray


def read_district(source: str | Path, bounds: tuple[float, float, float, float] | None = None) -> District:
    """The edges of a prediction's GeoPackage whose lines meet ``bounds`` (MINX, MINY, MAXX,
    MAXY in its CRS; None: all), read through the layer's spatial index, so a district of a city
    of any size costs memory for the district alone. Vertex kinds are not in the GeoPackage."""
    source = Path(source)
    if not source.exists():
        raise InputError(source, "not found")
    gpkg = source if source.suffix == ".gpkg" else (source if source.is_dir() else source.parent) / "boundaries.gpkg"
    if not gpkg.exists():
        raise InputError(gpkg, "file not found (a predict output folder holds boundaries.gpkg)")
    try:
        info = pyogrio.read_info(gpkg, layer=EDGES_LAYER)
        frame = pyogrio.read_dataframe(gpkg, layer=EDGES_LAYER, bbox=bounds)
    except Exception as exc:  # pyogrio raises its own types for a file or layer it cannot read
        raise InputError(gpkg, f"has no readable {EDGES_LAYER} layer ({exc})") from None
    values = (info.get("layer_metadata") or {}).get(TRANSFORM_KEY)
    if values is None:
        raise InputError(gpkg, f"its {EDGES_LAYER} layer does not say its pixel grid (written by an older csboundary)")
    try:
        transform = Affine(*map(float, values.split(",")))
    except (TypeError, ValueError):
        raise InputError(gpkg, f"its pixel grid ({TRANSFORM_KEY} = {values!r}) is not six numbers") from None
    if bounds is not None:
        extent = prediction_extent(gpkg, transform, info)
        if extent is not None and not (
            bounds[0] < extent[2] and extent[0] < bounds[2] and bounds[1] < extent[3] and extent[1] < bounds[3]
        ):
            raise InputError(
                source,
                f"--bounds {','.join(f'{v:g}' for v in bounds)} lies outside the prediction "
                f"({', '.join(f'{v:.6g}' for v in extent)} in {info.get('crs') or 'pixels'})",
            )
    missing = [
        c for c in ("edge_id", "u", "v", "kind", "confidence", "patch_row", "patch_col") if c not in frame.columns
    ]
    if missing:
        raise InputError(gpkg, f"its {EDGES_LAYER} layer lacks {', '.join(missing)} (not a csboundary prediction)")
    frame = frame.sort_values("edge_id", kind="stable")
    lines = []
    for geometry in frame.geometry:
        xy = np.asarray(geometry.coords)[:, :2]
        cols, rows = world_to_pixel(transform, xy[:, 0], xy[:, 1])
        lines.append(np.stack([cols, rows], axis=1))
    ends = frame[["u", "v"]].to_numpy(np.int64).reshape(-1, 2)
    ids = np.unique(ends)
    position = {}
    for (u, v), line in zip(ends.tolist(), lines):
        position.setdefault(u, line[0])
        position.setdefault(v, line[-1])
    graph = BoundaryGraph(
        np.array([position[int(x)] for x in ids], float).reshape(-1, 2),
        np.searchsorted(ids, ends).reshape(-1, 2),
        edge_kinds=frame["kind"].astype(str).tolist(),
        edge_polylines=lines,
        edge_scores=frame["confidence"].to_numpy(float),
        edge_patches=frame[["patch_row", "patch_col"]].to_numpy(np.int64).reshape(-1, 2),
        transform=transform,
        crs=info.get("crs"),
    )
    return District(graph, frame["edge_id"].to_numpy(np.int64), ids)


def imagery_extent(prediction: Path) -> tuple[float, float, float, float] | None:
    """The imagery's extent in graph pixels (from summary.json), or None when not recorded."""
    try:
        width, height = json.loads((prediction / "summary.json").read_text())["mosaic_px"]
        return (0.0, 0.0, float(width), float(height))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def prediction_extent(gpkg: Path, transform: Affine, info: dict) -> tuple[float, float, float, float] | None:
    """(MINX, MINY, MAXX, MAXY) of what a prediction covers: its imagery (:func:`imagery_extent`
    on the pixel grid), else its edges' extent."""
    pixels = imagery_extent(gpkg.parent)
    if pixels is None:
        total = info.get("total_bounds")
        return tuple(map(float, total)) if total is not None and np.isfinite(total).all() else None
    xs, ys = pixel_to_world(transform, np.array(pixels[0::2]), np.array(pixels[1::2]))
    return float(min(xs)), float(min(ys)), float(max(xs)), float(max(ys))
