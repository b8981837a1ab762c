"""Picture of one patch's labels: segmentation and keypoint heat tinted over the image, edges
(normal orange, corner cyan along their polylines), vertices coloured by keypoint kind."""

from __future__ import annotations

import numpy as np

from csboundary.graph import BoundaryGraph
from csboundary.viz.overlay import draw_lines

KIND_COLOURS = {
    "corner": (255, 40, 40),  # red: ends of gathered (rounded-corner) runs, as in the paper's Fig. 7
    "isolated": (255, 230, 0),  # yellow: sharp corners and gradual curves
    "intersection": (60, 140, 255),  # blue: patch edges and auxiliary lines
    "end": (255, 255, 255),
    "skeleton": (255, 0, 255),  # magenta: ends of stretches filled in from the segmentation skeleton
}
EDGE_COLOURS = {"normal": (255, 150, 0), "corner": (0, 255, 255), "skeleton": (255, 0, 255)}


def draw_patch_labels(rgb: np.ndarray, arrays: dict[str, np.ndarray], graph: BoundaryGraph, core=None) -> np.ndarray:
    """Return ``rgb`` (h, w, 3) with the labels of the same window drawn over it."""
    import cv2

    out = (rgb.astype(np.float32) * 0.75).astype(np.float32)
    seg = arrays["segmentation"].astype(bool)
    out[seg] = out[seg] * 0.4 + np.array([0, 200, 120], np.float32) * 0.6
    heat = arrays["keypoint_heat"][..., None]
    out = out * (1 - 0.7 * heat) + np.array([255, 0, 255], np.float32) * 0.7 * heat
    out = np.clip(out, 0, 255).astype(np.uint8)
    for k in range(graph.n_edges):
        kind = (graph.edge_kinds or ["normal"] * graph.n_edges)[k]
        draw_lines(out, [graph.edge_polyline(k) - 0.5], EDGE_COLOURS.get(kind, (255, 150, 0)), 2)
    for i, p in enumerate(graph.vertices):
        kind = (graph.vertex_kinds or ["isolated"] * graph.n_vertices)[i]
        centre = tuple(int(v) for v in np.round((p - 0.5) * 8))
        cv2.circle(out, centre, 5 * 8, KIND_COLOURS.get(kind, (255, 255, 255)), -1, cv2.LINE_AA, shift=3)
        cv2.circle(out, centre, 5 * 8, (0, 0, 0), 1, cv2.LINE_AA, shift=3)
    if core is not None:
        x0, y0, x1, y1 = core
        cv2.rectangle(out, (x0, y0), (x1 - 1, y1 - 1), (255, 80, 80), 1)
    return out
