"""Integer pixel windows on a mosaic, and the pixel <-> world conversions of an affine transform.

Convention (rasterio's): pixel (col, row) = (0, 0) is the top-left corner of the top-left pixel;
the centre of pixel [r, c] is (c + 0.5, r + 0.5). Windows are half-open: [col_off, col_off+width).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from affine import Affine


@dataclass(frozen=True, order=True)
class PixelWindow:
    """A half-open integer rectangle of pixels; may extend beyond the raster it refers to."""

    col_off: int
    row_off: int
    width: int
    height: int

    def __post_init__(self) -> None:
        if self.width < 0 or self.height < 0:
            raise ValueError(f"window size must be >= 0, got {self.width}x{self.height}")

    @property
    def col_end(self) -> int:
        return self.col_off + self.width

    @property
    def row_end(self) -> int:
        return self.row_off + self.height

    @property
    def is_empty(self) -> bool:
        return self.width == 0 or self.height == 0

    @property
    def area(self) -> int:
        return self.width * self.height

    def intersection(self, other: "PixelWindow") -> "PixelWindow | None":
        """The common part of two windows, or None when they share no pixel."""
        c0, r0 = max(self.col_off, other.col_off), max(self.row_off, other.row_off)
        c1, r1 = min(self.col_end, other.col_end), min(self.row_end, other.row_end)
        if c1 <= c0 or r1 <= r0:
            return None
        return PixelWindow(c0, r0, c1 - c0, r1 - r0)

    def contains(self, other: "PixelWindow") -> bool:
        return (
            self.col_off <= other.col_off
            and self.row_off <= other.row_off
            and other.col_end <= self.col_end
            and other.row_end <= self.row_end
        )

    def relative_to(self, outer: "PixelWindow") -> "PixelWindow":
        """This window in the pixel coordinates of ``outer`` (whose top-left becomes (0, 0))."""
        return PixelWindow(self.col_off - outer.col_off, self.row_off - outer.row_off, self.width, self.height)

    def shifted(self, dcol: int, drow: int) -> "PixelWindow":
        return PixelWindow(self.col_off + dcol, self.row_off + drow, self.width, self.height)

    def slices(self) -> tuple[slice, slice]:
        """(row slice, col slice) for indexing an array whose (0, 0) is this window's frame origin."""
        return slice(self.row_off, self.row_end), slice(self.col_off, self.col_end)

    @classmethod
    def parse(cls, text: str) -> "PixelWindow":
        """Parse ``"col_off,row_off,width,height"``."""
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != 4:
            raise ValueError(f"expected col_off,row_off,width,height, got {text!r}")
        return cls(*(int(p) for p in parts))


def window_transform(transform: Affine, window: PixelWindow) -> Affine:
    """Affine transform of the raster cut out by ``window`` from a raster with ``transform``."""
    # Written out rather than ``transform * Affine.translation(...)``: affine 3 deprecates ``*`` for
    # matrix products (a PendingDeprecationWarning on every patch), and ``@`` needs affine >= 2.4.
    x, y = pixel_to_world(transform, window.col_off, window.row_off)
    return Affine(transform.a, transform.b, float(x), transform.d, transform.e, float(y))


def pixel_to_world(transform: Affine, cols, rows) -> tuple[np.ndarray, np.ndarray]:
    """Map continuous pixel coordinates to world coordinates (vectorised)."""
    cols = np.asarray(cols, dtype=float)
    rows = np.asarray(rows, dtype=float)
    a, b, c, d, e, f = transform.a, transform.b, transform.c, transform.d, transform.e, transform.f
    return a * cols + b * rows + c, d * cols + e * rows + f


def world_to_pixel(transform: Affine, xs, ys) -> tuple[np.ndarray, np.ndarray]:
    """Map world coordinates to continuous pixel coordinates (vectorised inverse of the transform)."""
    return pixel_to_world(~transform, xs, ys)


def window_from_bounds(transform: Affine, minx: float, miny: float, maxx: float, maxy: float) -> PixelWindow:
    """Smallest pixel window covering the world rectangle (north-up transforms)."""
    xs, ys = world_to_pixel(transform, [minx, maxx, minx, maxx], [miny, miny, maxy, maxy])
    # Tolerance in pixels for the round-off of the inverse transform: at UTM-sized coordinates and a
    # non-binary pixel size (e.g. 0.3 m) it reaches ~1e-8 px, so 1e-9 turned exact pixel edges into
    # an extra row/column.
    eps = 1e-6
    c0, c1 = math.floor(xs.min() + eps), math.ceil(xs.max() - eps)
    r0, r1 = math.floor(ys.min() + eps), math.ceil(ys.max() - eps)
    return PixelWindow(c0, r0, max(c1 - c0, 0), max(r1 - r0, 0))
