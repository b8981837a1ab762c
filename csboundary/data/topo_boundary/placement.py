"""Where a tile lies on the map: the georeference its patch files carry, or else the one its tile
id implies (an inference, see :func:`tile_origin_ft`), or else pixel coordinates in feet.

Pure functions of patches and tile ids (nothing is read or written), so the placement rules
can be tested on their own.
"""

from __future__ import annotations

import math
import re

from affine import Affine

from csboundary.data.topo_boundary.files import PATCH_SIZE, SPLITS, Patch
from csboundary.errors import InputError

FALLBACK_CRS = "EPSG:2263"  # NY State Plane Long Island, US survey feet: the NYC orthophotos' CRS
FALLBACK_GSD = 0.5  # US ft per pixel of the 2016 NYC orthophotos
GRID_FT = 2500.0  # NYC orthophoto tiles: 5000 px at 0.5 ft


def fallback_transform(gsd: float = FALLBACK_GSD) -> Affine:
    """Pixel coordinates scaled to feet, tile top-left at (0, 0), y up (north-up like a real map)."""
    return Affine(gsd, 0.0, 0.0, 0.0, -gsd, 0.0)


def tile_georeference(patches: list[Patch], patch_size: int = PATCH_SIZE) -> tuple[Affine, str, bool]:
    """``(transform, crs, georeferenced)`` of the tile the ``patches`` belong to.

    Each georeferenced patch implies a tile origin (its own origin moved back by its block offset);
    they must all agree to a hundredth of a pixel, or the files do not form one tile.
    """
    geo = [p for p in patches if p.georeferenced]
    if not geo:
        return fallback_transform(), FALLBACK_CRS, False
    first = geo[0]
    bare = [p for p in patches if not p.georeferenced]
    if bare:
        raise InputError(bare[0].path, f"has no georeference, but {first.path} of the same tile has")
    ref = _tile_transform(first, patch_size)
    for patch in geo:
        t = patch.transform
        if t.b != 0 or t.d != 0 or t.a <= 0 or t.e >= 0:
            raise InputError(patch.path, "rotated or not north-up georeference is not supported")
        if patch.crs != first.crs:
            raise InputError(patch.path, f"CRS {patch.crs} differs from {first.crs} of {first.path}")
        tt = _tile_transform(patch, patch_size)
        tol = 0.01 * abs(ref.a)
        if not all(math.isclose(u, v, rel_tol=1e-9, abs_tol=tol) for u, v in zip(tt[:6], ref[:6])):
            raise InputError(
                patch.path,
                f"georeference puts the tile origin at ({tt.c:.3f}, {tt.f:.3f}), "
                f"but {first.path} puts it at ({ref.c:.3f}, {ref.f:.3f})",
            )
    return ref, first.crs.to_string(), True


def _tile_transform(patch: Patch, patch_size: int) -> Affine:
    return patch.transform @ Affine.translation(-patch.col * patch_size, -patch.row * patch_size)


def tile_origin_ft(tile_id: str, grid_ft: float = GRID_FT) -> tuple[float, float] | None:
    """South-west corner (easting, northing) in EPSG:2263 feet that a 6-digit tile id encodes.

    An inference from the benchmark's ids, not a documented fact: the first three digits read
    as easting / 1000 ft modulo 1000 (NYC spans 913,000-1,067,000 ft, so 000-499 means
    1,000,000 more), the last three as northing / 1000 ft, and tiles lie on a 2,500 ft grid, so
    the corner is the one grid line within the id's 1,000 ft. None when no grid line is (the id
    does not follow the pattern). ``import-topo-boundary --no-placement`` turns it off.
    """
    if not re.fullmatch(r"\d{6}", tile_id):
        return None
    east3, north3 = int(tile_id[:3]), int(tile_id[3:])
    out = []
    for low in (east3 * 1000.0 + (1_000_000.0 if east3 < 500 else 0.0), north3 * 1000.0):
        corner = math.ceil(low / grid_ft) * grid_ft
        if corner >= low + 1000.0:
            return None
        out.append(corner)
    return out[0], out[1]


def placed_transform(tile_id: str, gsd_ft: float = FALLBACK_GSD, size_px: int = PATCH_SIZE * SPLITS) -> Affine | None:
    """The tile's north-up transform in EPSG:2263 from :func:`tile_origin_ft` (None if it has none)."""
    corner = tile_origin_ft(tile_id)
    if corner is None:
        return None
    return Affine(gsd_ft, 0.0, corner[0], 0.0, -gsd_ft, corner[1] + size_px * gsd_ft)
