"""A city of thousands of small tiles against the same pixels as one tile (issue 14).

    .venv/bin/python benchmarks/many_tiles.py [CITY] [--tile 220] [--nofile 256] [--work /tmp/many-tiles]

CITY (default data/cities/test-s0-2x2-5000, synthesized if missing) is rewritten twice: as one
GeoTIFF, and cut into TILE x TILE px GeoTIFFs (10000 px / 220 px -> 46 x 46 = 2116 tiles). Both run
``csboundary predict`` in a fresh process whose open-file limit is NOFILE (``ulimit -n``), one
after the other, with the same settings. Prints the tile count, seconds per patch of each (whole
run, and the read stage alone), their ratio (acceptance: within 10 %), and whether graph.json is
byte-identical (it should be: the same pixels).
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import rasterio
from rasterio.windows import Window


def _limit(nofile: int):
    return lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (nofile, nofile))


def write_tiles(source: Path, out: Path, tile: int | None) -> int:
    """The mosaic in ``source`` as one GeoTIFF (``tile`` None) or as ``tile``-px tiles; returns the count."""
    from csboundary.data.raster import Mosaic

    out.mkdir(parents=True, exist_ok=True)
    if any(out.glob("*.tif")):
        return len(list(out.glob("*.tif")))
    with Mosaic.open(source) as mosaic:
        size = tile or max(mosaic.width, mosaic.height)
        profile = {
            "driver": "GTiff",
            "count": 4,
            "dtype": "uint8",
            "crs": mosaic.crs,
            "tiled": size >= 512,
            **({"blockxsize": 512, "blockysize": 512} if size >= 512 else {}),
        }
        n = 0
        for row in range(0, mosaic.height, size):
            for col in range(0, mosaic.width, size):
                from csboundary.data.windows import PixelWindow

                win = PixelWindow(col, row, min(size, mosaic.width - col), min(size, mosaic.height - row))
                read = mosaic.read(win)
                transform = rasterio.windows.transform(Window(col, row, win.width, win.height), mosaic.transform)
                with rasterio.open(
                    out / f"t_{row:06d}_{col:06d}.tif",
                    "w",
                    width=win.width,
                    height=win.height,
                    transform=transform,
                    **profile,
                ) as dst:
                    dst.write(np.asarray(read.data, np.uint8))
                n += 1
    return n


def predict(tiles: Path, out: Path, nofile: int) -> dict:
    start = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "csboundary",
            "predict",
            str(tiles),
            "--out",
            str(out),
            "--device",
            "cpu",
            "--quiet",
            "--restart",
        ],
        check=True,
        preexec_fn=_limit(nofile),
        capture_output=True,
        text=True,
    )
    summary = json.loads((out / "summary.json").read_text())
    summary["wall_s"] = time.perf_counter() - start
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("city", nargs="?", type=Path, default=Path("data/cities/test-s0-2x2-5000"))
    parser.add_argument("--tile", type=int, default=220)
    parser.add_argument("--nofile", type=int, default=256)
    parser.add_argument("--work", type=Path, default=Path("/tmp/many-tiles"))
    args = parser.parse_args()
    if not (args.city / "city.json").exists():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "csboundary",
                "synth",
                str(args.city),
                "--seed",
                "0",
                "--split",
                "test",
                "--tiles",
                "2x2",
                "--tile-size",
                "5000",
                "--quiet",
            ],
            check=True,
        )
    one = write_tiles(args.city / "tiles", args.work / "one", None)
    many = write_tiles(args.city / "tiles", args.work / f"many-{args.tile}", args.tile)
    rows = {}
    for name, folder in (("one tile", args.work / "one"), (f"{many} tiles", args.work / f"many-{args.tile}")):
        summary = predict(folder, args.work / f"out-{folder.name}", args.nofile)
        n = summary["patches"]
        rows[name] = summary
        print(
            f"{name:>11s} (ulimit -n {args.nofile}): {n} patches, {summary['seconds']['total'] / n:.3f} s/patch "
            f"(read {summary['seconds']['read'] / n:.3f}), {summary['km2_per_hour']} km2/h, peak RSS "
            f"{summary['peak_rss_mb']['total']:.0f} MB",
            flush=True,
        )
    (a, b) = rows.values()
    ratio = (b["seconds"]["total"] / b["patches"]) / (a["seconds"]["total"] / a["patches"])
    same = (args.work / "out-one" / "graph.json").read_bytes() == (
        args.work / f"out-many-{args.tile}" / "graph.json"
    ).read_bytes()
    print(f"{one} vs {many} tiles: time per patch ratio {ratio:.3f} (limit 1.10); graph.json identical: {same}")


if __name__ == "__main__":
    main()
