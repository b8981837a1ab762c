"""The city graph, block by block: patch graphs in, the finished city graph out in a fixed order,
with memory bounded by one block whatever the size of the city.

Every step that makes the city graph out of the patch graphs reaches only so far: stitching joins
a patch to its neighbours, the short pieces dropped are shorter than the ring (:func:`ring_width`),
noding and end attachment look a few tens of pixels away, and an edge's evidence is counted within its own
patch core (:func:`~csboundary.graph.edge_evidence.edge_evidence`). So the city is cut into
blocks of ``block`` x ``block`` patches; each block's graph is made from the patch graphs of the
block and of a ring of ``halo`` patches around it, and keeps the edges whose midpoint lies in
one of the block's cores (:func:`~csboundary.graph.stitching.owner_cores`). Everything beyond the
ring is at least a patch (1000 px) away from those edges. One rule is not bounded by distance:
end attachment does not join an end to its own connected piece, and a piece may close only
beyond the ring; then a block attaches an end that one pass would not (blocks of one patch on
one of the 13 demo and test cities; none with blocks of 2 or 4: scripts/check_city_blocks.py).

The order is fixed by the blocks, not by how they are computed: blocks in row-major order, a
block's edges by their core (row-major), then by their midpoint (row, then column). ``one_pass``
makes the whole city graph at once and cuts it into the same blocks: the two must give the same
edges in the same order (``tests/pipeline/prediction/test_city_blocks.py``; the demo and test cities).
"""

from __future__ import annotations

import contextlib
import gc
import math
import time
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np
from tqdm import tqdm

from csboundary.data.grid import PatchGrid
from csboundary.graph import BoundaryGraph
from csboundary.graph.bubbles import BUBBLE_PX, drop_bubbles
from csboundary.graph.edge_evidence import Sampler, edge_evidence
from csboundary.graph.end_attachment import ATTACH, attach_ends, dangling_ends
from csboundary.graph.fragments import drop_short_fragments
from csboundary.graph.graph_stream import GraphStream, StreamBoundary, StreamPiece
from csboundary.graph.noding import node_shared_points
from csboundary.graph.stitching import StitchConfig, edge_midpoints, owner_cores, stitch_patch_graphs
from csboundary.graph.straightening import StraightenConfig, straighten
from csboundary.models.confidence_model import EdgeConfidence
from csboundary.pipeline.prediction.edge_scoring import scored_graph

Index = tuple[int, int]
BLOCK = 4  # patches along a block's side: 16 patch graphs and their ring of 20 in memory at once
HALO = 1  # patches of context around a block


@dataclass(frozen=True)
class CityGraphRecipe:
    """What turns a run's patch graphs (mosaic pixels) into its city graph."""

    stitch: StitchConfig = StitchConfig()
    crs: str | None = None
    min_fragment_px: float = 0.0  # connected pieces shorter than this are dropped
    attach_px: float = 0.0  # dangling ends are joined to the line ahead within this
    confidence: EdgeConfidence | None = None  # the edges' scores become this probability
    min_confidence: float = 0.0  # edges less sure than this are dropped
    evidence: bool = False  # compute the edges' evidence (to score them, or to fit a confidence)
    straighten: StraightenConfig | None = (
        StraightenConfig()
    )  # detours off a straight curb flattened (graph/straightening.py)
    bubble_px: float = (
        BUBBLE_PX  # of two short routes between the same two vertices, the longer goes (graph/bubbles.py)
    )
    block: int = BLOCK
    halo: int = HALO

    def __post_init__(self) -> None:
        if self.block < 1 or self.halo < 1:
            raise ValueError(f"block and halo must be >= 1, got {self.block} and {self.halo}")


@dataclass
class CityBlock:
    """One block of the city graph: its edges in order, the vertices they use (numbered in order
    of first use), each edge's core, and its evidence when the recipe asks for it without a
    confidence (to fit one)."""

    index: Index
    graph: BoundaryGraph
    cores: np.ndarray  # (E, 2)
    evidence: np.ndarray | None = None
    seconds: dict = field(default_factory=dict)  # graph_stitching, confidence


def city_graph(patch_graphs: dict[Index, BoundaryGraph], grid: PatchGrid, recipe: CityGraphRecipe) -> BoundaryGraph:
    """The city graph of patch graphs (mosaic pixels): stitched, without the connected pieces
    shorter than ``min_fragment_px``, noded where lines touch, cross or run together
    (``stitch.node_shared``), then with the dangling ends attached to the line of another piece
    up to ``attach_px`` ahead of them, and without the longer route of each short bubble
    (:func:`~csboundary.graph.bubbles.drop_bubbles`), its straight runs straightened
    (:func:`~csboundary.graph.straightening.straighten`). Noding and attaching come after the short pieces are
    dropped, so that noise is not kept alive by touching a road (Ottawa crops: F1@5 0.450 noding
    first, 0.452 after). Without scores from the confidence: :func:`city_blocks` adds them."""
    graph = drop_short_fragments(
        stitch_patch_graphs(patch_graphs, grid, recipe.stitch, recipe.crs), recipe.min_fragment_px
    )
    if recipe.stitch.node_shared:
        graph = node_shared_points(graph)
    if recipe.attach_px > 0:
        ends, _, headings = dangling_ends(graph)
        graph = attach_ends(graph, ends, recipe.attach_px, ATTACH, headings, merge_px=recipe.stitch.merge_px)
    return straighten(drop_bubbles(graph, recipe.bubble_px), recipe.straighten)


def block_ranges(grid: PatchGrid, block: int) -> list[tuple[range, range]]:
    """(patch rows, patch cols) of every block holding a planned patch, in row-major order."""
    if grid.planned is None:
        return [
            (range(r, min(r + block, grid.n_rows)), range(c, min(c + block, grid.n_cols)))
            for r in range(0, grid.n_rows, block)
            for c in range(0, grid.n_cols, block)
        ]
    corners = sorted({(r - r % block, c - c % block) for r, c in grid.planned})
    return [(range(r, min(r + block, grid.n_rows)), range(c, min(c + block, grid.n_cols))) for r, c in corners]


def city_blocks(
    load_graph: Callable[[Index], BoundaryGraph],
    grid: PatchGrid,
    recipe: CityGraphRecipe,
    sample: Sampler | None = None,
    one_pass: bool = False,
) -> Iterator[CityBlock]:
    """The city graph block by block (module docstring). ``load_graph(index)`` gives a patch's
    graph (mosaic pixels); ``sample`` reads the stored maps for the evidence. With ``one_pass``
    every patch graph is loaded and the city graph made once (memory grows with the city)."""
    whole = whole_cores = whole_mids = None
    if one_pass:
        whole = city_graph({p.index: load_graph(p.index) for p in grid}, grid, recipe)
        whole_mids = edge_midpoints(whole)
        whole_cores = owner_cores(whole, grid, whole_mids)
    halo = ring_width(grid, recipe)
    for rows, cols in block_ranges(grid, recipe.block):
        start, cpu = time.perf_counter(), time.thread_time()
        if whole is None:
            ring_rows = range(max(rows.start - halo, 0), min(rows.stop + halo, grid.n_rows))
            ring_cols = range(max(cols.start - halo, 0), min(cols.stop + halo, grid.n_cols))
            local = city_graph({(r, c): load_graph((r, c)) for r in ring_rows for c in ring_cols}, grid, recipe)
            mids = edge_midpoints(local)
            cores = owner_cores(local, grid, mids)
        else:
            local, cores, mids = whole, whole_cores, whole_mids
        keep = np.isin(cores[:, 0], rows) & np.isin(cores[:, 1], cols)
        index = (rows.start // recipe.block, cols.start // recipe.block)
        built, built_cpu = time.perf_counter(), time.thread_time()
        block = _finished_block(index, local, cores, mids, keep, grid, recipe, sample)
        block.seconds = {
            "graph_stitching": built - start,
            "confidence": time.perf_counter() - built,
            "cpu:graph_stitching": built_cpu - cpu,
            "cpu:confidence": time.thread_time() - built_cpu,
        }
        yield block


@contextlib.contextmanager
def _young_collections_only():
    """Python's automatic full garbage collections walk every live object, and what the stream
    holds grows with the city's width: they took the time per patch from 49 to 63 ms between
    100 and 1600 benchmark patch graphs (51 ms with them off). The loop collects each block's
    young objects itself instead."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def ring_width(grid: PatchGrid, recipe: CityGraphRecipe) -> int:
    """Patches of context around a block: ``recipe.halo``, or more when the shortest piece kept
    or the farthest end attachment is long. A piece that holds an edge of the block and leaves
    the ring runs across at least the ring less half a window, so it is never mistaken for a
    short one; an end is attached as one pass would as long as the line it reaches lies in the
    ring."""
    reach = max(recipe.min_fragment_px, recipe.attach_px, recipe.stitch.mend_px)
    return max(recipe.halo, math.ceil((reach + grid.config.size / 2) / grid.config.core))


def edge_reach(grid: PatchGrid, recipe: CityGraphRecipe | None = None) -> float:
    """How far (px, along each axis) a vertex may lie from the midpoint of an edge at it: an
    edge comes from one patch's window (``size`` px) and stays in it, or is an attachment of at
    most ``attach_px``. A vertex a later block touches after it was declared final is an error
    (:class:`~csboundary.graph.graph_stream.GraphStream`), never a silent one."""
    attach = 0.0 if recipe is None else recipe.attach_px
    return float(max(grid.config.size + 2 * grid.config.margin, attach + grid.config.size / 2))


@dataclass
class MadeCityGraph:
    """What :func:`stream_city_graph` measured on the way."""

    seconds: dict  # graph_stitching, confidence, outputs (the writer's)
    close_pairs: int  # vertices less than 1 px apart (stitching merges them; noding may make some)
    busiest_core: Index  # the patch core holding the most of the city graph's length
    held_peak: int  # vertices and edges the stream held at most


def stream_city_graph(
    load_graph: Callable[[Index], BoundaryGraph],
    grid: PatchGrid,
    recipe: CityGraphRecipe,
    sample: Sampler | None = None,
    writer: Callable[[StreamPiece | None, list[StreamBoundary]], None] | None = None,
    collector: "CityCollector | None" = None,
    one_pass: bool = False,
    progress: bool = False,
) -> MadeCityGraph:
    """Make the city graph block by block (:func:`city_blocks`) and hand each block's vertices
    and edges, then the boundaries it completed, to ``writer`` (and ``collector``, which keeps
    the whole graph). A vertex is final, and the boundaries through it can be completed, once
    every block within :func:`edge_reach` of it is done."""
    stream = GraphStream()
    core_length: dict[Index, float] = defaultdict(float)
    seconds: dict[str, float] = defaultdict(float)
    reach = edge_reach(grid, recipe)
    span = recipe.block * grid.config.core
    n_block_rows, n_block_cols = -(-grid.n_rows // recipe.block), -(-grid.n_cols // recipe.block)
    held = 0

    def final_step(points: np.ndarray) -> np.ndarray:
        """The block after which each point is final: the last (row-major) block within reach."""
        row = np.minimum((points[:, 1] + reach) // span, n_block_rows - 1)
        col = np.minimum((points[:, 0] + reach) // span, n_block_cols - 1)
        return (row * n_block_cols + col).astype(np.int64)

    def emit(piece: StreamPiece | None, boundaries: list[StreamBoundary]) -> None:
        start = time.perf_counter()
        if writer is not None:
            writer(piece, boundaries)
        seconds["outputs"] += time.perf_counter() - start

    n_blocks = len(block_ranges(grid, recipe.block))
    with (
        tqdm(total=n_blocks, desc="stitch graphs", unit="block", disable=not progress or n_blocks < 2) as bar,
        _young_collections_only(),
    ):
        for block in city_blocks(load_graph, grid, recipe, sample, one_pass):
            for stage, value in block.seconds.items():
                seconds[stage] += value
            start, cpu = time.perf_counter(), time.thread_time()
            piece = stream.add(block.graph, final_step(block.graph.vertices))
            held = max(held, stream.held)
            boundaries = stream.finish(block.index[0] * n_block_cols + block.index[1])
            for (r, c), length in zip(block.cores.tolist(), block.graph.edge_lengths()):
                core_length[r, c] += float(length)
            if collector is not None:
                collector.add(piece, block.evidence)
            seconds["graph_stitching"] += time.perf_counter() - start
            seconds["cpu:graph_stitching"] += time.thread_time() - cpu
            emit(piece, boundaries)
            gc.collect(1)  # the block's own garbage; what the stream holds is left alone
            bar.update(1)
    emit(None, stream.finish())
    return MadeCityGraph(dict(seconds), stream.close_pairs, max(core_length, key=core_length.get, default=(0, 0)), held)


class CityCollector:
    """The whole city graph (and its evidence) put together from the pieces of a
    :class:`~csboundary.graph.graph_stream.GraphStream`, numbered as the files number it."""

    def __init__(self, transform, crs: str | None):
        self.transform, self.crs = transform, crs
        self.vertices: list[np.ndarray] = []
        self.vertex_kinds: list[str] = []
        self.edges: list = []
        self.evidence: list[np.ndarray] = []

    def add(self, piece: StreamPiece, evidence: np.ndarray | None = None) -> None:
        self.vertices.append(piece.vertices)
        self.vertex_kinds += piece.vertex_kinds or ["vertex"] * len(piece.vertices)
        self.edges += piece.edges
        if evidence is not None:
            self.evidence.append(evidence)

    def result(self) -> tuple[BoundaryGraph, np.ndarray | None]:
        edges = self.edges
        graph = BoundaryGraph(
            np.concatenate(self.vertices).reshape(-1, 2) if self.vertices else np.zeros((0, 2)),
            np.array([[e.u, e.v] for e in edges], np.int64).reshape(-1, 2),
            vertex_kinds=list(self.vertex_kinds),
            edge_kinds=[e.kind or "normal" for e in edges],
            edge_polylines=[e.polyline for e in edges],
            edge_scores=np.array([np.nan if e.score is None else e.score for e in edges], float),
            edge_patches=np.array([e.patch or (-1, -1) for e in edges], np.int64).reshape(-1, 2),
            transform=self.transform,
            crs=self.crs,
        )
        return graph, np.concatenate(self.evidence) if self.evidence else None


def _finished_block(
    index: Index,
    local: BoundaryGraph,
    cores: np.ndarray,
    mids: np.ndarray,
    keep: np.ndarray,
    grid: PatchGrid,
    recipe: CityGraphRecipe,
    sample: Sampler | None,
) -> CityBlock:
    """The block's edges of ``local`` in order, scored by the confidence."""
    degree = np.bincount(local.edges.ravel(), minlength=local.n_vertices)  # in the city graph, not just the block
    picked = np.flatnonzero(keep)
    picked = picked[_edge_order(local, picked, cores, mids)]
    graph, used = _subgraph_in_order(local, picked)
    cores = cores[picked]
    evidence = None
    if recipe.evidence and graph.n_edges:
        evidence = edge_evidence(graph, sample, cores[:, 0] * grid.n_cols + cores[:, 1], degree[used])
        if recipe.confidence is not None:
            graph = scored_graph(graph, recipe.confidence, evidence)
            kept = np.flatnonzero(graph.edge_scores >= recipe.min_confidence)
            graph, _ = _subgraph_in_order(graph, kept)
            cores, evidence = cores[kept], None  # the evidence described the edges before any was dropped
    return CityBlock(index, graph, cores, evidence)


def _edge_order(graph: BoundaryGraph, picked: np.ndarray, cores: np.ndarray, mids: np.ndarray) -> np.ndarray:
    """The order of the ``picked`` edges: by core (row-major), then midpoint (row, col), then
    the positions of u and of v, all exact numbers of the edge itself."""
    ends = graph.vertices[graph.edges[picked]].reshape(-1, 4)
    keys = (
        ends[:, 3],
        ends[:, 2],
        ends[:, 1],
        ends[:, 0],
        mids[picked, 0],
        mids[picked, 1],
        cores[picked, 1],
        cores[picked, 0],
    )
    return np.lexsort(keys).astype(np.int64)  # the last key sorts first


def _subgraph_in_order(graph: BoundaryGraph, edges: np.ndarray) -> tuple[BoundaryGraph, np.ndarray]:
    """The graph of ``edges`` in that order, its vertices numbered in order of first use; also
    the old index of each new vertex."""
    ends = graph.edges[edges].reshape(-1)
    used, first = np.unique(ends, return_index=True)
    used = used[np.argsort(first, kind="stable")]
    renumber = np.full(graph.n_vertices, -1, np.int64)
    renumber[used] = np.arange(len(used))
    pick = edges.tolist()
    return BoundaryGraph(
        graph.vertices[used],
        renumber[graph.edges[edges]].reshape(-1, 2),
        vertex_kinds=None if graph.vertex_kinds is None else [graph.vertex_kinds[i] for i in used.tolist()],
        edge_kinds=None if graph.edge_kinds is None else [graph.edge_kinds[k] for k in pick],
        edge_polylines=None if graph.edge_polylines is None else [graph.edge_polylines[k] for k in pick],
        edge_scores=None if graph.edge_scores is None else np.asarray(graph.edge_scores)[edges],
        edge_patches=None if graph.edge_patches is None else graph.edge_patches[edges],
        transform=graph.transform,
        crs=graph.crs,
    ), used
