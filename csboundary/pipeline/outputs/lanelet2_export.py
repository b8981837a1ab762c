"""Road boundaries as a Lanelet2 map: what HD-map tools (Autoware and others) read.

Every boundary of the ``road_boundaries`` layer (a chain of graph edges merged through degree-2
vertices) becomes one Lanelet2 linestring of type ``road_border``; a boundary that closes on
itself (a traffic island, a roundabout's centre) ends on its own first point, which makes it a
closed linestring in Lanelet2. Attributes: ``confidence`` (length-weighted mean edge score),
``confidence_min``, ``length_m`` and ``boundary_id`` (the GeoPackage row).

Lanelet2 stores latitude and longitude; its tools work in a local metric frame given by a
projector and an origin. The origin is the centre of the boundaries (or ``origin`` if given),
converted from the input's CRS to WGS 84; ``UtmProjector`` is the projector (Autoware's
``LocalCartesianUTM``). It is written beside the map as ``map_projector_info.yaml`` (Autoware's
file) so a reader can load the map in the same frame.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from csboundary.data.atomic import atomic_path, naming_full_disk
from csboundary.errors import InputError
from csboundary.graph.boundary_graph import BoundaryGraph
from csboundary.pipeline.outputs.prediction_files import check_finite_geometry, graph_frames

ROAD_BORDER = "road_border"
PROJECTOR_INFO = "map_projector_info.yaml"
LANELET2_MAP = "map.osm"  # the map's name in a prediction folder


def to_wgs84(crs: str):
    """A function (x, y) arrays in ``crs`` -> (lon, lat) arrays."""
    from pyproj import Transformer

    transformer = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    return lambda xs, ys: transformer.transform(np.asarray(xs, float), np.asarray(ys, float))


def projector_for(origin: tuple[float, float]):
    """Lanelet2's UTM projector around ``origin`` (lat, lon)."""
    from lanelet2.io import Origin
    from lanelet2.projection import UtmProjector

    return UtmProjector(Origin(origin[0], origin[1]))


def local_xy(projector, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """(N, 2) metric coordinates of WGS 84 points in the projector's frame."""
    from lanelet2.core import GPSPoint

    out = np.empty((len(lon), 2))
    for k, (x, y) in enumerate(zip(lon, lat)):
        p = projector.forward(GPSPoint(float(y), float(x), 0.0))
        out[k] = (p.x, p.y)
    return out


def write_lanelet2(graph: BoundaryGraph, path: str | Path, origin: tuple[float, float] | None = None) -> dict:
    """Write ``graph``'s boundaries as a Lanelet2 OSM file at ``path`` (and the projector info
    beside it); returns ``{"path", "projector_info", "origin": (lat, lon), "linestrings"}``."""
    import lanelet2
    from lanelet2.core import AttributeMap, LaneletMap, LineString3d, Point3d

    path = Path(path)
    if graph.crs is None:
        raise InputError(path, "a Lanelet2 map needs georeferenced boundaries (the prediction has no CRS)")
    check_finite_geometry(graph, path)
    frame = graph_frames(graph)[0]
    to_lonlat = to_wgs84(graph.crs)
    if origin is None:  # the middle of the boundaries (of the frame's corner when there are none)
        if len(frame):
            x0, y0, x1, y1 = frame.total_bounds
            cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        else:
            cx, cy = graph.transform * (0, 0)
        lon, lat = to_lonlat([cx], [cy])
        origin = (float(lat[0]), float(lon[0]))
    projector = projector_for(origin)
    lmap = LaneletMap()
    next_id = 1
    for row in frame.itertuples():
        coords = np.asarray(row.geometry.coords)[:, :2]
        lon, lat = to_lonlat(coords[:, 0], coords[:, 1])
        try:
            local = local_xy(projector, lon, lat)
        except Exception as exc:  # lanelet2 / pyproj raise their own types for points its zone cannot hold
            raise InputError(
                path,
                f"the boundaries (near {float(lat[0]):.4f}, {float(lon[0]):.4f}) lie too far from the origin "
                f"{origin[0]:.4f}, {origin[1]:.4f} for a UTM projector: give an --origin near them",
            ) from exc
        if not np.isfinite(local).all():
            raise InputError(
                path,
                f"the boundaries lie too far from the origin {origin[0]:.4f}, {origin[1]:.4f} for a UTM projector: "
                "give an --origin near them",
            )
        closed = len(coords) > 2 and np.allclose(coords[0], coords[-1], rtol=0, atol=1e-9)
        points = []
        for x, y in local[:-1] if closed else local:
            points.append(Point3d(next_id, float(x), float(y), 0.0))
            next_id += 1
        if closed:
            points.append(points[0])  # the same point: a closed linestring
        attributes = {"type": ROAD_BORDER, "boundary_id": str(int(row.boundary_id)), "length_m": f"{row.length_m:.3f}"}
        for name in ("confidence_mean", "confidence_min"):
            value = getattr(row, name)
            if math.isfinite(value):
                attributes["confidence" if name == "confidence_mean" else name] = f"{value:.4f}"
        lmap.add(LineString3d(next_id, points, AttributeMap(attributes)))
        next_id += 1
    with (
        naming_full_disk(path),
        atomic_path(path) as tmp,
    ):  # lanelet2 says a full disk as "Pugixml failed to write the map"
        lanelet2.io.write(str(tmp), lmap, projector)
    info = path.with_name(PROJECTOR_INFO)
    with naming_full_disk(info), atomic_path(info) as tmp:
        tmp.write_text(
            f"projector_type: LocalCartesianUTM\nvertical_datum: WGS84\nmap_origin:\n  latitude: {origin[0]:.10f}\n"
            f"  longitude: {origin[1]:.10f}\n  altitude: 0.0\n"
        )
    return {"path": path, "projector_info": info, "origin": origin, "linestrings": len(frame)}


def read_origin(info: str | Path) -> tuple[float, float]:
    """(lat, lon) from a ``map_projector_info.yaml`` written by :func:`write_lanelet2`."""
    values = {}
    for line in Path(info).read_text().splitlines():
        if ":" in line:
            key, _, value = line.strip().partition(":")
            values[key] = value.strip()
    try:
        return float(values["latitude"]), float(values["longitude"])
    except (KeyError, ValueError) as exc:
        raise InputError(info, "not a map projector info file (no map_origin latitude/longitude)") from exc
