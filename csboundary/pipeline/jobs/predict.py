"""``predict`` and ``predict-patch`` as library calls: imagery in, a folder of georeferenced
outputs out. The command line only parses options and prints what these return."""

from __future__ import annotations

import contextlib
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Callable, Sequence

import geopandas as gpd
import numpy as np

from csboundary.data.atomic import check_output_dir, staging_folder
from csboundary.data.folder_lock import folder_lock
from csboundary.data.grid import Patch, PatchGrid
from csboundary.data.inputs import open_imagery
from csboundary.data.model_view import ModelInput, model_view
from csboundary.errors import InputError, InputWarning
from csboundary.graph import BoundaryGraph
from csboundary.graph.settings import SETTINGS, setting_value
from csboundary.models.checkpoint import file_sha256, shipped_weights
from csboundary.pipeline.jobs.prediction_run import run_prediction
from csboundary.pipeline.prediction.city import predict_city, run_here
from csboundary.pipeline.prediction.options import PredictionOptions
from csboundary.pipeline.prediction.patch import PatchPredictor
from csboundary.viz.labels import draw_patch_labels
from csboundary.viz.overlay import to_display, write_png

SPARSE_SHARE = 0.5  # imagery under fewer than this share of the patches is worth a word before the run
SECONDS_PER_PATCH = 1.0  # a patch with imagery on a 2-core CPU with ONNX Runtime (docs/scaling.md), for the estimate


def warn_if_sparse(grid: PatchGrid, mosaic, inputs: Sequence[str | Path]) -> None:
    """A warning when the imagery covers little of its extent (a city inside its bounding box):
    how much, that the rest is skipped, and the time the covered part will take. Finding the
    coverage reads every tile's block table, so a truncated tile is an InputError here, before
    the run store exists."""
    covered = sum(mosaic.may_have_data(patch.expanded) for patch in grid)
    if len(grid) >= 4 and covered < SPARSE_SHARE * len(grid):
        warnings.warn(
            f"{inputs[0]}: imagery covers {covered} of {len(grid)} patches ({covered / len(grid):.1%}) of its extent; "
            f"the empty ones are skipped without reading (about {covered * SECONDS_PER_PATCH / 60:.0f} min on a 2-core CPU)",
            InputWarning,
            stacklevel=2,
        )


def predict_to_folder(
    inputs: Sequence[str | Path],
    out: str | Path,
    predictor: PatchPredictor,
    options: PredictionOptions = PredictionOptions(),
    *,
    weights: str | Path | None = None,
    on_plan: Callable[[PatchGrid, ModelInput], None] | None = None,
) -> dict:
    """Predict the city that ``inputs`` name (tiles, a folder of tiles, a city directory) into
    ``out`` as ``options`` say, and return the run's summary. ``weights`` names the file
    ``predictor`` came from (None: the shipped one), for the run's manifest. ``on_plan`` is told
    the patch grid before any work. An unfinished run in ``out`` is continued unless
    ``options.restart``."""
    mosaic, _ = open_imagery(inputs)
    view = model_view(mosaic, options.gsd, predictor.pixel_size_m)
    check_output_dir(out, inputs=inputs)
    with contextlib.ExitStack() as stack:
        if Path(out).is_dir():  # a folder in use is refused before the plan is told (run_prediction locks it too)
            stack.enter_context(folder_lock(out))
        grid = PatchGrid.for_mosaic(view.mosaic, options.grid)
        warn_if_sparse(grid, view.mosaic, inputs)
        if on_plan is not None:
            on_plan(grid, view)
        settings = run_settings(predictor, view, weights, options.batch_size)
        stack.enter_context(view.mosaic)
        executor = run_here
        if options.distributed:
            from csboundary.pipeline.prediction.distributed import dask_client, dask_executor

            client, worker_threads = stack.enter_context(dask_client(options.scheduler, options.workers))
            executor = dask_executor(client)
            options = replace(options, threads=options.threads or worker_threads)
            # not part of the run's manifest: a run may resume elsewhere
            settings["cluster"] = options.scheduler or f"local, {options.workers} workers"
        elif options.threads:
            import torch

            torch.set_num_threads(options.threads)  # this process's own: no worker to set them in
            options = replace(options, threads=None)
        _, summary = run_prediction(
            view.mosaic,
            predictor,
            out,
            options,
            settings=settings,
            units=view.units,
            executor=executor,
            keep_graphs=False,
        )
    return summary


def model_settings(predictor: PatchPredictor, weights: str | Path | None = None) -> dict:
    """The model and how it runs, for a run's manifest and summary.json (JSON-ready): the weights,
    every graph setting by its name (:data:`~csboundary.graph.settings.SETTINGS`), and the engine
    and arithmetic (and why ``auto`` chose it)."""
    return {
        "weights": str(weights or "shipped"),
        "weights_sha256": file_sha256(weights or shipped_weights()),
        "graph": {name: setting_value(predictor.settings, name) for name in SETTINGS},
        # without a confidence the scores are the networks' own: --min-confidence later never filters them
        "edge_confidence": predictor.confidence is not None,
        "device": str(predictor.device),
        "engine": predictor.engine,
        "precision": predictor.precision,
        "precision_choice": predictor.precision_choice or predictor.precision,  # --precision auto: what, and why
    }


def run_settings(predictor: PatchPredictor, view: ModelInput, weights: str | Path | None, batch_size: int) -> dict:
    """:func:`model_settings`, the batch size, and how the imagery was read (its pixel size, whether
    it was resampled, its stretch)."""
    return {
        **model_settings(predictor, weights),
        "batch_size": batch_size,
        "input_pixel_m": [round(v, 5) for v in view.source_pixel_m],
        "resampled": view.resampled,
        "stretch": None if view.stretch is None else {"low": view.stretch.low, "high": view.stretch.high},
    }


def predict_patch_to_folder(
    image: str | Path, out: str | Path, predictor: PatchPredictor, gsd: float | None = None
) -> BoundaryGraph:
    """One image (at most 1100x1100 px at the model's pixel size) -> ``out``/graph.json,
    boundaries.geojson and overlay.png (maps and graph over the image); returns the graph.

    The image goes through the city pipeline exactly as ``predict`` takes it (in memory, on the
    same patch grid: one 1100 px window up to 1000 px, two or four windows above), so both write
    the same graph. An image without a CRS is taken to be at the model's pixel size unless
    ``gsd`` says otherwise."""
    image, out = Path(image), Path(out)
    check_output_dir(out, inputs=[image])
    mosaic, _ = open_imagery([image])
    with model_view(mosaic, gsd, predictor.pixel_size_m, assume_model_gsd=True).mosaic as mosaic:
        if mosaic.width > 1100 or mosaic.height > 1100:
            raise InputError(
                image,
                f"is {mosaic.width}x{mosaic.height} px at the model's pixel size; predict-patch takes at most 1100x1100 (a "
                f"patch)",
            )
        maps = CoreMaps(mosaic.width, mosaic.height)
        graph = predict_city(mosaic, predictor, PredictionOptions(progress=False), on_window=maps.add).graph
        read = mosaic.read(mosaic.window)
    frame = gpd.GeoDataFrame(
        {
            "kind": graph.edge_kinds or [],
            "confidence": list(graph.edge_scores) if graph.edge_scores is not None else [],
        },
        geometry=graph.to_linestrings(world=True),
        crs=graph.crs,
    )
    with staging_folder(check_output_dir(out, create=True), last="graph.json") as stage:
        graph.write_json(stage / "graph.json")
        frame.to_file(stage / "boundaries.geojson", driver="GeoJSON", engine="pyogrio", layer="boundaries")
        arrays = {"segmentation": maps.array[1] > 0.5, "keypoint_heat": maps.array[0]}
        write_png(stage / "overlay.png", draw_patch_labels(to_display(read.data, read.valid), arrays, graph))
    return graph


class CoreMaps:
    """A mosaic's stitched maps, put together from each window's core as the city pipeline hands
    the windows over (``predict_city``'s ``on_window``; the cores cover the mosaic once)."""

    def __init__(self, width: int, height: int):
        self.width, self.height = width, height
        self.array: np.ndarray | None = None  # (C, height, width)

    def add(self, patch: Patch, maps: np.ndarray) -> None:
        if self.array is None:
            self.array = np.zeros((maps.shape[0], self.height, self.width), np.float32)
        rows, cols = patch.core_local.slices()
        self.array[(slice(None), *patch.core.slices())] = maps[:, rows, cols]
