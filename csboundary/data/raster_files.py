"""One raster file on its own, before it joins a mosaic: find the files, read each one's
georeference and band layout, tell a true alpha band from NIR, which of its pixels are valid
and which of its blocks were ever written. :mod:`csboundary.data.raster` places the files in
one mosaic and reads windows across them. Every problem with a file is an :class:`InputError`
naming it.

Band rule: bands 1-4 are R, G, B, NIR. A 3-band RGB file is accepted with a warning and its NIR
is filled with the green band (:data:`NIR_FILL_BAND`): green is the visible band whose
reflectance tracks vegetation most closely, so the NIR-based cue "vegetation is bright" survives
in weakened form. Extra bands beyond 4 are ignored with a warning.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Sequence

import numpy as np
import rasterio
from affine import Affine
from rasterio.enums import ColorInterp, MaskFlags
from rasterio.errors import NodataShadowWarning, NotGeoreferencedWarning, RasterBlockError, RasterioIOError
from rasterio.windows import Window

from csboundary.errors import InputError

BANDS = 4
NIR_FILL_BAND = 1  # 0-based index of the band copied into NIR for 3-band input (green)
RASTER_SUFFIXES = (".tif", ".tiff", ".vrt", ".jp2", ".img")


def find_rasters(source: str | Path | Sequence[str | Path]) -> list[Path]:
    """Expand a file, a list of files, or a directory (searched recursively) into raster paths."""
    if isinstance(source, (str, Path)):
        source = [source]
    paths: list[Path] = []
    for item in source:
        item = Path(item)
        if item.is_dir():
            found = sorted(
                p for p in item.rglob("*") if p.suffix.lower() in RASTER_SUFFIXES and not p.name.startswith(".")
            )
            if not found:
                raise InputError(item, "directory holds no raster files (*.tif, *.tiff, *.vrt)")
            paths.extend(found)
        elif item.exists():
            paths.append(item)
        else:
            raise InputError(item, "file not found")
    if not paths:
        raise InputError("<input>", "no input rasters given")
    return paths


def inspect_raster(path: Path) -> tuple[object, Affine, int, str, int, int, bool]:
    """Open ``path`` just long enough to read its georeference, or raise a one-line InputError."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as ds:
                return ds.crs, ds.transform, ds.count, ds.dtypes[0], ds.width, ds.height, true_alpha(ds)
    except RasterioIOError as exc:
        text = str(exc)
        if "not recognized" in text or "not a supported" in text.lower():
            raise InputError(path, "not a raster (GDAL does not recognise the format)") from exc
        raise InputError(path, f"unreadable raster ({text.splitlines()[0]})") from exc


def true_alpha(ds) -> bool:
    """Is band 4 a real alpha mask? GDAL labels band 4 of most 4-band files alpha (see
    :func:`valid_mask`), so the label alone proves nothing; a band 4 holding only 0 and 255 in an
    overview of the file (an NIR band never does) is taken to be transparency. Remembered per
    file version: the overview of a huge file takes a second, and a run opens its inputs twice."""
    if ds.count != BANDS or ds.colorinterp[BANDS - 1] != ColorInterp.alpha or ds.width == 0 or ds.height == 0:
        return False
    try:
        stat = Path(ds.name).stat()
        key = (str(Path(ds.name).resolve()), stat.st_size, stat.st_mtime_ns)
    except OSError:
        key = None
    if key is not None and key in _ALPHA_SEEN:
        return _ALPHA_SEEN[key]
    side = (min(256, ds.height), min(256, ds.width))
    values = np.unique(ds.read(BANDS, out_shape=side, resampling=rasterio.enums.Resampling.nearest))
    alpha = bool(set(values.tolist()) <= {0, 255} and 255 in values)
    if key is not None:
        _ALPHA_SEEN[key] = alpha
    return alpha


_ALPHA_SEEN: dict[tuple, bool] = {}  # (file, size, mtime) -> whether band 4 is a true alpha mask


def valid_mask(ds, window: Window) -> np.ndarray:
    """Validity of ``window``'s pixels from the file's mask, nodata value or alpha band.

    GDAL flags band 4 of a 4-band uint8 GeoTIFF as alpha by default (rasterio and ``gdal_translate``
    write RGBA unless told otherwise), so ``dataset_mask`` would turn every pixel whose NIR is 0
    invalid. By the band rule band 4 is NIR, never transparency, so a mask derived from an alpha
    band among bands 1-4 is ignored. Internal masks (.msk / GDAL_TIFF_INTERNAL_MASK) and nodata
    values are honoured.
    """
    flags = ds.mask_flag_enums[0]
    if MaskFlags.alpha in flags and ColorInterp.alpha in ds.colorinterp[:BANDS]:
        return np.ones((int(window.height), int(window.width)), dtype=bool)
    with warnings.catch_warnings():
        # "nodata shadows the alpha band": exactly what we want, since band 4 is NIR.
        warnings.simplefilter("ignore", NodataShadowWarning)
        return ds.dataset_mask(window=window) > 0


MAX_COVERAGE_BLOCKS = 10**6  # a file with more blocks than this is not checked block by block (taken as covered)


def written_blocks(ds) -> tuple[np.ndarray, tuple[int, int]] | None:
    """Which blocks of a tiled or striped GeoTIFF were ever written, from the block offsets and
    byte counts (no pixel is read): ((rows, cols) bool, block shape), or None when that cannot be
    known (not a GeoTIFF, too many blocks). A block of any band that was written counts. A file
    cut short (a block reaching past its end) is an InputError, found before any work."""
    if ds.driver != "GTiff":
        return None
    block_rows, block_cols = ds.block_shapes[0]
    rows, cols = -(-ds.height // block_rows), -(-ds.width // block_cols)
    if rows * cols > MAX_COVERAGE_BLOCKS:
        return None
    bands = [1] if ds.interleaving is None or ds.interleaving.name == "pixel" else list(range(1, ds.count + 1))
    out = np.zeros((rows, cols), bool)
    end = 0
    for i in range(rows):
        for j in range(cols):
            for band in bands:
                try:
                    size = ds.block_size(band, i, j)
                    offset = int(ds.get_tag_item(f"BLOCK_OFFSET_{j}_{i}", "TIFF", bidx=band) or 0)
                except RasterBlockError:  # offset 0: a block never written (a sparse file)
                    continue
                except Exception:  # anything else: do not guess
                    return None
                if size > 0:
                    out[i, j] = True
                    end = max(end, offset + size)
    length = Path(ds.name).stat().st_size if Path(ds.name).exists() else None
    if length is not None and end > length:
        raise InputError(ds.name, f"truncated: its pixel blocks reach byte {end:,} of a {length:,}-byte file")
    return out, (block_rows, block_cols)
