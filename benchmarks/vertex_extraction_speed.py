"""Time vertex extraction on a 1100x1100 keypoint map with 150 pieces (100 blobs, 50 arcs).

Usage: .venv/bin/python benchmarks/vertex_extraction_speed.py
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from csboundary.graph.vertex_extraction import extract_vertices


def main() -> None:
    seeds = np.full((1100, 1100), 255, np.uint8)
    cells = [(35 + 70 * i, 35 + 70 * j) for j in range(16) for i in range(16)][:150]
    for k, (x, y) in enumerate(cells):
        if k < 100:
            seeds[y, x] = 0
        else:
            cv2.ellipse(seeds, (x - 12, y - 12), (25, 25), 0, 0, 90, 0, 1)
    distance = cv2.distanceTransform(seeds, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    prob = np.exp(-(distance**2) / (2 * 3.0**2)).astype(np.float32)
    extract_vertices(prob)
    times = []
    for _ in range(5):
        start = time.perf_counter()
        graph = extract_vertices(prob)
        times.append(time.perf_counter() - start)
    print(
        f"1100x1100 map, 150 pieces: {graph.n_vertices} vertices, {graph.n_edges} corner edges; median {np.median(times):.3f} s"
    )


if __name__ == "__main__":
    main()
