"""Writing 4-band uint8 GeoTIFF tiles (the project's raster interchange format)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rasterio
from affine import Affine
from rasterio.enums import ColorInterp

from csboundary.data.atomic import atomic_path

BAND_NAMES = ("red", "green", "blue", "nir")


def write_geotiff(
    path: str | Path,
    image: np.ndarray,
    transform: Affine,
    crs: str | None,
    *,
    valid: np.ndarray | None = None,
    tags: dict[str, str] | None = None,
) -> Path:
    """Write ``image`` (bands, rows, cols) as a tiled, compressed GeoTIFF, atomically.

    ``valid`` (rows, cols) bool, when given, is stored as the dataset's internal mask so readers
    see the missing areas as nodata without reserving a pixel value.
    """
    image = np.asarray(image)
    if image.ndim != 3:
        raise ValueError(f"image must be (bands, rows, cols), got shape {image.shape}")
    bands, rows, cols = image.shape
    profile = {
        "driver": "GTiff",
        "width": cols,
        "height": rows,
        "count": bands,
        "dtype": image.dtype.name,
        "crs": crs,
        "transform": transform,
        "tiled": True,
        "blockxsize": 512,
        "blockysize": 512,
        "compress": "deflate",
        "zlevel": 1,
        "predictor": 2,
        "interleave": "pixel",
        "photometric": "MINISBLACK",  # band 4 is NIR: never let GDAL tag it as alpha
    }
    with atomic_path(path) as tmp:
        with rasterio.Env(GDAL_TIFF_INTERNAL_MASK=True):
            with rasterio.open(tmp, "w", **profile) as dst:
                dst.write(image)
                for band, name in enumerate(BAND_NAMES[:bands], start=1):
                    dst.set_band_description(band, name)
                if bands == 4:
                    dst.colorinterp = [ColorInterp.red, ColorInterp.green, ColorInterp.blue, ColorInterp.undefined]
                if tags:
                    dst.update_tags(**tags)
                if valid is not None:
                    dst.write_mask(np.where(valid, 255, 0).astype(np.uint8))
    return Path(path)
