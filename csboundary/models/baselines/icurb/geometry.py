"""Window-pixel geometry shared by the expert and the tracer: a closed box test (the feet of a
point on segments are csboundary.graph.polyline.segment_feet)."""

from __future__ import annotations

import numpy as np


def inside(points: np.ndarray, box: tuple[float, float, float, float], eps: float = 1e-6) -> np.ndarray:
    """Which points lie in the closed box (x0, y0, x1, y1)."""
    p = np.asarray(points).reshape(-1, 2)
    return (p[:, 0] >= box[0] - eps) & (p[:, 1] >= box[1] - eps) & (p[:, 0] <= box[2] + eps) & (p[:, 1] <= box[3] + eps)
