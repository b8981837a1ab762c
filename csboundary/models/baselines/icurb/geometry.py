"""Window-pixel geometry shared by the expert and the tracer: a closed box test and the feet of
a point on segments."""

from __future__ import annotations

import numpy as np


def inside(points: np.ndarray, box: tuple[float, float, float, float], eps: float = 1e-6) -> np.ndarray:
    """Which points lie in the closed box (x0, y0, x1, y1)."""
    p = np.asarray(points).reshape(-1, 2)
    return (p[:, 0] >= box[0] - eps) & (p[:, 1] >= box[1] - eps) & (p[:, 0] <= box[2] + eps) & (p[:, 1] <= box[3] + eps)


def segment_feet(a: np.ndarray, b: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foot points of ``q`` on segments a->b: parameter t, foot, distance."""
    ab = b - a
    t = np.clip(((q - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0, 1)
    foot = a + t[:, None] * ab
    return t, foot, np.linalg.norm(q - foot, axis=-1)
