"""Graph stitching time and memory against the number of patch graphs (issue 14: NYC is ~51,000).

    python benchmarks/stitch_scale.py 100 400 1600 6400

Each patch graph is what the streaming pipeline hands the stitcher: a street grid of boundaries
every 250 px (so lines cross every patch border and every overlap) cut to the patch's 1100 px
window, as polylines of 40 px steps joined through degree-2 vertices, in mosaic pixels. Prints, per
size, the patch count, the stitching seconds, microseconds per patch, the city graph's size and
this process's peak resident memory.
"""

from __future__ import annotations

import math
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from csboundary.data.grid import PatchGrid  # noqa: E402
from csboundary.graph import BoundaryGraph  # noqa: E402
from csboundary.graph.stitching import stitch_patch_graphs  # noqa: E402

SPACING = 250  # px between boundaries, both directions
STEP = 40  # px between vertices along a boundary (~220 per patch: several times a predicted patch graph)


def patch_graph(patch) -> BoundaryGraph:
    """The grid's boundaries inside the patch's expanded window, in mosaic pixels."""
    w = patch.expanded
    lines = []
    for x in range(math.ceil(w.col_off / SPACING) * SPACING + 5, w.col_end, SPACING):
        rows = np.arange(w.row_off, w.row_end, STEP, dtype=float)
        lines.append(np.stack([np.full_like(rows, x), rows], axis=1))
    for y in range(math.ceil(w.row_off / SPACING) * SPACING + 5, w.row_end, SPACING):
        cols = np.arange(w.col_off, w.col_end, STEP, dtype=float)
        lines.append(np.stack([cols, np.full_like(cols, y)], axis=1))
    graph = BoundaryGraph.from_polylines(lines)
    return BoundaryGraph(graph.vertices, graph.edges, edge_scores=np.full(graph.n_edges, 0.9))


def main() -> None:
    sizes = [int(v) for v in sys.argv[1:]] or [100, 400, 1600]
    print("patches  seconds  us/patch  vertices  edges  peak_rss_mb")
    for n in sizes:
        side = max(1, round(math.sqrt(n)))
        grid = PatchGrid(side * 1000, side * 1000)
        graphs = {p.index: patch_graph(p) for p in grid}
        start = time.perf_counter()
        city = stitch_patch_graphs(graphs, grid)
        seconds = time.perf_counter() - start
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{len(grid):7d}  {seconds:7.2f}  {seconds / len(grid) * 1e6:8.0f}  {city.n_vertices:8d}  {city.n_edges:5d}  {rss:11.0f}")


if __name__ == "__main__":
    main()
