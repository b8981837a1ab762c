"""The pictures of a prediction run: overview.png (the whole mosaic, the prediction in orange over
the patch grid) and detail.png (full resolution, the patch core holding the most boundary)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from csboundary.data.atomic import naming_full_disk
from csboundary.data.raster import Mosaic
from csboundary.data.windows import pixel_to_world
from csboundary.pipeline.prediction.city_job import CityResult
from csboundary.pipeline.prediction.run_store import RunStore
from csboundary.viz.overlay import draw_world_lines, overview_from_thumbs, overview_scale, render_window, write_png

ORANGE = (255, 140, 0)


OVERVIEW_PX = 2000  # longest side of overview.png


def write_pictures(
    mosaic: Mosaic, result: CityResult, out: Path, gpkg: Path, ground_truth=(), store: RunStore | None = None
) -> dict[str, Path]:
    """``overview.png`` (whole mosaic, from the run's core thumbnails when ``store`` has them
    all) and ``detail.png`` (the patch core holding the most of the city graph), the prediction
    read back from ``gpkg`` a chunk at a time, so drawing a city's lines holds one chunk. The
    overview is PNG-encoded in a second thread while this one draws the detail (encoding leaves
    the GIL)."""
    base = (
        None
        if store is None
        else overview_from_thumbs(
            result.grid, overview_scale(mosaic.window, OVERVIEW_PX), store.load_thumb, result.blank
        )
    )
    with ThreadPoolExecutor(1, thread_name_prefix="csboundary-png") as encoder:
        overview = render_window(mosaic, mosaic.window, ground_truth, max_size=OVERVIEW_PX, grid=result.grid, base=base)
        for lines in edge_lines_in_chunks(gpkg):
            draw_world_lines(overview, mosaic, mosaic.window, lines, ORANGE, max_size=OVERVIEW_PX)
        encoded = {"overview": encoder.submit(write_png, out / "overview.png", overview)}
        core = result.grid.patch(*result.busiest_core).core
        detail = render_window(mosaic, core, ground_truth)
        for lines in edge_lines_in_chunks(gpkg, bounds=window_bounds(mosaic, core)):
            draw_world_lines(detail, mosaic, core, lines, ORANGE)
        encoded["detail"] = encoder.submit(write_png, out / "detail.png", detail)
        written = {}
        for name, future in encoded.items():
            with naming_full_disk(out / f"{name}.png"):
                written[name] = future.result()
        return written


def edge_lines_in_chunks(gpkg: Path, bounds=None, chunk: int = 50_000):
    """The GeoPackage's edge lines (world): all of them ``chunk`` at a time, or those meeting ``bounds``."""
    import pyogrio

    from csboundary.pipeline.outputs.prediction_files import EDGES_LAYER

    if bounds is not None:
        yield list(pyogrio.read_dataframe(gpkg, layer=EDGES_LAYER, columns=[], bbox=bounds).geometry)
        return
    total = pyogrio.read_info(gpkg, layer=EDGES_LAYER)["features"]
    for skip in range(0, total, chunk):
        yield list(
            pyogrio.read_dataframe(gpkg, layer=EDGES_LAYER, columns=[], skip_features=skip, max_features=chunk).geometry
        )


def window_bounds(mosaic: Mosaic, window) -> tuple[float, float, float, float]:
    """World (minx, miny, maxx, maxy) of a pixel window of the mosaic."""
    xs, ys = pixel_to_world(
        mosaic.transform, np.array([window.col_off, window.col_end]), np.array([window.row_off, window.row_end])
    )
    return float(min(xs)), float(min(ys)), float(max(xs)), float(max(ys))
