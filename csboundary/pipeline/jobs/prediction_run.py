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
from pathlib import Path
from typing import Callable

import rasterio

from csboundary.data.atomic import DiskFull, disk_full_file, naming_full_disk, staging_folder
from csboundary.data.grid import PatchGrid
from csboundary.data.model_view import mosaic_units
from csboundary.data.raster import Mosaic
from csboundary.data.units import GroundUnits
from csboundary.models.patch_model import PatchModel
from csboundary.pipeline.outputs.map_output import write_maps_cog
from csboundary.pipeline.outputs.pictures import OVERVIEW_PX, write_pictures
from csboundary.pipeline.outputs.prediction_files import GraphWriter
from csboundary.pipeline.outputs.prediction_reader import read_prediction_graph
from csboundary.pipeline.outputs.run_summary import PIXEL_UNITS, SUMMARY, peak_rss_mb, summarize
from csboundary.pipeline.prediction.city import CityRun, predict_city, run_here
from csboundary.pipeline.prediction.city_job import GDAL_ENV, CityResult
from csboundary.pipeline.prediction.options import PredictionOptions
from csboundary.pipeline.prediction.run_folder import run_folder
from csboundary.viz.overlay import overview_scale

# how the work is spread or why a setting was chosen, not what it computes: a run may resume on another cluster
RUN_ONLY_SETTINGS = {"cluster", "precision_choice"}


def run_prediction(
    mosaic: Mosaic,
    model: PatchModel,
    out_dir: str | Path,
    options: PredictionOptions = PredictionOptions(),
    *,
    settings: dict | None = None,
    ground_truth=(),
    units: GroundUnits | None = None,
    executor: Callable[[CityRun], None] = run_here,
    keep_graphs: bool = True,
) -> tuple[CityResult, dict]:
    """Predict ``mosaic`` and write every output into ``out_dir``; returns the result and the summary.

    ``ground_truth`` (world LineStrings), when given, is drawn in cyan under the prediction.
    ``units`` turns coordinates into metres (default: the mosaic CRS's; see
    :func:`csboundary.data.model_view.model_view`, which also gives them for CRS-less imagery).
    ``settings`` (JSON-ready) describe the model and how it is run: with the inputs, the grid and
    the code version they decide whether an unfinished run in ``out_dir`` is resumed or refused.
    The city graph is written block by block as it is made; ``keep_graphs`` also keeps it (and
    the patch graphs) in the result, for scoring: ``predict`` does not, so its memory does not
    grow with the city. ``options`` (:class:`PredictionOptions`) say how the city is predicted
    (:func:`predict_city`) and which files beyond the usual are written (maps.tif, Lanelet2).
    """
    if units is None:
        units = mosaic_units(mosaic) or PIXEL_UNITS
    manifest = run_manifest(mosaic, settings or {}, options)
    try:
        with (
            run_folder(out_dir, manifest, options.restart) as (out, store),
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
            writer = GraphWriter(files, crs, PatchGrid.for_mosaic(mosaic, options.grid).transform, units)
            stack.callback(writer.abort)
            result = predict_city(
                mosaic,
                model,
                options,
                store=store,
                executor=executor,
                overview_scale=overview_scale(mosaic.window, OVERVIEW_PX),
                writer=writer.add,
                keep_graphs=keep_graphs,
            )
            written_at = time.perf_counter()
            counts = writer.close()
            rss_after_prediction = peak_rss_mb()
            files.update(write_pictures(mosaic, result, stage, files["gpkg"], ground_truth, store))
            if options.write_maps:
                files["maps"] = write_maps_cog(stage / "maps.tif", mosaic, result.grid, store)
            if options.lanelet2:
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


def run_manifest(mosaic: Mosaic, settings: dict, options: PredictionOptions) -> dict:
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
        "grid": [options.grid.core, options.grid.margin],
        "batch_size": options.batch_size,
        "write_maps": options.write_maps,
        "code_version": code_version(),
    }
