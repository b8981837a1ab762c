"""Any imagery as the model sees it: at the model's pixel size and in 8 bits, read on the fly.

The networks were trained on 8-bit imagery at 0.152 m per pixel. :func:`model_view` wraps a
:class:`~csboundary.data.raster.Mosaic` so that every window read is

* **resampled** to square pixels of the model's size in metres, whatever the input's pixel size
  (0.03-1 m), CRS units (metres, feet) or CRS kind: a geographic CRS (EPSG:4326) is resampled
  per axis with the metres per degree at the mosaic's centre, so pixels are square on the ground
  there (over a 20 km city the scale drifts by well under 1 %); coordinates stay in the input's
  CRS, so every output is written in it with no reprojection;
* **stretched** to 8 bits when the input is 16-bit, signed or floating point: per band, the 2nd
  and 98th percentiles of the valid pixels of a whole-mosaic overview map to 0 and 255 (one
  stretch for the whole mosaic, so patches agree); nodata, masked and NaN pixels are invalid.

Reads are windowed: a patch reads only the source pixels under it (plus a 2 px margin), so
memory does not grow with the input. 8-bit input at the model's pixel size is returned as is.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import cv2
import numpy as np
from affine import Affine

from csboundary.data.footprint import scaled
from csboundary.data.raster import Mosaic, WindowRead
from csboundary.data.units import MODEL_GSD, GroundUnits, geometric_mean, ground_units, pixel_size_m
from csboundary.data.windows import PixelWindow
from csboundary.errors import InputError, InputWarning

PIXEL_SIZE_RANGE_M = (0.03, 1.0)  # resampled outside this the imagery no longer shows curbs the model knows
RESAMPLE_TOLERANCE = 0.02  # within 2 % of the model's pixel size: used as it is
WARN_FACTOR = 1.25  # resampling by more than this (either way) is said in a warning
STRETCH_PERCENTILES = (2.0, 98.0)


@dataclass(frozen=True)
class BandStretch:
    """Per-band linear map of ``low`` -> 0 and ``high`` -> 255, clipped."""

    low: tuple[float, ...]
    high: tuple[float, ...]

    def apply(self, data: np.ndarray) -> np.ndarray:
        low = np.asarray(self.low, np.float32)[:, None, None]
        span = np.maximum(np.asarray(self.high, np.float32)[:, None, None] - low, 1e-6)
        out = (np.nan_to_num(data.astype(np.float32)) - low) * (255.0 / span)
        return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def fit_stretch(
    mosaic: Mosaic, percentiles: tuple[float, float] = STRETCH_PERCENTILES, side: int = 1024
) -> BandStretch:
    """The stretch of ``mosaic``'s valid pixels, from an overview at most ``side`` px wide; for
    groups of tiles kilometres apart, from an overview of each group, all of them holding
    about ``side`` squared pixels (an overview of their box would shrink each to a few pixels)."""
    parts = mosaic.footprint
    if parts == [mosaic.window]:
        scale = min(1.0, side / max(mosaic.width, mosaic.height))
    else:
        scale = min(1.0, side / math.sqrt(sum(p.area for p in parts)))
    reads = [mosaic.read(p, scale=scale) if scale < 1 else mosaic.read(p) for p in parts]
    pixels = np.concatenate([r.data[:, r.valid] for r in reads], axis=1).astype(np.float64)
    pixels = pixels[:, np.isfinite(pixels).all(axis=0)]
    if pixels.shape[1] == 0:
        raise InputError(mosaic.tiles[0].path, "no valid pixel (all nodata, masked or NaN)")
    low, high = np.percentile(pixels, percentiles, axis=1)
    return BandStretch(tuple(float(v) for v in low), tuple(float(max(h, lo + 1e-6)) for lo, h in zip(low, high)))


class ResampledMosaic(Mosaic):
    """A read-only view of ``source`` on a grid of ``unit_x`` x ``unit_y`` CRS units per pixel,
    optionally stretched to 8 bits. Geometry (``transform``, ``width``...) is the new grid's."""

    def __init__(self, source: Mosaic, unit_x: float, unit_y: float, stretch: BandStretch | None):
        width = max(1, int(math.floor(source.width * source.transform.a / unit_x + 1e-9)))
        height = max(1, int(math.floor(source.height * abs(source.transform.e) / unit_y + 1e-9)))
        t = source.transform
        transform = Affine(
            unit_x, 0.0, t.c, 0.0, math.copysign(unit_y, t.e), t.f
        )  # a CRS-less picture keeps its rows going down
        super().__init__(source.tiles, source.crs, transform, width, height)
        self.source = source
        self.factor = (unit_x / t.a, unit_y / abs(t.e))  # source pixels per view pixel
        self.stretch = stretch

    def read(self, window: PixelWindow, scale: float = 1.0) -> WindowRead:
        if scale != 1.0:
            return self._read_reduced(window, scale)
        fx, fy = self.factor
        pad = 2 + int(math.ceil(max(fx, fy)))
        c0, r0 = int(math.floor(window.col_off * fx)) - pad, int(math.floor(window.row_off * fy)) - pad
        c1, r1 = int(math.ceil(window.col_end * fx)) + pad, int(math.ceil(window.row_end * fy)) + pad
        src = self.source.read(PixelWindow(c0, r0, c1 - c0, r1 - r0))
        data = src.data.astype(np.float32)
        valid = src.valid.astype(np.float32)
        image = np.moveaxis(data, 0, -1)
        if fx > 1.05 or fy > 1.05:  # shrinking: low-pass first so fine texture does not alias
            image = cv2.GaussianBlur(image, (0, 0), sigmaX=max(0.5 * fx, 0.01), sigmaY=max(0.5 * fy, 0.01))
        # view pixel centre (col + 0.5) lies at source column (col + 0.5) * fx, i.e. index - 0.5
        matrix = np.array(
            [[fx, 0.0, (window.col_off + 0.5) * fx - 0.5 - c0], [0.0, fy, (window.row_off + 0.5) * fy - 0.5 - r0]],
            dtype=np.float64,
        )
        size = (window.width, window.height)
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        out = cv2.warpAffine(image, matrix, size, flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if out.ndim == 2:
            out = out[..., None]
        mask = (
            cv2.warpAffine(
                valid, matrix, size, flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT
            )
            > 0.5
        )
        out = np.moveaxis(out, -1, 0)
        if self.stretch is not None:
            pixels = self.stretch.apply(out)
        else:
            pixels = np.clip(np.rint(out), 0, 255).astype(np.uint8)
        pixels[:, ~mask] = 0
        return WindowRead(window, pixels, mask)

    @property
    def footprint(self) -> list[PixelWindow]:
        """The source's footprint on this grid (found once: samplers ask at every draw)."""
        found = getattr(self, "_view_footprint", None)
        if found is None:
            parts = self.source.footprint
            found = self._view_footprint = (
                [self.window] if parts == [self.source.window] else scaled(parts, *self.factor, self.window)
            )
        return found

    def may_have_data(self, window: PixelWindow) -> bool:
        fx, fy = self.factor
        pad = 2 + int(math.ceil(max(fx, fy)))
        c0, r0 = int(math.floor(window.col_off * fx)) - pad, int(math.floor(window.row_off * fy)) - pad
        c1, r1 = int(math.ceil(window.col_end * fx)) + pad, int(math.ceil(window.row_end * fy)) + pad
        return self.source.may_have_data(PixelWindow(c0, r0, c1 - c0, r1 - r0))

    def close(self) -> None:
        self.source.close()


class StretchedMosaic(Mosaic):
    """``source`` at its own pixel size, stretched to 8 bits."""

    def __init__(self, source: Mosaic, stretch: BandStretch):
        super().__init__(source.tiles, source.crs, source.transform, source.width, source.height)
        self.source, self.stretch = source, stretch

    def read(self, window: PixelWindow, scale: float = 1.0) -> WindowRead:
        raw = self.source.read(window, scale)
        pixels = self.stretch.apply(raw.data)
        pixels[:, ~raw.valid] = 0
        return WindowRead(raw.window, pixels, raw.valid)

    def may_have_data(self, window: PixelWindow) -> bool:
        return self.source.may_have_data(window)

    def close(self) -> None:
        self.source.close()


@dataclass(frozen=True)
class ModelInput:
    """What :func:`model_view` did: the view, its ground units and the input's pixel size."""

    mosaic: Mosaic
    units: GroundUnits
    source_pixel_m: tuple[float, float]
    resampled: bool
    stretch: BandStretch | None


def mosaic_units(mosaic: Mosaic, gsd: float | None = None) -> GroundUnits | None:
    """The ground units of the mosaic's CRS at its centre; without a CRS, those of pixels of
    ``gsd`` metres (None when that is not given either)."""
    if mosaic.crs is None:
        return ground_units(None, pixel_metres=gsd / abs(mosaic.transform.a)) if gsd else None
    centre = mosaic.pixel_to_world(mosaic.width / 2, mosaic.height / 2)
    return ground_units(mosaic.crs, (float(centre[0]), float(centre[1])))


def model_view(
    mosaic: Mosaic, gsd: float | None = None, model_gsd: float = MODEL_GSD, assume_model_gsd: bool = False
) -> ModelInput:
    """``mosaic`` as the model sees it (module doc). ``gsd`` gives the pixel size in metres of
    imagery without a CRS (and overrides nothing else); ``assume_model_gsd`` takes such imagery
    to be at the model's pixel size, with a warning (one image, as ``predict-patch`` reads it).
    Raises InputError for imagery without a usable scale or with a pixel size outside
    :data:`PIXEL_SIZE_RANGE_M`; warns when resampling by more than :data:`WARN_FACTOR`."""
    first = mosaic.tiles[0].path
    if mosaic.crs is None:
        if gsd is None and assume_model_gsd:
            warnings.warn(
                f"{first}: no CRS: its pixels are taken to be the model's {model_gsd:g} m (give --gsd otherwise)",
                InputWarning,
                stacklevel=2,
            )
            gsd = model_gsd * abs(mosaic.transform.a)
        if gsd is None:
            raise InputError(
                first, "has no CRS, so its pixel size is unknown: give --gsd (metres per pixel) to predict it"
            )
        units = mosaic_units(mosaic, gsd)
    else:
        if gsd is not None:
            warnings.warn(
                f"{first}: --gsd ignored: the CRS {mosaic.crs.to_string()} gives the pixel size",
                InputWarning,
                stacklevel=2,
            )
        units = mosaic_units(mosaic)
    pixel = pixel_size_m(units, mosaic.transform)
    size = geometric_mean(pixel)
    low, high = PIXEL_SIZE_RANGE_M
    if not (low <= size <= high):
        raise InputError(
            first,
            f"pixel size {size:.3g} m is outside {low:g}-{high:g} m: the model ({model_gsd:g} m) would not see curbs in it",
        )
    dtype = np.dtype(mosaic.tiles[0].dtype)
    stretch = None if dtype == np.uint8 else fit_stretch(mosaic)
    if stretch is not None:
        warnings.warn(
            f"{first}: {dtype} imagery stretched to 8 bits per band (2nd-98th percentile: "
            f"{', '.join(f'{lo:.4g}-{hi:.4g}' for lo, hi in zip(stretch.low, stretch.high))})",
            InputWarning,
            stacklevel=2,
        )
    needs_resample = max(abs(pixel[0] / model_gsd - 1), abs(pixel[1] / model_gsd - 1)) > RESAMPLE_TOLERANCE
    if needs_resample:
        factor = size / model_gsd
        if factor > WARN_FACTOR or factor < 1 / WARN_FACTOR:
            warnings.warn(
                f"{first}: pixel size {size:.3g} m resampled to the model's {model_gsd:g} m "
                f"({'up' if factor > 1 else 'down'}sampled "
                f"{max(factor, 1 / factor):.2f}x); accuracy drops the further the input is from {model_gsd:g} m",
                InputWarning,
                stacklevel=2,
            )
        view: Mosaic = ResampledMosaic(
            mosaic, model_gsd / units.metres_per_unit[0], model_gsd / units.metres_per_unit[1], stretch
        )
    elif stretch is not None:
        view = StretchedMosaic(mosaic, stretch)
    else:
        view = mosaic
    return ModelInput(view, units, pixel, needs_resample, stretch)
