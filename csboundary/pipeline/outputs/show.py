"""Pictures of the inputs for a person to check: a window of the imagery with the road
boundaries over it, or one patch with its training labels (what ``csboundary show`` draws)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import shapely

from csboundary.data.grid import GridConfig, Patch, PatchGrid
from csboundary.data.raster import Mosaic
from csboundary.data.windows import PixelWindow
from csboundary.errors import InputError, InputWarning
from csboundary.graph import BoundaryGraph
from csboundary.labels.writer import MANIFEST, PATCH_DIR, load_patch_arrays, patch_stem
from csboundary.viz.labels import draw_patch_labels
from csboundary.viz.overlay import render_window, to_display


def labels_grid(labels_dir: str | Path) -> GridConfig:
    """The patch grid a ``csboundary labels`` folder was written with."""
    manifest = Path(labels_dir) / MANIFEST
    if not manifest.exists():
        raise InputError(labels_dir, f"not a labels folder (no {MANIFEST})")
    return GridConfig(**json.loads(manifest.read_text())["config"]["grid"])


def patch_of(mosaic: Mosaic, row: int, col: int, grid_config: GridConfig = GridConfig()):
    """Patch (row, col) of the mosaic's grid; ValueError naming the grid's size if it has none."""
    grid = PatchGrid(mosaic.width, mosaic.height, mosaic.transform, grid_config)
    if (row, col) not in grid:
        raise ValueError(f"patch {row},{col} is outside the {grid.n_rows}x{grid.n_cols} grid")
    return grid.patch(row, col)


def render_patch_labels(mosaic: Mosaic, labels_dir: str | Path, patch: Patch) -> tuple[np.ndarray, BoundaryGraph]:
    """(h, w, 3) picture of ``patch``'s expanded window (a patch of the labels' grid, see
    :func:`labels_grid`) with its labels, and its label graph."""
    stem = patch_stem(patch)
    folder = Path(labels_dir) / PATCH_DIR
    arrays = load_patch_arrays(folder / f"{stem}.npz")
    graph = BoundaryGraph.read_json(folder / f"{stem}.graph.json")
    with mosaic:
        read = mosaic.read(patch.expanded)
    core = patch.core_local
    rgb = draw_patch_labels(
        to_display(read.data, read.valid), arrays, graph, (core.col_off, core.row_off, core.col_end, core.row_end)
    )
    return rgb, graph


def render_view(
    mosaic: Mosaic,
    lines: list,
    window: PixelWindow | None = None,
    bounds: tuple[float, float, float, float] | None = None,
    max_size: int = 2000,
    grid: bool = False,
    source: str | Path = "imagery",
    lines_source: str | Path | None = None,
) -> tuple[np.ndarray, PixelWindow]:
    """(h, w, 3) picture of a pixel ``window`` or world ``bounds`` (default: everything) with
    ``lines`` over it, downsampled to ``max_size``, and the window drawn (clipped to the
    imagery). InputError naming ``source`` (the imagery) when the window misses it; a warning
    naming ``lines_source`` when no line falls in it (wrong CRS?)."""
    with mosaic:
        win = (
            window
            if window is not None
            else mosaic.window_from_bounds(*bounds)
            if bounds is not None
            else mosaic.window
        )
        inside = win.intersection(mosaic.window)
        if inside is None or inside.is_empty:
            where = f" in {mosaic.crs.to_string()} coordinates" if bounds is not None and mosaic.crs is not None else ""
            raise InputError(
                source,
                f"the window{where} lies outside the imagery ({mosaic.width}x{mosaic.height} px, "
                f"bounds {tuple(round(b, 3) for b in mosaic.bounds)})",
            )
        if lines and not any_line_in(lines, mosaic, inside):
            warnings.warn(
                f"{lines_source or source}: none of the {len(lines)} boundaries lies in the window (wrong CRS, or a file "
                f"without one?)",
                InputWarning,
                stacklevel=2,
            )
        rgb = render_window(
            mosaic, inside, lines, max_size=max_size, grid=PatchGrid.for_mosaic(mosaic) if grid else None
        )
    return rgb, inside


def any_line_in(lines: list, mosaic: Mosaic, window: PixelWindow) -> bool:
    """Whether any of the world-coordinate ``lines`` meets the pixel ``window``."""
    x0, y1 = mosaic.pixel_to_world(window.col_off, window.row_off)
    x1, y0 = mosaic.pixel_to_world(window.col_end, window.row_end)
    box = shapely.box(min(x0, x1), min(y0, y1), max(x0, x1), max(y0, y1))
    return any(line.intersects(box) for line in lines)
