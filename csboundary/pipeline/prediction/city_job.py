"""One city run's work per patch, whoever runs it: the FPN's maps of a batch of patches (read ->
model -> stored) and a window's graph (its stitched maps, averaged over the patches covering it
-> vertex extraction -> AfANet -> the patch graph in mosaic pixels, stored), in :class:`CityJob`,
and what a run returns (:class:`CityResult`). What a model offers for it is
:class:`~csboundary.models.patch_model.PatchModel`; :mod:`csboundary.pipeline.prediction.city`
schedules the work.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import time
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import rasterio

from csboundary.data.grid import Patch, PatchGrid
from csboundary.data.nodata import fill_nodata
from csboundary.data.raster import Mosaic
from csboundary.graph import BoundaryGraph
from csboundary.graph.stitching import to_mosaic
from csboundary.models.patch_model import PatchModel
from csboundary.pipeline.prediction.map_stitching import Index, stitch_window
from csboundary.pipeline.prediction.run_store import RunStore
from csboundary.viz.overlay import core_thumbnail

GDAL_CACHE_MB = 128  # GDAL's block cache defaults to 5 % of RAM and would grow with the city
# GDAL lists a tile's folder on every open to find side-car files; with thousands of tiles in one
# folder that listing dominates the open (side-cars are still probed one by one).
# rasterio hands an integer GDAL_CACHEMAX to GDALSetCacheMax64 as BYTES (GDAL itself reads small
# values as megabytes): 128 gave a 128-byte cache, so every window decoded its compressed blocks
# again (an overlapped window read took 30 ms instead of 1-2 ms; tests/pipeline/prediction/test_gdal_cache.py).
GDAL_ENV = {"GDAL_CACHEMAX": GDAL_CACHE_MB * 2**20, "GDAL_DISABLE_READDIR_ON_OPEN": "TRUE"}
STAGES = ("read", "fpn", "map_stitching", "vertex_extraction", "afanet", "graph_stitching", "confidence")
CPU = "cpu:"  # a stage's core seconds (its thread's) beside its wall seconds
DEFAULT_CHANNELS = 2  # keypoint + segmentation: the maps of a window no covering patch has imagery for


def _heap_trimmer():
    """glibc's ``malloc_trim``, or a no-op elsewhere. Patch-sized arrays freed in a varying order
    fragment the heap, and glibc keeps the freed pages: without trimming, resident memory grew by
    ~3.5 MB per patch (474 -> 826 MB over 100 patches); with it, it stays flat (~480 MB)."""
    try:
        trim = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return lambda: None
    return lambda: trim(0)


_trim_heap = _heap_trimmer()


@dataclass
class CityResult:
    """The stitched city graph, the unstitched patch graphs (mosaic pixels) and what it took."""

    graph: BoundaryGraph
    patch_graphs: dict[tuple[int, int], BoundaryGraph]
    grid: PatchGrid
    seconds: dict[str, float] = field(default_factory=dict)
    map_bytes_peak: int = 0  # stored patch maps at most (memory or disk)
    patches_without_imagery: int = 0  # windows with no valid pixel: the FPN was not run on them
    work: dict[str, int] = field(default_factory=dict)  # patches predicted / windows connected by this run, and reused
    evidence: np.ndarray | None = (
        None  # (E, F) edge evidence of ``graph`` (graph/edge_evidence.py), for a model collecting it
    )
    blank: frozenset = frozenset()  # patches known to have no imagery, never read
    outputs_seconds: float = 0.0  # spent in the writer the city graph was handed to, block by block
    patch_graph_edges: int = 0  # edges of all patch graphs, before stitching
    close_vertex_pairs: int = (
        0  # city graph vertices less than 1 px apart (stitching merges them; noding may make some)
    )
    busiest_core: tuple[int, int] = (0, 0)  # the patch core holding the most city graph length

    @property
    def n_patches(self) -> int:
        return len(self.grid)


class StageTimer:
    """Wall seconds per stage, and under ``CPU + stage`` the core seconds of the thread that ran
    it (all of a stage's work when its libraries run on the calling thread: one thread each)."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)

    def __call__(self, stage: str, fn, *args):
        start, cpu = time.perf_counter(), time.thread_time()
        out = fn(*args)
        self.seconds[stage] += time.perf_counter() - start
        self.seconds[CPU + stage] += time.thread_time() - cpu
        return out

    def add(self, seconds: dict[str, float]) -> None:
        for stage, value in seconds.items():
            self.seconds[stage] += value


@dataclass
class CityJob:
    """The two steps of a city run, on a mosaic, a model and a store: what a worker is given."""

    mosaic: Mosaic
    model: PatchModel
    grid: PatchGrid
    store: RunStore
    write_cores: bool = False  # keep each core's stitched maps (uint8) for maps.tif
    threads: int | None = None  # torch threads in a worker process (None: leave as is)
    overview_scale: float | None = None  # keep each core reduced by this for overview.png (None: do not)
    blank: frozenset = frozenset()  # patches known to have no imagery (unwritten blocks of a sparse file): never read

    def find_blank(self) -> frozenset:
        """The patches whose windows hold no written block of any tile (data/raster.py)."""
        return frozenset(p.index for p in self.grid if not self.mosaic.may_have_data(p.expanded))

    def load_maps(self, index: Index) -> np.ndarray | None:
        """A patch's stored maps; None (zeros) for a blank patch, whose maps are never stored."""
        return None if index in self.blank else self.store.load_maps(index)

    def read_batch(self, indices: list[Index]) -> list:
        """The windows of one FPN batch (safe to run in a prefetching thread)."""
        with rasterio.Env(**GDAL_ENV):
            return [self.mosaic.read(self.grid.patch(*i).expanded) for i in indices]

    def predict_maps(self, indices: list[Index], reads: list | None = None) -> tuple[list[bool], dict[str, float]]:
        """Predict one FPN batch (reading it unless ``reads`` are given) and store its maps;
        returns whether each window had imagery (the FPN skips those without) and the seconds
        per stage."""
        timed = StageTimer()
        if reads is None:
            reads = timed("read", self.read_batch, indices)
        maps, seconds = self.compute_maps(indices, reads)
        timed.add(seconds)
        timed.add(self.store_maps(indices, reads, maps))
        return [m is not None for m in maps], dict(timed.seconds)

    def compute_maps(self, indices: list[Index], reads: list) -> tuple[list[np.ndarray | None], dict[str, float]]:
        """The FPN maps of one batch's windows (None for a window without imagery, which the FPN
        skips). Touches neither the store nor the run's state, so it may run in a thread beside
        the windows being connected."""
        timed = StageTimer()
        work = [k for k, r in enumerate(reads) if r.valid.any()]
        images = [fill_nodata(reads[k].data, reads[k].valid) for k in work]  # no false edge along the imagery's border
        patches = [self.grid.patch(*indices[k]) for k in work]
        predicted = timed("fpn", self.model.patch_maps, patches, images) if work else []
        maps: list[np.ndarray | None] = [None] * len(reads)
        for k, m in zip(work, predicted):
            maps[k] = m * reads[k].valid[None]  # no keypoints where there is no image
        return maps, dict(timed.seconds)

    def store_maps(self, indices: list[Index], reads: list, maps: list[np.ndarray | None]) -> dict[str, float]:
        """Store a batch's maps (and images, thumbnails); returns the seconds per stage."""
        timed = StageTimer()
        for index, m, read in zip(indices, maps, reads):
            timed("map_stitching", self.store.save_maps, index, m)
            if m is not None:
                timed("read", self.store.save_image, index, read.data)
        if self.overview_scale:
            for index, read in zip(indices, reads):
                timed(
                    "read",
                    self.store.save_thumb,
                    index,
                    core_thumbnail(read, self.grid.patch(*index), self.overview_scale),
                )
        return dict(timed.seconds)

    def stitched_maps(self, index: Index) -> np.ndarray:
        """The window's maps averaged over every patch covering it (float32)."""
        channels = self.store.channels or DEFAULT_CHANNELS
        return stitch_window(self.grid, self.grid.patch(*index), self.load_maps, channels)

    def connect_window(self, index: Index, maps: np.ndarray | None = None) -> tuple[BoundaryGraph, dict[str, float]]:
        """Stitch the window, find its vertices and edges, store its graph (mosaic pixels)."""
        graph, maps, seconds = self.window_graph(index, maps)
        self.keep_window(index, graph, maps)
        return graph, seconds

    def window_graph(
        self, index: Index, maps: np.ndarray | None = None
    ) -> tuple[BoundaryGraph, np.ndarray, dict[str, float]]:
        """The window's graph (mosaic pixels), its stitched maps and the seconds per stage. Only
        reads the store, so several windows may be computed at once in threads."""
        timed = StageTimer()
        patch = self.grid.patch(*index)
        if maps is None:
            maps = timed("map_stitching", self.stitched_maps, index)
        if not maps.any():  # no imagery under the window or its neighbours: no boundary, nothing to read or connect
            return empty_graph(patch), maps, dict(timed.seconds)
        image = timed("read", self.store.load_image, index)
        if image is None:  # not kept (a store in memory, or an interrupted run)
            with rasterio.Env(**GDAL_ENV):
                image = timed("read", lambda: self.mosaic.read(patch.expanded).data)
        found = timed("vertex_extraction", self.model.extract, maps)
        graph = to_mosaic(timed("afanet", self.model.connect, patch, image, maps, found), patch)
        return graph, maps, dict(timed.seconds)

    def keep_window(self, index: Index, graph: BoundaryGraph, maps: np.ndarray) -> None:
        """Store a window's graph (and its core's maps for maps.tif); its image is no longer needed."""
        if self.write_cores:
            rows, cols = self.grid.patch(*index).core_local.slices()
            core = maps[:, rows, cols]
            self.store.save_core(index, np.clip(np.rint(core * 255), 0, 255).astype(np.uint8) if core.any() else None)
        self.store.save_graph(index, graph)
        self.store.drop_image(index)
        _trim_heap()


def empty_graph(patch: Patch) -> BoundaryGraph:
    """The graph of a window with no imagery around it (mosaic pixels)."""
    return to_mosaic(BoundaryGraph(np.zeros((0, 2)), np.zeros((0, 2), np.int64)), patch)


def reads_evidence(model: PatchModel) -> bool:
    """Whether the run keeps every core's maps to read the edges' evidence from (a model with an
    edge confidence, or one collecting evidence to fit it)."""
    return model.confidence is not None or model.collect_evidence
