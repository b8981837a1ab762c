"""The on-disk layout of a city: tiles, vector ground truth and a small metadata file.

::

    CITY/
      city.json            metadata (source, seed/split or tile id, CRS, GSD, tile list, notes)
      tiles/*.tif          4-band uint8 GeoTIFF tiles on one pixel grid
      ground_truth.gpkg    road boundaries as LineStrings, layer ``road_boundaries``

Both the synthetic city and imported Topo-boundary tiles are written in this layout, so every
later command takes a city directory (or plain rasters plus a ground-truth file).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from affine import Affine

from csboundary.data.atomic import atomic_path
from csboundary.data.units import geometric_mean, ground_units, pixel_size_m
from csboundary.errors import InputError

META_FILE = "city.json"
TILES_DIR = "tiles"
GROUND_TRUTH_FILE = "ground_truth.gpkg"


def tile_name(row: int, col: int) -> str:
    """File name of the tile at grid position (row, col) of a city."""
    return f"tile_r{row:02d}_c{col:02d}.tif"


def write_meta(city_dir: str | Path, meta: dict[str, Any]) -> Path:
    """Write ``city.json`` atomically (written last, so its presence marks a finished city)."""
    path = Path(city_dir) / META_FILE
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    return path


def begin_city(city_dir: str | Path) -> Path:
    """Prepare ``city_dir`` for (re)writing: drop an old ``city.json``, tiles and ground truth
    first, so an interrupted or smaller rewrite never mixes old and new files."""
    city_dir = Path(city_dir)
    (city_dir / META_FILE).unlink(missing_ok=True)
    (city_dir / GROUND_TRUTH_FILE).unlink(missing_ok=True)
    old_tiles = city_dir / TILES_DIR
    if old_tiles.is_dir():  # a smaller new city must not inherit tiles of the old one
        for tile in old_tiles.iterdir():
            if tile.is_file():
                tile.unlink()
    city_dir.mkdir(parents=True, exist_ok=True)
    return city_dir


def read_meta(city_dir: str | Path) -> dict[str, Any]:
    path = Path(city_dir) / META_FILE
    if not path.exists():
        raise InputError(city_dir, f"not a city directory (no {META_FILE}: an interrupted synth or import?)")
    try:
        meta = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"invalid JSON ({exc})") from exc
    if not isinstance(meta, dict):
        raise InputError(path, "invalid city metadata (not a JSON object)")
    return meta


def pixel_metres(meta: dict[str, Any]) -> float | None:
    """A city's pixel size in true metres from its ``city.json``: ``gsd`` is in the CRS's units
    (US feet for NYC tiles), so it is converted; ``pixel_m`` (written by make-city and
    import-masks) is taken as it is. None when unknown (a geographic CRS needs the ``transform``)."""
    if isinstance(meta.get("pixel_m"), (int, float)):
        return float(meta["pixel_m"])
    gsd, crs, transform = meta.get("gsd"), meta.get("crs"), meta.get("transform")
    if not isinstance(gsd, (int, float)) or not crs:
        return None
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    placed = isinstance(transform, list) and len(transform) == 6
    try:
        if not placed and CRS.from_user_input(crs).is_geographic:
            return None
        grid = Affine(*transform[:6]) if placed else Affine.scale(gsd)
        return geometric_mean(pixel_size_m(ground_units(crs, (grid.c, grid.f) if placed else None), grid))
    except CRSError:
        return None


def is_city_dir(path: str | Path) -> bool:
    return (Path(path) / META_FILE).is_file()


def ground_truth_path(city_dir: str | Path) -> Path:
    return Path(city_dir) / GROUND_TRUTH_FILE


def tiles_dir(city_dir: str | Path) -> Path:
    return Path(city_dir) / TILES_DIR
