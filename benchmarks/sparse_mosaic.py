"""A huge, mostly empty GeoTIFF against its data alone (issue 43).

    .venv/bin/python benchmarks/sparse_mosaic.py [--size 100000] [--corner 5000] [--work /tmp/sparse]

Writes the classic test city's first CORNER x CORNER px twice: as its own GeoTIFF, and into the
top-left corner of a SIZE x SIZE px GeoTIFF whose other blocks are never written (tiled 512 px,
deflate, sparse, nodata 0: how a city inside its bounding box is often delivered). Runs
``csboundary predict`` on each in a fresh process and prints the seconds of each, their ratio
(acceptance: at most 1.5) and how many patches were skipped as empty.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import rasterio
from rasterio.windows import Window


def write(path: Path, data: np.ndarray, size: int, profile: dict) -> None:
    profile = dict(
        profile,
        width=size,
        height=size,
        tiled=True,
        blockxsize=512,
        blockysize=512,
        compress="deflate",
        nodata=0,
        SPARSE_OK=True,
    )
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(data, window=Window(0, 0, data.shape[2], data.shape[1]))


def predict(image: Path, out: Path) -> tuple[float, dict]:
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "csboundary", "predict", str(image), "--out", str(out), "--quiet", "--restart"],
        capture_output=True,
        text=True,
    )
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(done.stderr)
    return seconds, {"stderr": done.stderr.strip(), **json.loads((out / "summary.json").read_text())}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--size", type=int, default=100_000)
    parser.add_argument("--corner", type=int, default=5000)
    parser.add_argument("--city", type=Path, default=Path("data/cities/test-s1-1x1-5000"))
    parser.add_argument("--work", type=Path, default=Path("/tmp/sparse"))
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    tile = sorted((args.city / "tiles").glob("*.tif"))[0]
    with rasterio.open(tile) as src:
        data = src.read(window=Window(0, 0, args.corner, args.corner))
        profile = {k: src.profile[k] for k in ("driver", "count", "dtype", "crs", "transform")}
    data = np.where(data == 0, 1, data).astype(
        data.dtype
    )  # no pixel of the data equals nodata (a black pixel stays data)
    corner, sparse = args.work / "corner.tif", args.work / "sparse.tif"
    write(corner, data, args.corner, profile)
    write(sparse, data, args.size, profile)
    print(f"{sparse}: {sparse.stat().st_size / 2**20:.1f} MB on disk for {args.size} x {args.size} px")
    t_corner, s_corner = predict(corner, args.work / "out-corner")
    t_sparse, s_sparse = predict(sparse, args.work / "out-sparse")
    print(f"corner alone: {t_corner:.1f} s, {s_corner['patches']} patches, {s_corner['counts']['edges']} edges")
    print(
        f"sparse mosaic: {t_sparse:.1f} s, {s_sparse['patches']} patches ({s_sparse['patches_without_imagery']} without imagery), "
        f"{s_sparse['counts']['edges']} edges"
    )
    print(f"ratio {t_sparse / t_corner:.2f} (acceptance: at most 1.5)")
    if s_sparse["stderr"]:
        print("said:", s_sparse["stderr"])


if __name__ == "__main__":
    main()
