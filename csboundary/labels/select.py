"""Which boundaries reach a window, and whether a polyline stays inside one (closed bounds)."""

from __future__ import annotations

import numpy as np

from csboundary.data.windows import PixelWindow
from csboundary.labels.boundaries import Boundary

EPS = 1e-6  # px; keypoints computed on a window's edge line count as inside


def boundary_bounds(boundaries: list[Boundary]) -> np.ndarray:
    """(N, 4) min col, min row, max col, max row of every boundary (for fast window queries)."""
    if not boundaries:
        return np.zeros((0, 4))
    return np.array([[*b.points.min(axis=0), *b.points.max(axis=0)] for b in boundaries])


def near_window(bounds: np.ndarray, window: PixelWindow, pad: float = 0.0) -> np.ndarray:
    """Indices of boundaries whose bounding boxes reach ``window`` grown by ``pad`` px."""
    if len(bounds) == 0:
        return np.zeros(0, dtype=int)
    hit = (
        (bounds[:, 2] >= window.col_off - pad)
        & (bounds[:, 0] <= window.col_end + pad)
        & (bounds[:, 3] >= window.row_off - pad)
        & (bounds[:, 1] <= window.row_end + pad)
    )
    return np.flatnonzero(hit)


def inside(points: np.ndarray, window: PixelWindow, eps: float = EPS) -> np.ndarray:
    """Which points lie in the closed window [col_off, col_end] x [row_off, row_end]."""
    points = np.asarray(points).reshape(-1, 2)
    return (
        (points[:, 0] >= window.col_off - eps)
        & (points[:, 0] <= window.col_end + eps)
        & (points[:, 1] >= window.row_off - eps)
        & (points[:, 1] <= window.row_end + eps)
    )
