"""The surface gate's cost against its radius, and predict with --surface-gate 200 against the
default (issue 65: a 200 px gate ran 40 times slower than the default).

    .venv/bin/python benchmarks/surface_gate_speed.py [--city CITY] [--opencv]

First the gate of one 1100 x 1100 patch (a street grid's surface) at radii 8 to 200 px, median of
3 runs, checked bit for bit against OpenCV's dilate and erode with the same elliptic kernel (the
old implementation; timed as well with --opencv: about a quarter of a minute per extreme at
200 px). With --city (e.g. a city made by ``csboundary synth CITY --tiles 1x1 --tile-size 2000``),
``csboundary predict`` runs on it with the shipped weights' default (no gate) and with
``--surface-gate 200``, and the wall seconds, summary.json's total seconds and the gated run's
ratio to the default are printed.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from csboundary.graph.disc_filter import disc_kernel
from csboundary.graph.surface_gate import SurfaceGateConfig, surface_change

RADII = (8, 25, 50, 100, 200)


def street_surface(size: int = 1100) -> np.ndarray:
    """A soft street grid: roadway 1, blocks 0, 3 px ramps at the curbs."""
    road = np.zeros((size, size), np.uint8)
    for k in range(60, size, 260):
        road[k : k + 70] = 1
        road[:, k : k + 70] = 1
    return cv2.GaussianBlur(road.astype(np.float32), (0, 0), 3)


def opencv_change(surface: np.ndarray, radius: int, full: float) -> np.ndarray:
    """The gate as it was computed: OpenCV's kernel over every pixel of the disc."""
    disc = disc_kernel(radius)
    spread = cv2.dilate(surface, disc, borderType=cv2.BORDER_REPLICATE) - cv2.erode(
        surface, disc, borderType=cv2.BORDER_REPLICATE
    )
    return np.clip(spread / np.float32(full), 0.0, 1.0)


def median_seconds(run, repeats: int = 3) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def patch_gate(opencv: bool) -> None:
    surface = street_surface()
    for radius in RADII:
        config = SurfaceGateConfig(radius_px=radius, min_piece_px=0)
        seconds, gate = median_seconds(lambda config=config: surface_change(surface, config))
        line = f"radius {radius:3d} px: {seconds:.3f} s"
        if opencv or radius <= 50:
            old_seconds, old = median_seconds(
                lambda radius=radius, config=config: opencv_change(surface, radius, config.full_change), 1
            )
            line += f"  (OpenCV's kernel {old_seconds:.3f} s, identical: {bool(np.array_equal(gate, old))})"
        print(line)


def predict_seconds(city: Path, out: Path, extra: tuple[str, ...]) -> tuple[float, float]:
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "csboundary", "predict", str(city), "--out", str(out), "--quiet", "--restart", *extra],
        check=True,
        capture_output=True,
    )
    wall = time.perf_counter() - start
    return wall, json.loads((out / "summary.json").read_text())["seconds"]["total"]


def predict_ratio(city: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        rows = {}
        for name, extra in (("default", ()), ("--surface-gate 200", ("--surface-gate", "200"))):
            rows[name] = predict_seconds(city, Path(tmp) / name.strip("-").replace(" ", "_"), extra)
            print(f"predict {city.name}, {name}: wall {rows[name][0]:.1f} s, summary total {rows[name][1]:.2f} s")
        (wall, total), (wall0, total0) = rows["--surface-gate 200"], rows["default"]
        print(f"gate 200 / default: wall {wall / wall0:.2f}x, summary total {total / total0:.2f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--city", type=Path, help="a city directory to run predict on, without and with --surface-gate 200"
    )
    parser.add_argument("--opencv", action="store_true", help="also time OpenCV's kernel at 100 and 200 px (slow)")
    args = parser.parse_args()
    patch_gate(args.opencv)
    if args.city is not None:
        predict_ratio(args.city)


if __name__ == "__main__":
    main()
