"""Peak memory of city-scale inference for cities of 1x1, 2x2, 3x3 (or more) tiles: memory is
bounded by a band of patches and a block of the city graph, not by the city.

Each size runs the city pipeline as `csboundary predict` does (shipped weights, the city graph
written block by block and not kept) in a fresh process (so peaks do not mix) and reports that
process's peak resident memory, the averager's peak map memory, the time and the seconds per
patch of graph stitching and of the edge confidence. Cities are synthesized (test split, seed 0) into CACHE unless already there.

Usage: .venv/bin/python benchmarks/city_memory.py [--tile-size 5000] [--sizes 1,2,3] [--cache data/cities]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

CHILD = """
import json, os, resource, sys, time
from csboundary.data.raster import Mosaic
from csboundary.models.device import resolve_device
from csboundary.pipeline.prediction.patch import PatchPredictor
from csboundary.pipeline.jobs.prediction_run import run_prediction
from csboundary.pipeline.prediction.options import PredictionOptions
start = time.perf_counter()
with Mosaic.open(sys.argv[1]) as mosaic:
    _, summary = run_prediction(mosaic, PatchPredictor.load(None, resolve_device("cpu")), sys.argv[2],
                                PredictionOptions(progress=False), keep_graphs=False)
print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "peak_rss_prediction_mb": summary["peak_rss_mb"]["prediction"],
                  "map_store_peak_mb": summary["map_store_peak_mb"], "patches": summary["patches"],
                  "seconds": time.perf_counter() - start, "edges": summary["counts"]["edges"],
                  "seconds_per_patch": summary["seconds_per_patch"], "outputs_s": summary["seconds"]["outputs"],
                  "files_mb": {name: round(os.path.getsize(os.path.join(sys.argv[2], name)) / 2**20, 2)
                               for name in ("graph.json", "boundaries.gpkg", "boundaries.geojson")}}))
"""


def city(cache: Path, n: int, tile_size: int) -> Path:
    path = cache / f"test-s0-{n}x{n}-{tile_size}"
    if not (path / "city.json").exists():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "csboundary",
                "synth",
                str(path),
                "--seed",
                "0",
                "--split",
                "test",
                "--tiles",
                f"{n}x{n}",
                "--tile-size",
                str(tile_size),
                "--quiet",
            ],
            check=True,
        )
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tile-size", type=int, default=5000)
    parser.add_argument("--sizes", default="1,2,3")
    parser.add_argument("--cache", type=Path, default=Path("data/cities"))
    args = parser.parse_args()
    rows = []
    for n in (int(v) for v in args.sizes.split(",")):
        tiles = city(args.cache, n, args.tile_size) / "tiles"
        with tempfile.TemporaryDirectory() as out:
            done = subprocess.run(
                [sys.executable, "-c", CHILD, str(tiles), out], check=True, capture_output=True, text=True
            )
        row = {"tiles": f"{n}x{n}", **json.loads(done.stdout.strip().splitlines()[-1])}
        rows.append(row)
        print(
            f"{row['tiles']:>4s} tiles of {args.tile_size} px: {row['patches']:4d} patches, peak RSS {row['peak_rss_mb']:7.1f} MB "
            f"(after the city pipeline {row['peak_rss_prediction_mb']:7.1f} MB; maps stored {row['map_store_peak_mb']:5.1f} MB), "
            f"{row['seconds']:6.1f} s; {row['edges']} edges; "
            f"s/patch graph stitching {row['seconds_per_patch']['graph_stitching']}, "
            f"confidence {row['seconds_per_patch']['confidence']}; outputs {row['outputs_s']:.1f} s; files (MB) {row['files_mb']}",
            flush=True,
        )
    if len(rows) > 1:
        growth = rows[-1]["peak_rss_mb"] / rows[0]["peak_rss_mb"] - 1
        print(f"peak RSS growth {rows[0]['tiles']} -> {rows[-1]['tiles']}: {100 * growth:+.1f} % (limit +20 %)")


if __name__ == "__main__":
    main()
