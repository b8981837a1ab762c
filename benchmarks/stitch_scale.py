"""The city graph and its files against the number of patch graphs (NYC is ~51,000): time per patch
and peak memory of stitching plus writing the outputs, block by block as ``predict`` does.

    python benchmarks/stitch_scale.py 100 400 1600 6400 25600 [--one-pass] [--keep] [--block=N]

Each size runs in a fresh process (peak resident memory only grows within one). The patch graphs
are made on the fly, as the run store reads them from disk: a street grid of boundaries every
250 px (so lines cross every patch border and every overlap) cut to the patch's 1100 px window,
polylines of 40 px steps joined through degree-2 vertices, in mosaic pixels (~210 vertices per
patch: about three times a predicted patch graph). Every output is written (GeoPackage, GeoJSON,
graph.json) into a temporary folder and measured. ``--one-pass`` makes the city graph in one
piece, as before blocks (memory grows with the city); ``--keep`` also keeps the whole graph in
memory, as ``run_prediction`` does for scoring.

Prints, per size: patches, seconds, milliseconds per patch, the city graph's vertices, edges
and boundaries, the most vertices and edges the stream held at once, the files' sizes and this
process's peak resident memory (MB).
"""

from __future__ import annotations

import json
import math
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

SPACING = 250  # px between boundaries, both directions
STEP = 40  # px between vertices along a boundary
PIXEL_M = 0.15
CRS = "EPSG:32618"


def patch_graph(patch):
    """The grid's boundaries inside the patch's expanded window, in mosaic pixels."""
    from csboundary.graph import BoundaryGraph

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


def one(n: int, one_pass: bool, keep: bool, block: int | None = None) -> dict:
    from affine import Affine

    from csboundary.data.grid import PatchGrid
    from csboundary.data.units import ground_units
    from csboundary.pipeline.outputs.prediction_files import GraphWriter
    from csboundary.pipeline.prediction.city_blocks import CityCollector, CityGraphRecipe, stream_city_graph

    side = max(1, round(math.sqrt(n)))
    transform = Affine(PIXEL_M, 0, 580000, 0, -PIXEL_M, 4510000)
    grid = PatchGrid(side * 1000, side * 1000, transform)
    recipe = CityGraphRecipe(crs=CRS, **({"block": block} if block else {}))
    with tempfile.TemporaryDirectory(dir=Path(__file__).resolve().parents[1] / "runs") as tmp:
        files = {
            "gpkg": Path(tmp) / "boundaries.gpkg",
            "geojson": Path(tmp) / "boundaries.geojson",
            "graph_json": Path(tmp) / "graph.json",
        }
        writer = GraphWriter(files, CRS, transform, ground_units(CRS, transform * (0, 0)))
        collector = CityCollector(transform, CRS) if keep else None
        start = time.perf_counter()
        made = stream_city_graph(
            lambda index: patch_graph(grid.patch(*index)),
            grid,
            recipe,
            writer=writer.add,
            collector=collector,
            one_pass=one_pass,
        )
        counts = writer.close()
        seconds = time.perf_counter() - start
        sizes = {k: round(p.stat().st_size / 2**20, 1) for k, p in files.items()}
    return {
        "patches": len(grid),
        "seconds": round(seconds, 2),
        "ms_per_patch": round(seconds / len(grid) * 1000, 2),
        "vertices": counts["vertices"],
        "edges": counts["edges"],
        "boundaries": counts["boundaries"],
        "held_peak": made.held_peak,
        "files_mb": sizes,
        "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
        "stages": {k: round(v, 2) for k, v in made.seconds.items()},
    }


def main() -> None:
    args = sys.argv[1:]
    if args and args[0] == "--one":
        block = next((int(a.split("=")[1]) for a in args if a.startswith("--block=")), None)
        print(json.dumps(one(int(args[1]), "--one-pass" in args, "--keep" in args, block)))
        return
    flags = [a for a in args if a.startswith("--")]
    sizes = [int(a) for a in args if not a.startswith("--")] or [100, 400, 1600, 6400]
    print(f"mode: {'one pass' if '--one-pass' in flags else 'blocks'}{', graph kept' if '--keep' in flags else ''}")
    print("patches  seconds  ms/patch  vertices    edges  boundaries  held_peak  gpkg_mb  json_mb  peak_rss_mb")
    for n in sizes:
        out = subprocess.run(
            [sys.executable, __file__, "--one", str(n), *flags], check=True, capture_output=True, text=True
        ).stdout
        r = json.loads(out.strip().splitlines()[-1])
        print(
            f"{r['patches']:7d}  {r['seconds']:7.1f}  {r['ms_per_patch']:8.2f}  {r['vertices']:8d}  {r['edges']:7d}  "
            f"{r['boundaries']:10d}"
            f"  {r['held_peak']:9d}  {r['files_mb']['gpkg']:7.1f}  {r['files_mb']['graph_json']:7.1f}  {r['peak_rss_mb']:11.1f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
