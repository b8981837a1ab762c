"""Open one GeoTIFF, several tiles, or a directory of tiles as one mosaic and read any window.

Tiles must share one CRS, one pixel size and one pixel grid (tile origins a whole number of
pixels apart); windows may cross tile borders and the mosaic's edge, and come back padded with
zeros and a validity mask. Every problem with an input file is an :class:`InputError` naming it.
What each file holds on its own (georeference, bands, valid pixels, written blocks) is read by
:mod:`csboundary.data.raster_files`, which also states the band rule: bands 1-4 are R, G, B,
NIR, and a 3-band RGB file gets the green band as its NIR.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import cv2
import numpy as np
import rasterio
from affine import Affine
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError
from rasterio.windows import Window

from csboundary.data.footprint import footprint
from csboundary.data.raster_files import BANDS, NIR_FILL_BAND, find_rasters, inspect_raster, valid_mask, written_blocks
from csboundary.data.windows import PixelWindow, pixel_to_world, window_from_bounds, world_to_pixel
from csboundary.errors import InputError, InputWarning

MAX_OPEN_FILES = 64  # open tiles kept at once (Linux allows 1024 files per process, macOS 256)


@dataclass(frozen=True)
class Tile:
    """One source file placed in the mosaic."""

    path: Path
    window: PixelWindow  # where the file lies, in mosaic pixels
    band_count: int
    dtype: str
    alpha: bool = False  # band 4 is a true alpha mask (0/255 only), not NIR: RGB + validity


@dataclass
class WindowRead:
    """Pixels of a window: ``data`` (4, h, w) with invalid pixels set to 0, ``valid`` (h, w) bool."""

    window: PixelWindow
    data: np.ndarray
    valid: np.ndarray


def area_reduced(data: np.ndarray, valid: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(B, h, w) bands and their (h, w) validity reduced to ``height`` x ``width`` by area
    average: (B, height, width) bands of the same dtype, and valid where at least half the area
    was. Each band is resized on its own, straight from its (possibly strided) plane: OpenCV's
    multi-channel resize needs a pixel-interleaved copy, which took 15x the resizing itself."""
    pixels = np.stack([cv2.resize(band, (width, height), interpolation=cv2.INTER_AREA) for band in data])
    kept = cv2.resize(valid.astype(np.float32), (width, height), interpolation=cv2.INTER_AREA) >= 0.5
    return pixels.reshape(len(data), height, width), kept.reshape(height, width)


class Mosaic:
    """Several aligned raster tiles behaving as one north-up image with one affine transform."""

    def __init__(self, tiles: list[Tile], crs, transform: Affine, width: int, height: int):
        self.tiles = tiles
        self.crs = crs
        self.transform = transform
        self.width = width
        self.height = height
        self._handles: OrderedDict[Path, rasterio.DatasetReader] = OrderedDict()  # least recently used first
        self._lock = threading.RLock()  # a prefetching thread and the main thread share the open files
        self.max_open = MAX_OPEN_FILES
        self._coverage: dict[Path, tuple | None] = {}  # written blocks per tile, found on first use
        self._boxes = np.array(
            [[t.window.col_off, t.window.row_off, t.window.col_end, t.window.row_end] for t in tiles], dtype=np.int64
        ).reshape(-1, 4)

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def open(cls, source: str | Path | Sequence[str | Path]) -> "Mosaic":
        """Open and validate every raster in ``source`` (file, list of files, or directory)."""
        paths = find_rasters(source)
        with rasterio.Env(
            GDAL_DISABLE_READDIR_ON_OPEN="TRUE"
        ):  # no folder listing per tile: side-cars are probed one by one
            infos = [(p, *inspect_raster(p)) for p in paths]
        first = infos[0]
        for path, crs, transform, count, dtype, width, height, alpha in infos:
            if width == 0 or height == 0:
                raise InputError(path, "empty image (0 pixels)")
            if count < 3:
                raise InputError(path, f"has {count} band(s); need 4 (R, G, B, NIR) or at least 3 (R, G, B)")
            if count == 3 or alpha:
                what = "RGB + alpha input (band 4 holds only 0/255)" if alpha else "3-band RGB input"
                warnings.warn(f"{path}: {what}; NIR is filled with the green band", InputWarning, stacklevel=2)
            elif count > BANDS:
                warnings.warn(f"{path}: {count} bands; using bands 1-4 as R, G, B, NIR", InputWarning, stacklevel=2)
            if transform.b != 0 or transform.d != 0 or transform.a <= 0 or transform.e >= 0:
                if not (crs is None and transform == Affine.identity()):
                    raise InputError(path, "rotated or not north-up georeference is not supported")
            if (crs is None) != (first[1] is None) or (crs is not None and crs != first[1]):
                raise InputError(path, f"CRS {crs} differs from {first[1]} of {first[0]}")
            if not (
                math.isclose(transform.a, first[2].a, rel_tol=1e-9)
                and math.isclose(abs(transform.e), abs(first[2].e), rel_tol=1e-9)
            ):
                raise InputError(
                    path,
                    f"pixel size {transform.a:g}x{abs(transform.e):g} differs from {first[2].a:g}x{abs(first[2].e):g} of "
                    f"{first[0]}",
                )
            if dtype != first[4]:
                raise InputError(path, f"data type {dtype} differs from {first[4]} of {first[0]}")
        crs = first[1]
        if crs is None:
            if len(infos) > 1 and all(i[2] == Affine.identity() for i in infos):
                raise InputError(paths[1], "no CRS and no georeference: tiles cannot be placed in one mosaic")
            if first[2] == Affine.identity():
                warnings.warn(
                    f"{first[0]}: no CRS and no georeference; working in pixel coordinates", InputWarning, stacklevel=2
                )
            else:
                warnings.warn(
                    f"{first[0]}: no CRS; coordinates follow the file's geotransform, in unknown units",
                    InputWarning,
                    stacklevel=2,
                )

        res_x, res_y = first[2].a, first[2].e
        west = min(i[2].c for i in infos)
        north = max(i[2].f for i in infos) if res_y < 0 else min(i[2].f for i in infos)
        tiles = []
        for path, _crs, transform, count, dtype, width, height, alpha in infos:
            # Judge alignment against the first tile, not the westmost/northmost origin: otherwise a
            # misaligned tile lying west or north of the others gets the *aligned* tiles blamed.
            dcol = (transform.c - first[2].c) / res_x
            drow = (transform.f - first[2].f) / res_y
            if abs(dcol - round(dcol)) > 1e-6 or abs(drow - round(drow)) > 1e-6:
                raise InputError(
                    path, f"not aligned to the pixel grid of {first[0]} (offset {dcol:.3f}, {drow:.3f} px)"
                )
            col = (transform.c - west) / res_x
            row = (transform.f - north) / res_y
            tiles.append(Tile(path, PixelWindow(int(round(col)), int(round(row)), width, height), count, dtype, alpha))
        width = max(t.window.col_end for t in tiles)
        height = max(t.window.row_end for t in tiles)
        transform = Affine(res_x, 0.0, west, 0.0, res_y, north)
        return cls(tiles, crs, transform, width, height)

    # -- geometry -------------------------------------------------------------------------------
    @property
    def window(self) -> PixelWindow:
        """The whole mosaic as a window."""
        return PixelWindow(0, 0, self.width, self.height)

    @property
    def footprint(self) -> list[PixelWindow]:
        """Where the imagery lies, in mosaic pixels: ``[self.window]`` when the files fill the
        mosaic, else each file's window (tiles scattered over a city: data/footprint.py)."""
        found = getattr(self, "_footprint", None)
        if found is None:
            found = self._footprint = footprint([t.window for t in self.tiles], self.window)
        return found

    @property
    def gsd(self) -> float:
        """Ground sampling distance: world units per pixel (x)."""
        return float(self.transform.a)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        xs, ys = pixel_to_world(self.transform, [0, self.width], [0, self.height])
        return float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max())

    def pixel_to_world(self, cols, rows):
        return pixel_to_world(self.transform, cols, rows)

    def world_to_pixel(self, xs, ys):
        return world_to_pixel(self.transform, xs, ys)

    def window_from_bounds(self, minx: float, miny: float, maxx: float, maxy: float) -> PixelWindow:
        return window_from_bounds(self.transform, minx, miny, maxx, maxy)

    def crop(self, window: PixelWindow) -> "Mosaic":
        """The part of the mosaic under ``window`` (mosaic pixels) as a mosaic of its own: the
        same files, placed relative to the window's corner (a district of a city)."""
        part = window.intersection(self.window)
        if part is None:
            raise ValueError(f"{window} does not meet the mosaic {self.window}")
        window = part
        tiles = [
            dataclasses.replace(
                t,
                window=PixelWindow(
                    t.window.col_off - window.col_off,
                    t.window.row_off - window.row_off,
                    t.window.width,
                    t.window.height,
                ),
            )
            for t in self._tiles_in(window)
        ]
        return Mosaic(
            tiles,
            self.crs,
            self.transform * Affine.translation(window.col_off, window.row_off),
            window.width,
            window.height,
        )

    # -- reading --------------------------------------------------------------------------------
    def read(self, window: PixelWindow, scale: float = 1.0) -> WindowRead:
        """Read ``window`` (mosaic pixels; may cross tiles and the mosaic edge) as 4 bands + mask.

        ``scale`` < 1 gives a reduced picture of ``round(scale * size)`` pixels (area average),
        read in strips so that even a whole city's overview never holds the full window.
        """
        with self._lock:
            return self._read_reduced(window, scale) if scale != 1.0 else self._read_full(window)

    def _read_full(self, window: PixelWindow) -> WindowRead:
        dtype = np.dtype(self.tiles[0].dtype)
        data = np.zeros((BANDS, window.height, window.width), dtype=dtype)
        valid = np.zeros((window.height, window.width), dtype=bool)
        for tile in self._tiles_in(window):
            part = tile.window.intersection(window)
            src = part.relative_to(tile.window)
            dst_rows, dst_cols = part.relative_to(window).slices()
            if not self._tile_may_have_data(tile, src):  # unwritten blocks of a sparse file: nodata, nothing to read
                continue
            pixels, mask = self._read_tile(tile, src)
            data[:, dst_rows, dst_cols] = np.where(mask, pixels, data[:, dst_rows, dst_cols])
            valid[dst_rows, dst_cols] |= mask  # where tiles overlap, a later tile's nodata keeps earlier pixels
        return WindowRead(window, data, valid)

    def _read_reduced(self, window: PixelWindow, scale: float, strip_pixels: int = 2**26) -> WindowRead:
        # Not GDAL's decimated reads: GDAL weights its average by band 4 as if it were alpha.
        # Strips of at most ``strip_pixels`` source pixels keep memory bounded for any width.
        strip_rows = max(1, min(1024, strip_pixels // max(window.width, 1)))
        height, width = max(1, round(window.height * scale)), max(1, round(window.width * scale))
        data = np.zeros((BANDS, height, width), dtype=np.dtype(self.tiles[0].dtype))
        valid = np.zeros((height, width), dtype=bool)
        for top in range(0, window.height, strip_rows):
            r0, r1 = round(top * scale), round(min(top + strip_rows, window.height) * scale)
            if r1 <= r0:
                continue
            part = PixelWindow(window.col_off, window.row_off + top, window.width, min(strip_rows, window.height - top))
            if next(iter(self._tiles_in(part)), None) is None:  # between tiles kilometres apart: nothing to read
                continue
            strip = self.read(part)
            data[:, r0:r1], valid[r0:r1] = area_reduced(strip.data, strip.valid, width, r1 - r0)
        return WindowRead(window, data, valid)

    def read_world(self, minx: float, miny: float, maxx: float, maxy: float) -> WindowRead:
        """Read the pixels covering a world rectangle (in the mosaic's CRS units)."""
        return self.read(self.window_from_bounds(minx, miny, maxx, maxy))

    def _tiles_in(self, window: PixelWindow) -> Iterable[Tile]:
        """Tiles overlapping ``window``: one vectorised test over every tile's box (2,049 NYC tiles
        take ~10 us), not a Python loop."""
        b = self._boxes
        if window.width <= 0 or window.height <= 0:
            return iter(())
        hit = (
            (b[:, 0] < window.col_end)
            & (b[:, 2] > window.col_off)
            & (b[:, 1] < window.row_end)
            & (b[:, 3] > window.row_off)
        )
        return (self.tiles[i] for i in np.flatnonzero(hit))

    def may_have_data(self, window: PixelWindow) -> bool:
        """False only when no tile holds a written block under ``window``: a sparse GeoTIFF (a
        city inside its bounding box) leaves the blocks outside the city unwritten, and such a
        window is known empty without reading (or decompressing) anything. True when unsure."""
        with self._lock:
            return any(
                self._tile_may_have_data(tile, tile.window.intersection(window).relative_to(tile.window))
                for tile in self._tiles_in(window)
            )

    def _tile_may_have_data(self, tile: Tile, part: PixelWindow) -> bool:
        """Whether a written block of ``tile`` lies under ``part`` (tile pixels); True when unsure."""
        coverage = self._coverage.get(tile.path, ...)
        if coverage is ...:
            coverage = self._coverage[tile.path] = written_blocks(self._handle(tile.path))
        if coverage is None:
            return True
        blocks, (block_rows, block_cols) = coverage
        rows = slice(part.row_off // block_rows, (part.row_end - 1) // block_rows + 1)
        cols = slice(part.col_off // block_cols, (part.col_end - 1) // block_cols + 1)
        return bool(blocks[rows, cols].any())

    def _read_tile(self, tile: Tile, src: PixelWindow) -> tuple[np.ndarray, np.ndarray]:
        ds = self._handle(tile.path)
        rio_window = Window(src.col_off, src.row_off, src.width, src.height)
        indexes = list(range(1, (3 if tile.alpha else min(tile.band_count, BANDS)) + 1))
        try:
            pixels = ds.read(indexes, window=rio_window)
            mask = ds.read(BANDS, window=rio_window) > 0 if tile.alpha else valid_mask(ds, rio_window)
        except RasterioIOError as exc:
            raise InputError(tile.path, f"unreadable pixels ({str(exc).splitlines()[0]})") from exc
        if pixels.shape[0] == 3:
            pixels = np.concatenate([pixels, pixels[NIR_FILL_BAND : NIR_FILL_BAND + 1]], axis=0)
        if np.issubdtype(pixels.dtype, np.floating):
            mask &= np.isfinite(pixels).all(axis=0)
        return pixels, mask

    def _handle(self, path: Path):
        ds = self._handles.get(path)
        if ds is not None:
            self._handles.move_to_end(path)
        else:
            while len(self._handles) >= self.max_open:  # a city of thousands of tiles stays under the open-file limit
                self._handles.popitem(last=False)[1].close()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", NotGeoreferencedWarning)
                    ds = rasterio.open(path)
            except RasterioIOError as exc:
                raise InputError(path, f"unreadable raster ({str(exc).splitlines()[0]})") from exc
            self._handles[path] = ds
        return ds

    def close(self) -> None:
        for ds in self._handles.values():
            ds.close()
        self._handles.clear()

    def __getstate__(self) -> dict:
        """Pickled without its open files (a Dask worker opens the tiles it reads itself)."""
        state = dict(self.__dict__)
        state["_handles"] = OrderedDict()
        del state["_lock"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state, _lock=threading.RLock())
        self.__dict__.setdefault("_coverage", {})

    def __enter__(self) -> "Mosaic":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Mosaic({len(self.tiles)} tiles, {self.width}x{self.height} px, crs={self.crs}, gsd={self.gsd:g})"
