"""Load a prediction and a ground truth into one pixel frame for evaluation.

Inputs are the project's graph JSON (``csboundary-graph``), any OGR vector file of LineStrings
(GeoPackage, GeoJSON, ...), a prediction folder (its ``graph.json``) or a city directory (its
``ground_truth.gpkg``). The common frame is,
in this order: ``--pixels`` (coordinates already are pixels; of the ``--raster`` when one is
given, which then gives the extent), the raster given with ``--raster``
(a city directory, GeoTIFF(s) or a directory of tiles), the city directory given as an input,
the transform stored in a graph JSON input, or ``--gsd`` (a north-up grid of that pixel size at
the inputs' top-left corner). World coordinates are reprojected to the frame's CRS when both are
known and differ; world coordinates with a CRS and without one are refused (:func:`check_spaces`).
Every problem is an :class:`~csboundary.errors.InputError` naming the file.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from affine import Affine

from csboundary.data import city_layout
from csboundary.data.grid import PatchGrid
from csboundary.data.units import geometric_mean, ground_units, pixel_size_m
from csboundary.data.windows import pixel_to_world, world_to_pixel
from csboundary.errors import InputError
from csboundary.graph.boundary_graph import FORMAT, BoundaryGraph

MAX_FRAME_PIXELS = 10**12  # 1,000,000 patches of 1000 px: larger than any city (NYC is 250k x 205k px)
GEOJSON_TYPES = ("FeatureCollection", "Feature", "LineString", "MultiLineString", "GeometryCollection")


@dataclass(frozen=True)
class Frame:
    """The pixel frame of an evaluation: ``transform`` pixel -> world (None: pixels only)."""

    transform: Affine | None
    crs: str | None
    width: int | None = None  # raster size when a raster defines the frame
    height: int | None = None
    source: str = "pixels"
    footprint: tuple = ()  # the raster's groups of tiles kilometres apart (data/footprint.py); () when it is one


def frame_metres_per_px(frame: Frame) -> float | None:
    """Metres per pixel of ``frame`` (geometric mean of east and north) where its CRS or units
    say; None for a frame in pixels only."""
    if frame.transform is None:
        return None
    units = ground_units(frame.crs, at=(frame.transform.c, frame.transform.f))
    return geometric_mean(pixel_size_m(units, frame.transform)) if units is not None else None


@dataclass
class Source:
    """One input as read: a graph (with its own transform) or world/pixel LineStrings."""

    path: Path
    graph: BoundaryGraph | None = None
    lines: object = None  # GeoDataFrame of LineStrings

    @property
    def crs(self):
        if self.graph is not None:
            return self.graph.crs if self.graph.transform is not None else None
        return self.lines.crs


def read_source(path: str | Path) -> Source:
    """Read a graph JSON, a vector file or a city directory's ground truth."""
    from csboundary.data.ground_truth import read_ground_truth

    path = Path(path)
    if not path.exists():
        raise InputError(path, "file not found")
    if path.is_dir():
        if city_layout.is_city_dir(path) and city_layout.ground_truth_path(path).exists():
            return Source(path, lines=read_ground_truth(city_layout.ground_truth_path(path)))
        if (path / "graph.json").is_file():  # a prediction folder: its graph
            return read_source(path / "graph.json")
        raise InputError(
            path,
            "is a directory but neither a city directory with ground_truth.gpkg nor a prediction folder with "
            "graph.json",
        )
    if path.suffix.lower() == ".json":
        try:
            data = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise InputError(path, f"not JSON ({exc})") from exc
        if isinstance(data, dict) and data.get("format") == FORMAT:
            return Source(path, graph=BoundaryGraph.from_dict(data, str(path)))
        if not (isinstance(data, dict) and data.get("type") in GEOJSON_TYPES):
            raise InputError(path, f"neither a {FORMAT} JSON file nor GeoJSON")
    return Source(path, lines=read_ground_truth(path))


def check_degrees(lines, path) -> None:
    """Coordinates of a geographic CRS (GeoJSON without a ``crs`` member is WGS 84) must be
    longitudes and latitudes; pixels or metres read as degrees would score as if nothing matched."""
    if lines.crs is None or not lines.crs.is_geographic or not len(lines):
        return
    x0, y0, x1, y1 = lines.total_bounds
    if not (np.isfinite([x0, y0, x1, y1]).all() and -90 <= y0 and y1 <= 90 and -180 <= x0 and x1 <= 360):
        worst = y1 if abs(y1) > 90 else (y0 if abs(y0) > 90 else (x1 if abs(x1) > 180 else x0))
        raise InputError(
            path,
            f"coordinates out of range for {lines.crs.to_string()} (degrees; {worst:g} found): pixels need "
            "--pixels, projected coordinates need the file's CRS",
        )


def frame_from_raster(path: str | Path) -> Frame:
    """The pixel frame of a city directory, a GeoTIFF, several tiles or a directory of tiles."""
    from csboundary.data.raster import Mosaic

    path = Path(path)
    source = city_layout.tiles_dir(path) if city_layout.is_city_dir(path) else path
    with Mosaic.open(source) as mosaic:
        crs = mosaic.crs.to_string() if mosaic.crs is not None else None
        transform = mosaic.transform if mosaic.crs is not None else None
        parts = tuple(mosaic.footprint) if mosaic.footprint != [mosaic.window] else ()
        return Frame(transform, crs, mosaic.width, mosaic.height, str(path), parts)


def resolve_frame(
    pred: Source, gt: Source, raster: str | Path | None = None, gsd: float | None = None, pixels: bool = False
) -> Frame:
    """Pick the common pixel frame (order: module doc)."""
    if pixels:
        if raster is not None:  # the coordinates are the raster's pixels: it still gives the imagery's extent
            size = frame_from_raster(raster)
            return Frame(None, None, size.width, size.height, source=f"pixels of {raster} (--pixels)")
        return Frame(None, None, source="pixels (--pixels)")
    if raster is not None:
        return frame_from_raster(raster)
    for src in (gt, pred):
        if src.path.is_dir() and city_layout.is_city_dir(src.path) and city_layout.tiles_dir(src.path).is_dir():
            return frame_from_raster(src.path)
    for src in (gt, pred):
        if src.graph is not None and src.graph.transform is not None:
            return Frame(src.graph.transform, src.graph.crs, source=str(src.path))
    vectors = [s for s in (gt, pred) if s.lines is not None]
    crs = next((s.crs for s in vectors if s.crs is not None), None)
    if gsd is not None:
        if gsd <= 0:
            raise InputError("--gsd", f"pixel size must be > 0, got {gsd}")
        boxes = [np.asarray(_to_crs(s, crs).total_bounds) for s in vectors if len(s.lines)]
        if not boxes:
            raise InputError(gt.path, "--gsd needs world coordinates, but no input holds lines")
        minx, maxy = min(b[0] for b in boxes), max(b[3] for b in boxes)
        return Frame(
            Affine(gsd, 0.0, math.floor(minx), 0.0, -gsd, math.ceil(maxy)),
            crs.to_string() if crs is not None else None,
            source=f"--gsd {gsd:g}",
        )
    if crs is None:
        return Frame(None, None, source="pixels (no CRS in the inputs)")
    blame = next(s for s in vectors if s.crs is not None)
    raise InputError(
        blame.path,
        f"holds world coordinates ({crs.to_string()}): give --raster or --gsd to convert them to pixels, or --pixels if they "
        f"are pixels",
    )


def to_frame(src: Source, frame: Frame) -> BoundaryGraph:
    """The input as a BoundaryGraph in the frame's pixels."""
    if src.graph is not None:
        graph = src.graph
        if (
            frame.transform is None
            or graph.transform is None
            or (graph.transform == frame.transform and _same_crs(graph.crs, frame.crs))
        ):
            return dataclasses.replace(graph, transform=frame.transform, crs=frame.crs)
        project = _projector(src, graph.crs, frame)

        def move(px: np.ndarray) -> np.ndarray:
            xs, ys = pixel_to_world(graph.transform, px[:, 0], px[:, 1])
            xs, ys = project(xs, ys)
            cols, rows = world_to_pixel(frame.transform, xs, ys)
            return np.stack([cols, rows], axis=1)

        polylines = None
        if graph.edge_polylines is not None:
            polylines = [move(np.asarray(p, dtype=float)) if p is not None else None for p in graph.edge_polylines]
        return dataclasses.replace(
            graph, vertices=move(graph.vertices), edge_polylines=polylines, transform=frame.transform, crs=frame.crs
        )
    table = src.lines
    if (
        frame.transform is not None
        and frame.crs is not None
        and src.crs is not None
        and not _same_crs(src.crs, frame.crs)
    ):
        try:
            table = table.to_crs(frame.crs)
        except Exception as exc:  # pyproj raises several types
            raise InputError(
                src.path, f"cannot reproject from {src.crs} to {frame.crs} ({exc})".splitlines()[0]
            ) from exc
    lines, scores = line_parts(table)
    if frame.transform is None:
        return BoundaryGraph.from_polylines([np.asarray(line.coords)[:, :2] for line in lines], scores=scores)
    return BoundaryGraph.from_world_lines(lines, frame.transform, crs=frame.crs, scores=scores)


SCORE_COLUMNS = (
    "confidence_mean",
    "confidence",
)  # a boundary's confidence (road_boundaries), else an edge's (edges layer)


def line_parts(table) -> tuple[list, list[float] | None]:
    """The LineStrings of a table of lines and, when it has a confidence column
    (:data:`SCORE_COLUMNS`), each one's confidence (NaN where missing or not a number), so a
    prediction read from its GeoPackage or GeoJSON keeps the scores graph.json holds."""
    from csboundary.data.ground_truth import as_linestrings

    column = next((c for c in SCORE_COLUMNS if c in table.columns), None)
    values = [np.nan] * len(table) if column is None else [_number(v) for v in table[column]]
    lines, scores = [], []
    for geom, value in zip(table.geometry, values):
        for part in as_linestrings(geom):
            lines.append(part)
            scores.append(value)
    return lines, (scores if column is not None else None)


def _number(value) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return float("nan")
    return number if math.isfinite(number) else float("nan")


def load_pair(
    pred_path, gt_path, raster=None, gsd: float | None = None, pixels: bool = False
) -> tuple[BoundaryGraph, BoundaryGraph, Frame]:
    """Read both inputs, put them in one frame and check that they can be compared."""
    pred_src, gt_src = read_source(pred_path), read_source(gt_path)
    if not pixels:
        for src in (pred_src, gt_src):
            if src.lines is not None:
                check_degrees(src.lines, src.path)
    frame = resolve_frame(pred_src, gt_src, raster, gsd, pixels)
    if not pixels:
        check_spaces(pred_src, gt_src, frame)
    pred, gt = to_frame(pred_src, frame), to_frame(gt_src, frame)
    for graph, path in ((pred, pred_src.path), (gt, gt_src.path)):
        check_finite(graph, path, frame)
    check_overlap(pred, gt, frame, pred_src.path, gt_src.path)
    return pred, gt, frame


def check_spaces(pred: Source, gt: Source, frame: Frame) -> None:
    """World coordinates with a CRS and world coordinates without one cannot be put on each other
    (a prediction of a picture without a CRS is in its pixels, a labelled city in metres): taking
    one to be in the other's CRS scores near 0 without a word. Inputs in different CRSs are fine
    (they are reprojected); graphs without a transform are the frame's pixels by definition."""
    placed = [
        (s.path, s.crs, "graph" if s.graph is not None else "lines")
        for s in (pred, gt)
        if s.graph is None or s.graph.transform is not None
    ]
    if frame.width is not None:  # a raster gives the frame: it is placed too
        placed.append((frame.source, frame.crs, "raster"))
    known = next(((path, crs) for path, crs, _ in placed if crs is not None), None)
    unknown = next(((path, kind) for path, crs, kind in placed if crs is None), None)
    if known is None or unknown is None:
        return
    from pyproj import CRS

    crs = CRS.from_user_input(known[1]).to_string()
    problem = f"has no CRS but {known[0]} is in {crs}, so the two cannot be aligned (scores would be meaningless)"
    predicted = (
        "a prediction of a picture without a CRS is scored by predicting the labelled city itself "
        "(evaluate-model CITY, evaluate-set SET)"
    )
    advice = {
        "graph": predicted,
        "lines": f"if its coordinates are in {crs}, set that CRS (e.g. ogr2ogr -a_srs {crs}); {predicted}",
        "raster": "give a georeferenced raster, or leave --raster out",
    }[unknown[1]]
    raise InputError(unknown[0], f"{problem}: {advice}")


def check_finite(graph: BoundaryGraph, path, frame: Frame) -> None:
    """NaN or infinite coordinates (in the file, or from a projection that cannot place them)
    would poison every metric silently."""
    parts = [graph.vertices] + [np.asarray(p, dtype=float) for p in (graph.edge_polylines or []) if p is not None]
    bad = sum(int((~np.isfinite(np.asarray(p, dtype=float).reshape(-1, 2))).any(axis=1).sum()) for p in parts)
    if bad:
        raise InputError(
            path,
            f"{bad} point(s) have no finite position in the evaluation frame ({frame.source}): "
            "NaN or infinite coordinates, or coordinates the frame's CRS cannot hold",
        )


def check_overlap(pred: BoundaryGraph, gt: BoundaryGraph, frame: Frame, pred_path, gt_path) -> None:
    """Disjoint inputs almost always mean a wrong CRS or frame, so they are refused."""
    box_pred, box_gt = graph_bounds(pred), graph_bounds(gt)
    if frame.width is not None:
        raster_box = np.array([0.0, 0.0, frame.width, frame.height])
        for box, path in ((box_gt, gt_path), (box_pred, pred_path)):
            if box is not None and not _touch(box, raster_box):
                raise InputError(path, f"lies outside the raster {frame.source} (different CRS or frame?)")
    if box_pred is not None and box_gt is not None and not _touch(box_pred, box_gt):
        raise InputError(pred_path, f"does not overlap the ground truth {gt_path} (different CRS or frame?)")


def graph_bounds(graph: BoundaryGraph) -> np.ndarray | None:
    """[min col, min row, max col, max row] of vertices and polylines, None if empty."""
    parts = [graph.vertices] + [np.asarray(p, dtype=float) for p in (graph.edge_polylines or []) if p is not None]
    pts = np.concatenate([p.reshape(-1, 2) for p in parts])
    if len(pts) == 0:
        return None
    return np.concatenate([pts.min(axis=0), pts.max(axis=0)])


def grid_for(frame: Frame, pred: BoundaryGraph, gt: BoundaryGraph) -> PatchGrid:
    """The patch grid of the frame: the raster's, or one from pixel (0, 0) covering both graphs."""
    if frame.width is not None:
        return PatchGrid(
            frame.width, frame.height, frame.transform or Affine.identity(), footprint=list(frame.footprint) or None
        )
    boxes = [b for b in (graph_bounds(pred), graph_bounds(gt)) if b is not None]
    width = math.ceil(max([b[2] for b in boxes], default=0))
    height = math.ceil(max([b[3] for b in boxes], default=0))
    if width <= 0 or height <= 0:
        raise InputError("<inputs>", "no boundary lies at positive pixel coordinates: nothing to cut into patches")
    if width * height > MAX_FRAME_PIXELS:
        raise InputError(
            "<inputs>", f"the boundaries span {width}x{height} px: give --raster so the patches are the imagery's"
        )
    return PatchGrid(width, height, frame.transform or Affine.identity())


def _touch(a: np.ndarray, b: np.ndarray, margin: float = 1.0) -> bool:
    return bool(a[0] <= b[2] + margin and b[0] <= a[2] + margin and a[1] <= b[3] + margin and b[1] <= a[3] + margin)


def _same_crs(a, b) -> bool:
    if a is None or b is None:
        return True  # unknown CRS: taken to be the frame's
    from pyproj import CRS

    return CRS.from_user_input(a) == CRS.from_user_input(b)


def _to_crs(src: Source, crs):
    table = src.lines
    if crs is not None and table.crs is not None and not _same_crs(table.crs, crs):
        try:
            return table.to_crs(crs)
        except Exception as exc:
            raise InputError(src.path, f"cannot reproject from {table.crs} to {crs} ({exc})".splitlines()[0]) from exc
    return table


def _projector(src: Source, crs, frame: Frame):
    if _same_crs(crs, frame.crs):
        return lambda xs, ys: (xs, ys)
    from pyproj import Transformer

    try:
        transformer = Transformer.from_crs(crs, frame.crs, always_xy=True)
    except Exception as exc:
        raise InputError(src.path, f"cannot reproject from {crs} to {frame.crs} ({exc})".splitlines()[0]) from exc
    return lambda xs, ys: transformer.transform(xs, ys)
