"""Time the labels of one 5000x5000 tile (25 patches): keypoints once, then every patch's maps,
graph and compressed files. Target (issue 3): at most 60 s on one core.

Usage: .venv/bin/python benchmarks/labels_speed.py [CITY_DIR]   (synthesizes a 1x1 city if none)
"""

from __future__ import annotations

import os
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import cv2  # noqa: E402

cv2.setNumThreads(1)

from csboundary.data.synth.city import synthesize_city  # noqa: E402
from csboundary.labels.writer import write_city_labels  # noqa: E402


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        city = sys.argv[1] if len(sys.argv) > 1 else f"{tmp}/city"
        if len(sys.argv) == 1:
            synthesize_city(city, seed=0, split="test", tiles=(1, 1), progress=False)
        t0 = time.perf_counter()
        manifest = write_city_labels(city, f"{tmp}/labels", progress=False)
        total = time.perf_counter() - t0
    c = manifest["counts"]
    print(
        f"{c['patches']} patches ({manifest['mosaic'][0]}x{manifest['mosaic'][1]} px): {total:.1f} s in all, "
        f"{manifest['seconds']['prepare']:.2f} s keypoints, {total / c['patches']:.2f} s per patch; "
        f"{c['vertices']} vertices, {c['edges']} edges ({c['corner_edges']} corner)"
    )


if __name__ == "__main__":
    main()
