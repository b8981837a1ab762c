"""Optional output of the stitched probability maps as a Cloud-Optimized GeoTIFF.

Each window's core (final, and covering the mosaic exactly once) is kept in the run store as
uint8 while the run goes (so an interrupted run keeps them too); at the end they are written into
a tiled scratch GeoTIFF one core at a time, so memory stays bounded, and GDAL's COG driver copies
it (overviews, tiling, deflate) to the final name. Tiles scattered over a city (a grid planned
over their footprint, data/grid.py) give a sparse tiled GeoTIFF instead: only the blocks under
the imagery are written, and no overview pass reads the empty box between them. Bands: 1 = keypoint, 2 = segmentation
probability, 3 = road-surface probability when the FPN has that head, stored as uint8 = round(255 p)
(descriptions and the ``scale`` tag say
so) to keep
city-sized maps small.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import rasterio
import rasterio.shutil
from rasterio.windows import Window

from csboundary.data.atomic import atomic_path, naming_full_disk
from csboundary.data.grid import PatchGrid
from csboundary.data.raster import Mosaic
from csboundary.pipeline.prediction.run_store import RunStore

BANDS = ("keypoint_probability", "segmentation_probability", "road_surface_probability")


def write_maps_cog(path: str | Path, mosaic: Mosaic, grid: PatchGrid, store: RunStore) -> Path:
    """``maps.tif`` from the stored cores of every patch (written only when complete)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    bands = BANDS[: min(len(BANDS), store.channels or 2)]
    scratch = path.with_name(f".{path.stem}.scratch-{os.getpid()}.tif")
    try:  # GDAL says a full disk as "Write failed" or "Write error at scanline": named as such
        with (
            naming_full_disk(path),
            rasterio.open(
                scratch,
                "w",
                driver="GTiff",
                width=mosaic.width,
                height=mosaic.height,
                count=len(bands),
                dtype="uint8",
                crs=mosaic.crs,
                transform=mosaic.transform,
                tiled=True,
                blockxsize=512,
                blockysize=512,
                compress="deflate",
                BIGTIFF="IF_SAFER",
                SPARSE_OK=grid.planned is not None,
            ) as dst,
        ):
            for patch in grid:
                core = patch.core
                values = store.load_core(patch.index)
                if values is None:  # all zero: no imagery near this core
                    values = np.zeros((len(bands), core.height, core.width), np.uint8)
                dst.write(values[: len(bands)], window=Window(core.col_off, core.row_off, core.width, core.height))
            for band, name in enumerate(bands, start=1):
                dst.set_band_description(band, name)
            dst.update_tags(scale="probability = value / 255")
        with naming_full_disk(path), atomic_path(path) as tmp:
            if grid.planned is None:
                rasterio.shutil.copy(scratch, tmp, driver="COG", compress="DEFLATE")
            else:
                os.replace(scratch, tmp)
    finally:
        scratch.unlink(missing_ok=True)
    return path
