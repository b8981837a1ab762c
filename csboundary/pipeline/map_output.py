"""Optional output of the stitched probability maps as a Cloud-Optimized GeoTIFF.

Windows arrive one patch at a time from the streaming pipeline; each writes its core (final, and
covering the mosaic exactly once) into a tiled scratch GeoTIFF, so memory stays bounded. On
``close`` GDAL's COG driver copies it (overviews, tiling, deflate) to the final name. Bands:
1 = keypoint, 2 = segmentation probability, stored as uint8 = round(255 p) (descriptions and
the ``scale`` tag say so) to keep city-sized maps small.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np
import rasterio
import rasterio.shutil
from rasterio.windows import Window

from csboundary.data.atomic import atomic_path
from csboundary.data.grid import Patch
from csboundary.data.raster import Mosaic

BANDS = ("keypoint_probability", "segmentation_probability")


class StitchedMapWriter(contextlib.AbstractContextManager):
    """Callable ``(patch, stitched maps)`` for :func:`predict_city`'s ``on_window``."""

    def __init__(self, path: str | Path, mosaic: Mosaic):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._scratch = self.path.with_name(f".{self.path.stem}.scratch-{os.getpid()}.tif")
        self._dst = rasterio.open(
            self._scratch, "w", driver="GTiff", width=mosaic.width, height=mosaic.height, count=len(BANDS), dtype="uint8",
            crs=mosaic.crs, transform=mosaic.transform, tiled=True, blockxsize=512, blockysize=512, compress="deflate", BIGTIFF="IF_SAFER",
        )

    def __call__(self, patch: Patch, maps: np.ndarray) -> None:
        rows, cols = patch.core_local.slices()
        values = np.clip(np.rint(maps[:, rows, cols] * 255), 0, 255).astype(np.uint8)
        core = patch.core
        self._dst.write(values, window=Window(core.col_off, core.row_off, core.width, core.height))

    def close(self) -> Path:
        """Finish: COG under the final name (only after a complete run)."""
        self._finish(complete=True)
        return self.path

    def __exit__(self, exc_type, exc, tb) -> None:
        self._finish(complete=exc_type is None)

    def _finish(self, complete: bool) -> None:
        if self._dst.closed:
            return
        try:
            if complete:
                for band, name in enumerate(BANDS, start=1):
                    self._dst.set_band_description(band, name)
                self._dst.update_tags(scale="probability = value / 255")
            self._dst.close()
            if complete:
                with atomic_path(self.path) as tmp:
                    rasterio.shutil.copy(self._scratch, tmp, driver="COG", compress="DEFLATE")
        finally:
            self._dst.close()
            self._scratch.unlink(missing_ok=True)
