"""Draw any window of a mosaic with road boundaries over it, as an RGB PNG.

Ground truth is drawn in cyan as in the paper's figures; areas without valid pixels (outside
the mosaic, missing tiles, nodata) are shown as a dark checkerboard so they are not mistaken
for imagery.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable, Sequence

import cv2
import numpy as np
from shapely.geometry import LineString, box

from csboundary.data.atomic import atomic_path
from csboundary.data.grid import Patch, PatchGrid
from csboundary.data.raster import Mosaic, WindowRead, area_reduced
from csboundary.data.windows import PixelWindow, world_to_pixel

CYAN = (0, 255, 255)
GRID_CORE = (255, 80, 80)
GRID_EXPANDED = (255, 200, 0)


def to_display(data: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(4, h, w) bands + mask -> (h, w, 3) uint8 RGB, invalid pixels as a checkerboard."""
    rgb = np.ascontiguousarray(np.moveaxis(data[:3], 0, -1))
    if rgb.dtype != np.uint8:
        top = float(np.percentile(rgb[valid], 99.5)) if valid.any() else 1.0
        rgb = np.clip(rgb.astype(np.float32) / max(top, 1e-6) * 255, 0, 255).astype(np.uint8)
    if not valid.all():
        rows, cols = np.indices(valid.shape)
        checker = np.where(((rows // 16 + cols // 16) % 2) == 0, 40, 60).astype(np.uint8)
        rgb[~valid] = checker[~valid, None]
    return rgb


def draw_lines(rgb: np.ndarray, lines: Iterable[np.ndarray], colour, thickness: int) -> None:
    """Draw polylines given in (fractional) pixel coordinates of ``rgb``, in place."""
    pts = [np.round(np.asarray(line) * 8).astype(np.int32) for line in lines if len(line) >= 2]
    if pts:
        cv2.polylines(rgb, pts, False, colour, thickness, cv2.LINE_AA, shift=3)


def render_window(
    mosaic: Mosaic,
    window: PixelWindow,
    boundaries: Iterable[LineString] = (),
    *,
    max_size: int | None = None,
    grid: PatchGrid | None = None,
    colour=CYAN,
    layers: Sequence[tuple[Iterable[LineString], tuple]] = (),
    base: WindowRead | None = None,
) -> np.ndarray:
    """RGB picture of ``window`` with ``boundaries`` (world coordinates) drawn over it.

    ``max_size`` downsamples large windows (longest side) before the lines are drawn, so lines
    stay visible; ``grid`` adds the patch grid (cores red, expanded windows yellow); ``layers``
    are more (lines, colour) pairs drawn on top (e.g. a prediction over the ground truth);
    ``base`` is the window's pixels already reduced (:func:`overview_from_thumbs`), not read again.
    """
    scale = overview_scale(window, max_size)
    # read reduced in strips: a city overview never holds the full image
    read = base if base is not None else mosaic.read(window, scale=scale)
    rgb = to_display(read.data, read.valid)
    if grid is not None:
        for patch in grid:
            for w, c in ((patch.expanded, GRID_EXPANDED), (patch.core, GRID_CORE)):
                corners = np.array(
                    [
                        [w.col_off, w.row_off],
                        [w.col_end, w.row_off],
                        [w.col_end, w.row_end],
                        [w.col_off, w.row_end],
                        [w.col_off, w.row_off],
                    ],
                    float,
                )
                draw_lines(rgb, [(corners - [window.col_off, window.row_off]) * scale], c, 1)
    draw_world_lines(rgb, mosaic, window, boundaries, colour, max_size)
    for lines_world, layer_colour in layers:
        draw_world_lines(rgb, mosaic, window, lines_world, layer_colour, max_size)
    return rgb


def draw_world_lines(
    rgb: np.ndarray,
    mosaic: Mosaic,
    window: PixelWindow,
    lines_world: Iterable[LineString],
    colour,
    max_size: int | None = None,
) -> None:
    """Draw world LineStrings onto a picture :func:`render_window` made of ``window`` (same
    ``max_size``), in place; lines off the window are skipped."""
    scale = overview_scale(window, max_size)
    world_box = box(*_world_bounds(mosaic, window))
    out = []
    for line in lines_world:
        if not line.intersects(world_box):
            continue
        xy = np.asarray(line.coords)[:, :2]
        cols, rows = world_to_pixel(mosaic.transform, xy[:, 0], xy[:, 1])
        out.append(np.stack([(cols - window.col_off) * scale, (rows - window.row_off) * scale], axis=1))
    draw_lines(rgb, out, colour, 2 if scale > 0.5 else 1)


def overview_scale(window: PixelWindow, max_size: int | None) -> float:
    """The reduction that brings the longest side of ``window`` to ``max_size`` (1 if it fits)."""
    if max_size and max(window.width, window.height) > max_size:
        return max_size / max(window.width, window.height)
    return 1.0


def _reduced_span(start: int, end: int, scale: float) -> tuple[int, int]:
    return round(start * scale), round(end * scale)


def core_thumbnail(read: WindowRead, patch: Patch, scale: float) -> np.ndarray:
    """A patch core's pixels reduced by ``scale`` (area average), validity as the last band
    (0/1): its piece of the overview, cut on the same rounded rows and columns as
    :func:`overview_from_thumbs` places it."""
    core = patch.core
    rows, cols = patch.core_local.slices()
    x0, x1 = _reduced_span(core.col_off, core.col_end, scale)
    y0, y1 = _reduced_span(core.row_off, core.row_end, scale)
    if x1 <= x0 or y1 <= y0:
        return np.zeros((read.data.shape[0] + 1, y1 - y0, x1 - x0), read.data.dtype)
    pixels, valid = area_reduced(read.data[:, rows, cols], read.valid[rows, cols], x1 - x0, y1 - y0)
    return np.concatenate([pixels, valid[None].astype(pixels.dtype)])


def overview_from_thumbs(grid: PatchGrid, scale: float, load, blank=frozenset()) -> WindowRead | None:
    """The whole mosaic reduced by ``scale`` from every core's :func:`core_thumbnail`
    (``load(index)``), the ``blank`` cores (no imagery) left empty; None if one is missing."""
    height, width = max(1, round(grid.height * scale)), max(1, round(grid.width * scale))
    data = valid = None
    for patch in grid:
        if patch.index in blank:
            continue
        thumb = load(patch.index)
        if thumb is None:
            return None
        if data is None:
            data = np.zeros((thumb.shape[0] - 1, height, width), thumb.dtype)
            valid = np.zeros((height, width), bool)
        x0, x1 = _reduced_span(patch.core.col_off, patch.core.col_end, scale)
        y0, y1 = _reduced_span(patch.core.row_off, patch.core.row_end, scale)
        data[:, y0:y1, x0:x1] = thumb[:-1]
        valid[y0:y1, x0:x1] = thumb[-1] > 0
    if data is None:  # every core blank: nothing to draw from
        return None
    return WindowRead(PixelWindow(0, 0, grid.width, grid.height), data, valid)


def _world_bounds(mosaic: Mosaic, window: PixelWindow) -> tuple[float, float, float, float]:
    xs, ys = mosaic.pixel_to_world([window.col_off, window.col_end], [window.row_off, window.row_end])
    return float(min(xs)), float(min(ys)), float(max(xs)), float(max(ys))


def write_png(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an RGB array as PNG, atomically."""
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
            raise OSError(f"{path}: could not write PNG")
    return Path(path)
