"""Time the synthetic city: plan (streets + scene) and render of one full-size 5000x5000 tile.

Usage: .venv/bin/python benchmarks/synth_render.py [--tiles 1x1] [--tile-size 5000]
Target (issue 2): a 5000x5000 tile renders in at most 20 s on one core.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2  # noqa: E402

cv2.setNumThreads(1)

from csboundary.data.geotiff import write_geotiff  # noqa: E402
from csboundary.data.synth.city import plan_city  # noqa: E402
from csboundary.data.synth.config import SynthConfig  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--tiles", default="2x2")
    parser.add_argument("--tile-size", type=int, default=5000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rows, cols = (int(v) for v in args.tiles.split("x"))
    config = SynthConfig(tile_size=args.tile_size)
    t0 = time.perf_counter()
    city = plan_city(config, "test", args.seed, (rows, cols))
    plan = time.perf_counter() - t0
    print(
        f"plan {rows}x{cols} city ({city.size_m[0]:.0f} x {city.size_m[1]:.0f} m): {plan:.2f} s "
        f"({plan / (rows * cols):.2f} s per tile); {len(city.scene.buildings)} buildings, {len(city.scene.trees)} trees, "
        f"{len(city.scene.cars)} cars"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for row in range(rows):
            for col in range(cols):
                t0 = time.perf_counter()
                image = city.render(row, col)
                render = time.perf_counter() - t0
                t0 = time.perf_counter()
                write_geotiff(f"{tmp}/t.tif", image, city.transform(row, col), config.crs)
                write = time.perf_counter() - t0
                print(
                    f"tile ({row},{col}) {args.tile_size}x{args.tile_size}: render {render:.2f} s, write GeoTIFF {write:.2f} s, "
                    f"plan share {plan / (rows * cols):.2f} s -> {render + write + plan / (rows * cols):.2f} s in all (one core)"
                )


if __name__ == "__main__":
    main()
