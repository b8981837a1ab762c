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
(:mod:`csboundary.pipeline.prediction.run_store`): the same command run again after a crash, Ctrl-C or
SIGKILL continues where it stopped, and refuses a store left by other inputs, weights or
settings (``restart`` discards it). The store is removed once the outputs are in place. One
run at a time works in a folder, and a full disk keeps the finished work
(:mod:`csboundary.pipeline.prediction.run_folder`); met while writing an output, the error names
that file, of which nothing is left under its final name.
"""

from __future__ import annotations

import contextlib
import errno
import json
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable

import numpy as np
import rasterio

from csboundary.data.atomic import DiskFull, disk_full_file, naming_full_disk, staging_folder
from csboundary.data.footprint import union_area
from csboundary.data.grid import GridConfig, PatchGrid
from csboundary.data.model_view import mosaic_units
from csboundary.data.raster import Mosaic
from csboundary.data.units import GroundUnits
from csboundary.data.windows import pixel_to_world
from csboundary.graph.stitching import StitchConfig
from csboundary.models.patch_model import PatchModel
from csboundary.pipeline.outputs.map_output import write_maps_cog
from csboundary.pipeline.outputs.prediction_files import GraphWriter, read_prediction_graph
from csboundary.pipeline.prediction.city import CityRun, predict_city, run_here
from csboundary.pipeline.prediction.city_job import CPU, GDAL_ENV, STAGES, CityResult
from csboundary.pipeline.prediction.run_folder import run_folder
from csboundary.pipeline.prediction.run_store import RunStore
from csboundary.viz.overlay import overview_scale

ORANGE = (255, 140, 0)
OVERVIEW_PX = 2000  # longest side of overview.png
SUMMARY = "summary.json"
RUN_ONLY_SETTINGS = {
    "cluster",
    "precision_choice",
}  # how the work is spread or why a setting was chosen, not what it computes:
# a run may resume on another cluster
PIXEL_UNITS = GroundUnits((1.0, 1.0), "pixel")  # no CRS and no stated pixel size: lengths in pixels


def run_prediction(
    mosaic: Mosaic,
    model: PatchModel,
    out_dir: str | Path,
    *,
    write_maps: bool = False,
    batch_size: int = 1,
    grid_config: GridConfig = GridConfig(),
    stitch: StitchConfig = StitchConfig(),
    progress: bool = True,
    settings: dict | None = None,
    ground_truth=(),
    units: GroundUnits | None = None,
    restart: bool = False,
    executor: Callable[[CityRun], None] = run_here,
    threads: int | None = None,
    lanelet2: bool = False,
    keep_graphs: bool = True,
    **city,
) -> tuple[CityResult, dict]:
    """Predict ``mosaic`` and write every output into ``out_dir``; returns the result and the summary.

    ``ground_truth`` (world LineStrings), when given, is drawn in cyan under the prediction.
    ``units`` turns coordinates into metres (default: the mosaic CRS's; see
    :func:`csboundary.data.model_view.model_view`, which also gives them for CRS-less imagery).
    ``settings`` (JSON-ready) describe the model and how it is run: with the inputs, the grid and
    the code version they decide whether an unfinished run in ``out_dir`` is resumed or refused.
    The city graph is written block by block as it is made; ``keep_graphs`` also keeps it (and
    the patch graphs) in the result, for scoring: ``predict`` does not, so its memory does not
    grow with the city. ``city`` passes ``block`` and ``one_pass`` on to :func:`predict_city`.
    """
    if units is None:
        units = mosaic_units(mosaic) or PIXEL_UNITS
    manifest = run_manifest(mosaic, settings or {}, grid_config, batch_size, write_maps)
    try:
        with (
            run_folder(out_dir, manifest, restart) as (out, store),
            staging_folder(out) as stage,
            contextlib.ExitStack() as stack,
        ):
            (out / SUMMARY).unlink(missing_ok=True)  # a summary from an earlier run must not vouch for this one
            start = time.perf_counter()
            stack.enter_context(rasterio.Env(**GDAL_ENV))  # overviews read every tile too
            files = {
                "gpkg": stage / "boundaries.gpkg",
                "geojson": stage / "boundaries.geojson",
                "graph_json": stage / "graph.json",
            }
            crs = mosaic.crs.to_string() if mosaic.crs is not None else None
            writer = GraphWriter(files, crs, PatchGrid.for_mosaic(mosaic, grid_config).transform, units)
            stack.callback(writer.abort)
            result = predict_city(
                mosaic,
                model,
                grid_config=grid_config,
                stitch=stitch,
                batch_size=batch_size,
                progress=progress,
                store=store,
                write_cores=write_maps,
                executor=executor,
                threads=threads,
                overview_scale=overview_scale(mosaic.window, OVERVIEW_PX),
                writer=writer.add,
                keep_graphs=keep_graphs,
                **city,
            )
            written_at = time.perf_counter()
            counts = writer.close()
            rss_after_prediction = peak_rss_mb()
            files.update(write_pictures(mosaic, result, stage, files["gpkg"], ground_truth, store))
            if write_maps:
                files["maps"] = write_maps_cog(stage / "maps.tif", mosaic, result.grid, store)
            if lanelet2:
                from csboundary.pipeline.outputs.lanelet2_export import LANELET2_MAP, write_lanelet2

                graph = result.graph if keep_graphs else read_prediction_graph(files["graph_json"])
                written = write_lanelet2(graph, stage / LANELET2_MAP)
                files.update(lanelet2=written["path"], projector_info=written["projector_info"])
            seconds = dict(result.seconds, outputs=result.outputs_seconds + time.perf_counter() - written_at)
            seconds["total"] = time.perf_counter() - start
            summary = summarize(mosaic, result, seconds, files, settings or {}, units, counts)
            summary["peak_rss_mb"] = {"prediction": rss_after_prediction, "total": peak_rss_mb()}
            with naming_full_disk(stage / SUMMARY):
                (stage / SUMMARY).write_text(json.dumps(summary, indent=1) + "\n")
    except OSError as exc:  # a full disk while writing an output: the line names it
        named = full_output(exc, Path(out_dir))
        if named is None:
            raise
        raise named from exc
    return result, summary


def full_output(exc: OSError, out: Path) -> DiskFull | None:
    """A run that ended on a full disk while writing one of its outputs: the run folder's line
    (what of the run is kept, what to do) naming that output by its final name in ``out``
    instead of the folder; None for any other failure."""
    written = disk_full_file(exc)
    if exc.errno != errno.ENOSPC or written is None:
        return None
    return DiskFull(errno.ENOSPC, exc.strerror, str(out / Path(written.filename).name))


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
    return {
        "inputs": inputs,
        "settings": settings,
        "grid": [grid_config.core, grid_config.margin],
        "batch_size": batch_size,
        "write_maps": write_maps,
        "code_version": code_version(),
    }


def summarize(
    mosaic: Mosaic,
    result: CityResult,
    seconds: dict,
    files: dict,
    settings: dict,
    units: GroundUnits | None = None,
    counts: dict | None = None,
) -> dict:
    """Counts, timings and throughput of one run (JSON-ready); areas and lengths in true metres.
    ``counts`` are the writer's (:class:`~csboundary.pipeline.outputs.prediction_files.GraphWriter`); without
    them they are taken from ``result.graph``."""
    units = units or mosaic_units(mosaic) or PIXEL_UNITS
    if counts is None:
        counts = graph_counts(result.graph, units)
    area_km2 = (
        units.area_km2(mosaic.bounds) * union_area(mosaic.footprint) / mosaic.window.area
    )  # the imagery's, not its bounding box's
    n = result.n_patches
    kinds = counts["kinds"]
    return {
        "inputs": [
            str(Path(t.path).resolve()) for t in mosaic.tiles
        ],  # absolute: review and apply-review run from anywhere
        "crs": mosaic.crs.to_string() if mosaic.crs is not None else None,
        "length_unit": f"metre (from {units.unit_name}{', geodesic' if units.geographic else ''})",
        "mosaic_px": [mosaic.width, mosaic.height],
        "area_km2": round(area_km2, 6),
        "patches": n,
        "patches_without_imagery": result.patches_without_imagery,
        "grid": list(result.grid.shape),
        "counts": {
            "vertices": counts["vertices"],
            "edges": counts["edges"],
            "corner_edges": kinds.get("corner", 0),
            "skeleton_edges": kinds.get("skeleton", 0),  # filled in from the segmentation (graph/skeleton_fill.py)
            "attach_edges": kinds.get("attach", 0),  # a dangling end joined to the line ahead (graph/end_attachment.py)
            "boundaries": counts["boundaries"],
            "boundary_km": round(counts["boundary_m"] / 1000, 4),
            "patch_graph_edges": result.patch_graph_edges,
            "vertex_pairs_within_1px": result.close_vertex_pairs,
        },
        "seconds": {k: round(v, 3) for k, v in seconds.items() if not k.startswith(CPU)},
        "seconds_per_patch": {k: round(seconds[k] / n, 4) for k in (*STAGES, "total")},
        # the core seconds of the thread that ran each stage (the whole stage with one thread each)
        "core_seconds_per_patch": {k: round(seconds.get(CPU + k, 0.0) / n, 4) for k in STAGES},
        "km2_per_hour": round(area_km2 / (seconds["total"] / 3600), 3) if seconds["total"] > 0 else None,
        "map_store_peak_mb": round(result.map_bytes_peak / 2**20, 1),
        "work": result.work,
        "settings": settings,
        "files": {k: Path(v).name for k, v in files.items()},
    }


def graph_counts(graph, units: GroundUnits) -> dict:
    """What :class:`~csboundary.pipeline.outputs.prediction_files.GraphWriter` counts, of a whole graph."""
    from csboundary.pipeline.outputs.prediction_files import graph_frames

    kinds: dict[str, int] = {}
    for kind in graph.edge_kinds or ["normal"] * graph.n_edges:
        kinds[kind] = kinds.get(kind, 0) + 1
    boundaries, edges = graph_frames(graph, units)
    return {
        "vertices": graph.n_vertices,
        "edges": graph.n_edges,
        "kinds": kinds,
        "boundaries": len(boundaries),
        "boundary_m": float(edges["length_m"].sum()),
    }


def write_pictures(
    mosaic: Mosaic, result: CityResult, out: Path, gpkg: Path, ground_truth=(), store: RunStore | None = None
) -> dict[str, Path]:
    """``overview.png`` (whole mosaic, from the run's core thumbnails when ``store`` has them
    all) and ``detail.png`` (the patch core holding the most of the city graph), the prediction
    read back from ``gpkg`` a chunk at a time, so drawing a city's lines holds one chunk. The
    overview is PNG-encoded in a second thread while this one draws the detail (encoding leaves
    the GIL)."""
    from csboundary.viz.overlay import draw_world_lines, overview_from_thumbs, render_window, write_png

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


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and the noun, plural unless one: "1 patch", "4 patches", "2 vertices"."""
    return f"{n} {noun}" if n == 1 else f"{n} {plural or noun + ('es' if noun.endswith(('ch', 'sh', 's')) else 's')}"


def written_files(folder: Path) -> str:
    """The finished files of an output folder, by name (what a run wrote, for the user)."""
    return ", ".join(
        sorted(p.name + ("/" if p.is_dir() else "") for p in Path(folder).iterdir() if not p.name.startswith("."))
    )


def stage_table(summary: dict) -> str:
    """Seconds per patch for each stage, one line."""
    per = summary["seconds_per_patch"]
    parts = ", ".join(f"{k.replace('_', ' ')} {per[k]:.3f}" for k in STAGES)
    return (
        f"{counted(summary['patches'], 'patch')}, {summary['area_km2']:.3f} km2 in {summary['seconds']['total']:.1f} s "
        f"({summary['km2_per_hour']} km2/h); s/patch: {parts}"
    )


def peak_rss_mb() -> float:
    """This process's peak resident memory so far, in MB (Linux reports kB)."""
    import resource

    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)


def evaluate_run(
    result: CityResult,
    ground_truth,
    seed: int = 0,
    scales: tuple[str, ...] = ("patch", "city"),
    metres_per_px: float | None = None,
) -> dict[str, dict]:
    """Scores against ``ground_truth`` (world LineStrings) at the paper's two scales, those in
    ``scales``: ``patch`` (each patch's own graph on its core, averaged; Table I) and ``city``
    (the stitched graph as a whole; Table II). ``metres_per_px`` (the frame's pixel size) puts
    the city scale's review effort per km."""
    from csboundary.graph import BoundaryGraph
    from csboundary.metrics import evaluate
    from csboundary.pipeline.prediction.city import patch_scale_graph

    gt = BoundaryGraph.from_world_lines(list(ground_truth), result.grid.transform)
    score = {
        "patch": lambda: evaluate(patch_scale_graph(result), gt, scale="patch", grid=result.grid, seed=seed),
        "city": lambda: evaluate(
            result.graph,
            gt,
            scale="city",
            seed=seed,
            extent=(0, 0, result.grid.width, result.grid.height),
            metres_per_px=metres_per_px,
        ),
    }
    return {scale: score[scale]() for scale in scales}
