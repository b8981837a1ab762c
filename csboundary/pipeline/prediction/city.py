"""City-scale inference, patch by patch (paper Algorithm 1 and Section IV-E).

The run is two kinds of per-patch work, both in :class:`CityJob`: the FPN's maps of a batch of
patches (read -> model -> stored), and a window's graph (its stitched maps, averaged over the
patches covering it -> vertex extraction -> AfANet -> the patch graph in mosaic pixels, stored).
:class:`~csboundary.pipeline.prediction.map_stitching.WindowSchedule` says when a window can be stitched
and when a patch's maps can be dropped; the :class:`~csboundary.pipeline.prediction.run_store.RunStore`
holds what is done, in memory or on disk (then a killed run resumes where it stopped). Once every
window has its graph, the patch graphs are stitched into the city graph
(:func:`stitch_patch_graphs`).

Here the work runs in this process in the grid's row-major order, so map memory is bounded by
about two rows of patches; :mod:`csboundary.pipeline.prediction.distributed` hands the same ``CityJob``
steps to Dask workers. Every window's graph depends only on the stored maps of its patches, so
the city graph is the same whichever process computed which patch (given the same FPN batches).

The model is anything with the three steps of :class:`PatchModel`: the trained networks
(:class:`~csboundary.pipeline.prediction.patch.PatchPredictor`) or the ground truth
(:class:`~csboundary.pipeline.evaluation.oracle.OracleModel`), which is how stitching is tested.
"""

from __future__ import annotations

import os
import time
from collections import defaultdict
from typing import Callable

import numpy as np
import shapely
from shapely.geometry import LineString
from tqdm import tqdm

from csboundary.data.grid import Patch, PatchGrid
from csboundary.data.raster import Mosaic
from csboundary.graph import BoundaryGraph
from csboundary.graph.graph_stream import StreamBoundary, StreamPiece
from csboundary.graph.stitching import StitchConfig
from csboundary.models.patch_model import PatchModel
from csboundary.pipeline.prediction.city_blocks import BLOCK, CityCollector, CityGraphRecipe, stream_city_graph
from csboundary.pipeline.prediction.city_job import (
    CPU,
    DEFAULT_CHANNELS,
    STAGES,
    CityJob,
    CityResult,
    StageTimer,
    empty_graph,
    reads_evidence,
)
from csboundary.pipeline.prediction.edge_scoring import core_sampler
from csboundary.pipeline.prediction.map_stitching import Index, WindowSchedule
from csboundary.pipeline.prediction.options import PredictionOptions
from csboundary.pipeline.prediction.run_store import RunStore


def fpn_batches(grid: PatchGrid, batch_size: int) -> list[list[Index]]:
    """The FPN batches of a run: consecutive patches in row-major order. Fixed by the grid and
    the batch size alone, so a resumed or distributed run feeds the FPN the same batches."""
    indices = [p.index for p in grid]
    return [indices[k : k + batch_size] for k in range(0, len(indices), batch_size)]


class CityRun:
    """The bookkeeping of one run, whoever does the work: which windows are ready, which maps to
    drop, the patch graphs, the seconds per stage, the progress bar."""

    def __init__(
        self,
        job: CityJob,
        batch_size: int,
        progress: bool,
        on_window: Callable[[Patch, np.ndarray], None] | None = None,
    ):
        self.job, self.on_window = job, on_window
        grid, store = job.grid, job.store
        job.blank = job.find_blank()
        if job.write_cores:  # a window whose core an interrupted run did not keep is connected again
            for index in store.graphs_done():
                if not store.has_core(index):
                    store.drop_graph(index)
        graphs = store.graphs_done()
        self.schedule = WindowSchedule(grid, graphs_done=graphs)
        # windows with only blank patches around them have no boundary: done before the run, with
        # nothing stored, so a mostly empty mosaic costs little more than its data
        self.quiet = frozenset(
            i for i, around in self.schedule.neighbourhoods.items() if all(q in job.blank for q in around)
        )
        store.mark_empty_cores(self.quiet)
        self.schedule.graphs_done |= self.quiet
        # maps a finished window no longer needs were dropped; they count as done
        reused = store.maps_done() | {p.index for p in grid if self.schedule.releasable(p.index)}
        self.schedule.maps_done = reused | job.blank
        # with a store on disk the patch graphs are read back for the final stitching only, so
        # memory during the run does not grow with the number of patches
        self.patch_graphs = {} if store.root is not None else {i: store.load_graph(i) for i in sorted(graphs)}
        self.patch_graphs.update({i: empty_graph(grid.patch(*i)) for i in self.quiet})
        self.batches = [b for b in fpn_batches(grid, batch_size) if not set(b) <= self.schedule.maps_done]
        self.seconds: dict[str, float] = defaultdict(float)
        self.work = {
            "patches_predicted": 0,
            "windows_connected": 0,
            "patches_reused": len(reused - job.blank),
            "windows_reused": len(graphs - self.quiet),
        }
        self.map_bytes_peak = store.held_map_bytes()
        self.bar = tqdm(
            total=len(grid),
            initial=len(graphs | self.quiet),
            desc="predict patches",
            unit="patch",
            disable=not progress,
        )

    def add_seconds(self, seconds: dict[str, float]) -> None:
        for k, v in seconds.items():
            self.seconds[k] += v

    def maps_finished(self, batch: list[Index], seconds: dict[str, float]) -> list[Index]:
        """A batch's maps are stored; returns the windows now ready."""
        self.add_seconds(seconds)
        self.work["patches_predicted"] += len(batch)
        ready = []
        for index in batch:
            if index not in self.schedule.maps_done:
                ready += self.schedule.add_maps(index)
        self.map_bytes_peak = max(self.map_bytes_peak, self.job.store.held_map_bytes())
        return sorted(set(ready))

    def graph_finished(self, index: Index, graph: BoundaryGraph, seconds: dict[str, float]) -> None:
        self.add_seconds(seconds)
        self.work["windows_connected"] += 1
        if self.job.store.root is None:
            self.patch_graphs[index] = graph
        for q in self.schedule.add_graph(index):
            self.job.store.drop_maps(q)
        self.bar.update(1)

    def connect_all_here(self, indices: list[Index], workers: int) -> None:
        """Connect windows in this process, ``workers`` at a time in threads (vertex extraction's
        skeletons, ONNX Runtime and most array work release the GIL) once the FPN has no more
        work to share the cores with; stored and counted in ``indices``' order, so the result is
        the same for any number of workers."""
        if workers < 2 or len(indices) < 2 or self.on_window is not None:
            for index in indices:
                self.connect_here(index)
            return
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(workers, thread_name_prefix="csboundary-window") as pool:
            for index, future in [(i, pool.submit(self.job.window_graph, i)) for i in indices]:
                graph, maps, seconds = future.result()
                self.job.keep_window(index, graph, maps)
                self.graph_finished(index, graph, seconds)

    def connect_here(self, index: Index) -> None:
        """Connect one window in this process (calls ``on_window`` with its stitched maps)."""
        maps = None
        if self.on_window is not None:
            timed = StageTimer()
            maps = timed("map_stitching", self.job.stitched_maps, index)
            self.add_seconds(timed.seconds)
            self.on_window(self.job.grid.patch(*index), maps)
        graph, seconds = self.job.connect_window(index, maps)
        self.graph_finished(index, graph, seconds)

    def finish(
        self,
        stitch: StitchConfig,
        progress: bool,
        writer: Callable[[StreamPiece | None, list[StreamBoundary]], None] | None = None,
        keep_graphs: bool = True,
        block: int = BLOCK,
        one_pass: bool = False,
    ) -> CityResult:
        """Make the city graph block by block (:mod:`csboundary.pipeline.prediction.city_blocks`) and hand
        each block's vertices and edges, and the boundaries it completes, to ``writer``. With
        ``keep_graphs`` the result also holds the whole city graph and every patch graph (the
        evaluation needs them); without, memory stays one block's worth and the result's
        ``graph`` is empty. ``block`` (patches) and ``one_pass`` are those of
        :func:`~csboundary.pipeline.prediction.city_blocks.city_blocks`."""
        self.bar.close()
        if not self.schedule.done:
            missing = len(self.job.grid) - len(self.schedule.graphs_done)
            raise RuntimeError(f"{missing} window(s) have no graph: the run did not finish")
        grid, mosaic, store, model = self.job.grid, self.job.mosaic, self.job.store, self.job.model
        crs = mosaic.crs.to_string() if mosaic.crs is not None else None
        settings = model.settings
        recipe = CityGraphRecipe(
            stitch,
            crs,
            settings.min_fragment_px,
            settings.attach_px,
            model.confidence,
            settings.min_confidence,
            reads_evidence(model),
            block=block,
        )
        load_core = lambda index: store.load_core(index) if grid.is_planned(index) else None  # noqa: E731 (unplanned: no imagery, all zero)
        sample = core_sampler(grid, load_core, store.channels or DEFAULT_CHANNELS) if recipe.evidence else None
        counted: dict[Index, int] = {}

        def load(index: Index) -> BoundaryGraph:
            if index in self.quiet or not grid.is_planned(index):  # no imagery around it: no boundary
                graph = empty_graph(grid.patch(*index))
            else:
                graph = self.patch_graphs[index] if index in self.patch_graphs else store.load_graph(index)
            counted.setdefault(index, graph.n_edges)
            return graph

        whole = CityCollector(grid.transform, crs) if keep_graphs else None
        made = stream_city_graph(load, grid, recipe, sample, writer, whole, one_pass, progress)
        self.add_seconds({k: v for k, v in made.seconds.items() if k in STAGES or k.startswith(CPU)})
        if keep_graphs and store.root is not None:
            self.patch_graphs = {p.index: load(p.index) for p in grid}
        graph, evidence = (whole or CityCollector(grid.transform, crs)).result()
        seconds = {
            **{s: 0.0 for s in STAGES},
            **{k: v for k, v in self.seconds.items() if k in STAGES or k.startswith(CPU)},
        }
        return CityResult(
            graph,
            self.patch_graphs if keep_graphs else {},
            grid,
            seconds,
            self.map_bytes_peak,
            len(self.job.store.empty_patches() | self.job.blank),
            dict(self.work),
            evidence,
            self.job.blank,
            made.seconds.get("outputs", 0.0),
            sum(counted.values()),
            made.close_pairs,
            made.busiest_core,
        )


def run_here(run: CityRun, drain_workers: int | None = None) -> None:
    """Do a run's remaining work in this process, in row-major order: a window is connected as
    soon as its last covering patch is predicted. Two threads work ahead of this one: one reads
    the FPN batch after next (GDAL), one runs the FPN on the next batch (ONNX Runtime or
    PyTorch), both without holding the GIL, while this thread stores the current batch's maps and
    connects the windows they complete; vertex extraction, AfANet and the rest thus overlap the
    network. The windows the last batch completes are connected ``drain_workers`` at a time
    (default: one per core). Each stage's seconds are the time its own thread spent in it, so
    they add up to more than the run's wall time."""
    from concurrent.futures import ThreadPoolExecutor

    if drain_workers is None:
        drain_workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)

    for index in run.schedule.ready():  # windows an interrupted run left ready
        run.connect_here(index)
    batches, job = run.batches, run.job
    with (
        ThreadPoolExecutor(1, thread_name_prefix="csboundary-read") as reader,
        ThreadPoolExecutor(1, thread_name_prefix="csboundary-fpn") as network,
    ):
        reading = [reader.submit(job.read_batch, b) for b in batches[:2]]

        def read_and_predict(k: int):
            start = time.perf_counter()
            reads = reading[k].result()
            reading[k] = (
                None  # the batch is held by the caller until its maps are stored, not by this list for the whole run
            )
            waited = time.perf_counter() - start
            if k + 2 < len(batches):
                reading.append(reader.submit(job.read_batch, batches[k + 2]))
            maps, seconds = job.compute_maps(batches[k], reads)
            seconds["read"] = seconds.get("read", 0.0) + waited  # the reading the FPN waited for
            return reads, maps, seconds

        upcoming = network.submit(read_and_predict, 0) if batches else None
        for k, batch in enumerate(batches):
            reads, maps, seconds = upcoming.result()
            upcoming = network.submit(read_and_predict, k + 1) if k + 1 < len(batches) else None
            for stage, value in job.store_maps(batch, reads, maps).items():
                seconds[stage] = seconds.get(stage, 0.0) + value
            ready = run.maps_finished(batch, seconds)
            # the last windows have the cores to themselves: connect them side by side
            run.connect_all_here(ready, workers=1 if upcoming is not None else drain_workers)


def predict_city(
    mosaic: Mosaic,
    model: PatchModel,
    options: PredictionOptions = PredictionOptions(),
    *,
    on_window: Callable[[Patch, np.ndarray], None] | None = None,
    store: RunStore | None = None,
    executor: Callable[[CityRun], None] = run_here,
    overview_scale: float | None = None,
    writer: Callable[[StreamPiece | None, list[StreamBoundary]], None] | None = None,
    keep_graphs: bool = True,
) -> CityResult:
    """Predict the whole mosaic as ``options`` say (the grid, batches, threads, stitching and
    streaming; with ``write_maps`` every core's stitched maps are kept for maps.tif).
    ``on_window(patch, stitched_maps)`` sees every final window (in-process runs only); ``store``
    (default: in memory) holds the work done, and a store left by an interrupted run is resumed;
    ``executor`` does the work (default: this process; see
    :func:`csboundary.pipeline.prediction.distributed.dask_executor`); ``writer`` and
    ``keep_graphs``: see :meth:`CityRun.finish`."""
    grid = PatchGrid.for_mosaic(mosaic, options.grid)
    job = CityJob(
        mosaic,
        model,
        grid,
        store if store is not None else RunStore(),
        options.write_maps or reads_evidence(model),
        options.threads,
        overview_scale,
    )
    run = CityRun(job, options.batch_size, options.progress, on_window)
    executor(run)
    return run.finish(options.stitch, options.progress, writer, keep_graphs, options.block, options.one_pass)


def patch_scale_graph(result: CityResult) -> BoundaryGraph:
    """Every patch's own graph clipped to its core, side by side: what the paper's patch-scale
    evaluation judges ("graph within a single patch"), before any stitching."""
    lines: list[np.ndarray] = []
    for index, graph in sorted(result.patch_graphs.items()):
        core = result.grid.patch(*index).core
        for line in graph.to_linestrings():
            clipped = shapely.clip_by_rect(line, core.col_off, core.row_off, core.col_end, core.row_end)
            for part in getattr(clipped, "geoms", [clipped]):
                if isinstance(part, LineString) and part.length > 0:
                    lines.append(np.asarray(part.coords))
    return BoundaryGraph.from_polylines(lines, transform=result.graph.transform, crs=result.graph.crs)
