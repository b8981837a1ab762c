"""Vector ground truth: road boundaries as LineStrings in a projected CRS, one GeoPackage per city.

This geometry is the single source for every training label and for evaluation.
"""

from __future__ import annotations

from pathlib import Path

import geopandas as gpd
import pyogrio
import shapely
from shapely.geometry import LineString, MultiLineString, box

from csboundary.data.atomic import atomic_path
from csboundary.errors import InputError

LAYER = "road_boundaries"
SURFACE_LAYER = "road_surface"  # optional: the roadway as polygons (synthetic cities), the FPN's surface target
COMPLETE_LAYER = "complete_area"  # optional: polygons where the boundaries are complete; elsewhere labels are unknown


def as_linestrings(geometry) -> list[LineString]:
    """Flatten any (multi)line or collection geometry into its non-empty LineStrings."""
    if geometry is None or geometry.is_empty:
        return []
    if isinstance(geometry, LineString):
        return [geometry] if geometry.length > 0 else []
    if isinstance(geometry, MultiLineString) or hasattr(geometry, "geoms"):
        out: list[LineString] = []
        for part in geometry.geoms:
            out.extend(as_linestrings(part))
        return out
    if geometry.geom_type in ("Polygon", "MultiPolygon", "LinearRing"):
        return as_linestrings(shapely.line_merge(geometry.boundary))
    return []


def write_ground_truth(
    path: str | Path,
    frame: gpd.GeoDataFrame,
    surface: gpd.GeoDataFrame | None = None,
    complete: gpd.GeoDataFrame | None = None,
) -> Path:
    """Write a GeoDataFrame of boundary LineStrings to a GeoPackage layer, atomically; with
    ``surface``, the roadway polygons as a second layer (``road_surface``); with ``complete``,
    the polygons where the boundaries are complete (``complete_area``)."""
    with atomic_path(path) as tmp:
        frame.to_file(tmp, layer=LAYER, driver="GPKG", engine="pyogrio")
        if surface is not None:
            surface.to_file(tmp, layer=SURFACE_LAYER, driver="GPKG", engine="pyogrio")
        if complete is not None:
            complete.to_file(tmp, layer=COMPLETE_LAYER, driver="GPKG", engine="pyogrio")
    return Path(path)


def read_road_surface(path: str | Path, crs=None) -> list | None:
    """The roadway polygons of a ground-truth GeoPackage (reprojected to ``crs``), or None when
    it has no ``road_surface`` layer (imported and user cities: only boundaries are known)."""
    return _read_polygons(path, SURFACE_LAYER, crs)


def read_complete_area(path: str | Path, crs=None) -> list | None:
    """The polygons of a ground-truth GeoPackage where its boundaries are complete (a reviewed
    prediction's marked areas, reprojected to ``crs``), or None when it has no
    ``complete_area`` layer: then the labels are complete everywhere."""
    return _read_polygons(path, COMPLETE_LAYER, crs)


def _read_polygons(path: str | Path, layer: str, crs=None) -> list | None:
    try:
        if layer not in [name for name, _ in pyogrio.list_layers(path)]:
            return None
        frame = gpd.read_file(path, layer=layer, engine="pyogrio")
    except Exception as exc:  # pyogrio raises several unrelated types for unreadable files
        raise InputError(path, f"not a readable vector file ({type(exc).__name__}: {exc})".splitlines()[0]) from exc
    if crs is not None and frame.crs is not None and frame.crs != crs:
        frame = frame.to_crs(crs)
    return [g for g in frame.geometry if g is not None and not g.is_empty]


def read_ground_truth(
    path: str | Path, crs=None, bbox: tuple[float, float, float, float] | None = None
) -> gpd.GeoDataFrame:
    """Read boundary LineStrings (GeoPackage, GeoJSON or anything OGR reads), exploded to parts,
    reprojected to ``crs`` when both it and the file's CRS are known; with ``bbox`` (in
    ``crs``) only the lines meeting it."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file not found")
    try:
        layers = [name for name, _ in pyogrio.list_layers(path)]
        layer = LAYER if LAYER in layers else None
        frame = gpd.read_file(path, layer=layer, engine="pyogrio")
    except Exception as exc:  # pyogrio raises several unrelated types for unreadable files
        raise InputError(path, f"not a readable vector file ({type(exc).__name__}: {exc})".splitlines()[0]) from exc
    frame = frame.explode(index_parts=False, ignore_index=True)
    if crs is not None and frame.crs is not None and frame.crs != crs:
        frame = frame.to_crs(crs)
    bad = ~frame.geometry.geom_type.isin(["LineString", "LinearRing"])
    if bad.any():
        raise InputError(path, f"{int(bad.sum())} geometries are not LineStrings (road boundaries are lines)")
    if bbox is not None:
        frame = frame[frame.intersects(box(*bbox))].reset_index(drop=True)
    return frame
