"""The prediction job: imagery in, georeferenced road-boundary HD-map draft out.

``run_prediction`` wires the streaming city pipeline to its outputs, all in the input's CRS:

* ``boundaries.gpkg`` (layers ``road_boundaries``: LineStrings merged through degree-2 vertices,
  and ``edges``: one per graph edge) and ``boundaries.geojson``;
* ``graph.json`` (vertices in world and pixel coordinates, edges with confidence, kind, patch);
* ``overview.png`` (the whole mosaic, downsampled, prediction in orange over the patch grid) and
  ``detail.png`` (full resolution, the core of the patch with the most boundary);
* optionally ``maps.tif``: the stitched probability maps as a Cloud-Optimized GeoTIFF;
* optionally ``map.osm`` + ``map_projector_info.yaml``: the boundaries as a Lanelet2 map;
* ``summary.json``, written last: time per stage, seconds per patch, km2/h, counts, settings.

Every file is written under a temporary name and renamed when complete; ``summary.json`` existing
means the run finished. The work itself is kept in ``OUT/.csboundary-run/`` as it is done
(:mod:`csboundary.pipeline.run_store`): the same command run again after a crash, Ctrl-C or
SIGKILL continues where it stopped, and refuses a store left by other inputs, weights or
settings (``restart`` discards it). The store is removed once the outputs are in place.
"""

from __future__ import annotations

import contextlib
import json
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable

import numpy as np
import rasterio

from csboundary.data.atomic import check_output_dir, clear_stale_temporaries, staging_folder
from csboundary.data.grid import GridConfig
from csboundary.data.raster import Mosaic
from csboundary.data.model_view import mosaic_units
from csboundary.data.units import GroundUnits
from csboundary.graph.stitching import StitchConfig
from csboundary.pipeline.city import GDAL_ENV, STAGES, CityResult, CityRun, PatchModel, predict_city, run_here
from csboundary.pipeline.map_output import write_maps_cog
from csboundary.pipeline.run_store import STORE_DIR, RunStore
from csboundary.viz.overlay import overview_scale
from csboundary.pipeline.outputs import write_graph_outputs

ORANGE = (255, 140, 0)
OVERVIEW_PX = 2000  # longest side of overview.png
SUMMARY = "summary.json"
RUN_ONLY_SETTINGS = {"cluster"}  # how the work is spread, not what it computes: a run may resume on another cluster
PIXEL_UNITS = GroundUnits((1.0, 1.0), "pixel")  # no CRS and no stated pixel size: lengths in pixels


def run_prediction(mosaic: Mosaic, model: PatchModel, out_dir: str | Path, *, write_maps: bool = False, batch_size: int = 1,
                   grid_config: GridConfig = GridConfig(), stitch: StitchConfig = StitchConfig(), progress: bool = True,
                   settings: dict | None = None, ground_truth=(), units: GroundUnits | None = None, restart: bool = False,
                   executor: Callable[[CityRun], None] = run_here, threads: int | None = None,
                   lanelet2: bool = False) -> tuple[CityResult, dict]:
    """Predict ``mosaic`` and write every output into ``out_dir``; returns the result and the summary.

    ``ground_truth`` (world LineStrings), when given, is drawn in cyan under the prediction.
    ``units`` turns coordinates into metres (default: the mosaic CRS's; see
    :func:`csboundary.data.model_view.model_view`, which also gives them for CRS-less imagery).
    ``settings`` (JSON-ready) describe the model and how it is run: with the inputs, the grid and
    the code version they decide whether an unfinished run in ``out_dir`` is resumed or refused.
    """
    if units is None:
        units = mosaic_units(mosaic) or PIXEL_UNITS
    out = check_output_dir(out_dir, create=True)
    clear_stale_temporaries(out)  # what a run killed with SIGKILL left behind
    store = RunStore.open(out / STORE_DIR, run_manifest(mosaic, settings or {}, grid_config, batch_size, write_maps), restart=restart,
                           write_behind=True)
    (out / SUMMARY).unlink(missing_ok=True)  # a summary from an earlier run must not vouch for this one
    start = time.perf_counter()
    with staging_folder(out) as stage, contextlib.ExitStack() as stack:
        stack.enter_context(rasterio.Env(**GDAL_ENV))  # overviews read every tile too
        result = predict_city(mosaic, model, grid_config=grid_config, stitch=stitch, batch_size=batch_size, progress=progress,
                              store=store, write_cores=write_maps, executor=executor, threads=threads,
                              overview_scale=overview_scale(mosaic.window, OVERVIEW_PX))
        rss_after_prediction = peak_rss_mb()
        written_at = time.perf_counter()
        files = write_outputs(mosaic, result, stage, units, ground_truth, store)
        if write_maps:
            files["maps"] = write_maps_cog(stage / "maps.tif", mosaic, result.grid, store)
        if lanelet2:
            from csboundary.pipeline.lanelet2_export import LANELET2_MAP, write_lanelet2

            written = write_lanelet2(result.graph, stage / LANELET2_MAP)
            files.update(lanelet2=written["path"], projector_info=written["projector_info"])
        seconds = dict(result.seconds, outputs=time.perf_counter() - written_at)
        seconds["total"] = time.perf_counter() - start
        summary = summarize(mosaic, result, seconds, files, settings or {}, units)
        summary["peak_rss_mb"] = {"prediction": rss_after_prediction, "total": peak_rss_mb()}
        (stage / SUMMARY).write_text(json.dumps(summary, indent=1) + "\n")
    store.remove()
    return result, summary


def run_manifest(mosaic: Mosaic, settings: dict, grid_config: GridConfig, batch_size: int, write_maps: bool) -> dict:
    """What a run's stored work depends on: a resumed run must match it exactly. Input files are
    identified by path, size and modification time (hashing a city's imagery would take longer
    than a patch's work)."""
    from csboundary.models.checkpoint import code_version

    inputs = []
    for tile in mosaic.tiles:
        stat = Path(tile.path).stat()
        inputs.append([str(Path(tile.path).resolve()), stat.st_size, stat.st_mtime_ns])
    settings = {k: v for k, v in settings.items() if k not in RUN_ONLY_SETTINGS}
    return {"inputs": inputs, "settings": settings, "grid": [grid_config.core, grid_config.margin], "batch_size": batch_size,
            "write_maps": write_maps, "code_version": code_version()}


def summarize(mosaic: Mosaic, result: CityResult, seconds: dict, files: dict, settings: dict, units: GroundUnits | None = None) -> dict:
    """Counts, timings and throughput of one run (JSON-ready); areas and lengths in true metres."""
    graph = result.graph
    units = units or mosaic_units(mosaic) or PIXEL_UNITS
    area_km2 = units.area_km2(mosaic.bounds)
    boundary_m = sum(units.line_length_m(np.asarray(line.coords)) for line in graph.to_linestrings(world=True)) if graph.n_edges else 0.0
    n = result.n_patches
    kinds = graph.edge_kinds or []
    return {
        "inputs": [str(Path(t.path).resolve()) for t in mosaic.tiles],  # absolute: review and apply-review run from anywhere
        "crs": graph.crs,
        "length_unit": f"metre (from {units.unit_name}{', geodesic' if units.geographic else ''})",
        "mosaic_px": [mosaic.width, mosaic.height],
        "area_km2": round(area_km2, 6),
        "patches": n,
        "patches_without_imagery": result.patches_without_imagery,
        "grid": list(result.grid.shape),
        "counts": {
            "vertices": graph.n_vertices,
            "edges": graph.n_edges,
            "corner_edges": sum(k == "corner" for k in kinds),
            "skeleton_edges": sum(k == "skeleton" for k in kinds),  # filled in from the segmentation (graph/skeleton_fill.py)
            "attach_edges": sum(k == "attach" for k in kinds),  # a dangling end joined to the line ahead (graph/end_attachment.py)
            "boundary_km": round(boundary_m / 1000, 4),
            "patch_graph_edges": int(sum(g.n_edges for g in result.patch_graphs.values())),
            "vertex_pairs_within_1px": count_close_pairs(graph.vertices, 1.0),
        },
        "seconds": {k: round(v, 3) for k, v in seconds.items()},
        "seconds_per_patch": {k: round(seconds[k] / n, 4) for k in (*STAGES, "total")},
        "km2_per_hour": round(area_km2 / (seconds["total"] / 3600), 3) if seconds["total"] > 0 else None,
        "map_store_peak_mb": round(result.map_bytes_peak / 2**20, 1),
        "work": result.work,
        "settings": settings,
        "files": {k: Path(v).name for k, v in files.items()},
    }


def write_outputs(mosaic: Mosaic, result: CityResult, out: Path, units: GroundUnits, ground_truth=(), store: RunStore | None = None) -> dict[str, Path]:
    """The vector files (:func:`write_graph_outputs`) and the pictures (:func:`render_overlays`).
    The pictures are drawn first and PNG-encoded in a second thread while this one builds and
    writes the vector files: encoding leaves the GIL, so the two overlap (0.27 s instead of 0.40 s
    on the 16-patch test city); drawing too in that thread made both slower (0.46 s), as their
    Python work took turns on the GIL."""
    from csboundary.viz.overlay import write_png

    pictures = render_overlays(mosaic, result, ground_truth, store)
    with ThreadPoolExecutor(1, thread_name_prefix="csboundary-png") as encoder:
        encoded = {name: encoder.submit(write_png, out / f"{name}.png", rgb) for name, rgb in pictures.items()}
        files = write_graph_outputs(result.graph, out, units=units)
        files.update({name: future.result() for name, future in encoded.items()})
    return files


def render_overlays(mosaic: Mosaic, result: CityResult, ground_truth=(), store: RunStore | None = None) -> dict[str, np.ndarray]:
    """RGB pictures ``overview`` (whole mosaic; from the run's core thumbnails when ``store`` has
    them all) and ``detail`` (the patch core holding the most prediction)."""
    from csboundary.viz.overlay import overview_from_thumbs, render_window

    predicted = result.graph.to_linestrings(world=True)
    layers = [(predicted, ORANGE)]
    base = None if store is None else overview_from_thumbs(result.grid, overview_scale(mosaic.window, OVERVIEW_PX), store.load_thumb,
                                                           result.blank)
    overview = render_window(mosaic, mosaic.window, ground_truth, max_size=OVERVIEW_PX, grid=result.grid, layers=layers, base=base)
    busiest = max(result.patch_graphs, key=lambda i: result.patch_graphs[i].edge_lengths().sum(), default=(0, 0))
    detail = render_window(mosaic, result.grid.patch(*busiest).core, ground_truth, layers=layers)
    return {"overview": overview, "detail": detail}


def stage_table(summary: dict) -> str:
    """Seconds per patch for each stage, one line."""
    per = summary["seconds_per_patch"]
    parts = ", ".join(f"{k.replace('_', ' ')} {per[k]:.3f}" for k in STAGES)
    return (f"{summary['patches']} patches, {summary['area_km2']:.3f} km2 in {summary['seconds']['total']:.1f} s "
            f"({summary['km2_per_hour']} km2/h); s/patch: {parts}")


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, in MB (Linux reports kB)."""
    import resource

    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)


def count_close_pairs(vertices: np.ndarray, radius: float = 1.0) -> int:
    """Vertex pairs closer than ``radius`` (the stitched graph must have none)."""
    from scipy.spatial import cKDTree

    return len(cKDTree(vertices).query_pairs(radius - 1e-12)) if len(vertices) > 1 else 0


def evaluate_run(result: CityResult, ground_truth, seed: int = 0, scales: tuple[str, ...] = ("patch", "city")) -> dict[str, dict]:
    """Scores against ``ground_truth`` (world LineStrings) at the paper's two scales, those in
    ``scales``: ``patch`` (each patch's own graph on its core, averaged; Table I) and ``city``
    (the stitched graph as a whole; Table II)."""
    from csboundary.graph import BoundaryGraph
    from csboundary.metrics import evaluate
    from csboundary.pipeline.city import patch_scale_graph

    gt = BoundaryGraph.from_world_lines(list(ground_truth), result.grid.transform)
    score = {
        "patch": lambda: evaluate(patch_scale_graph(result), gt, scale="patch", grid=result.grid, seed=seed),
        "city": lambda: evaluate(result.graph, gt, scale="city", seed=seed, extent=(0, 0, result.grid.width, result.grid.height)),
    }
    return {scale: score[scale]() for scale in scales}
