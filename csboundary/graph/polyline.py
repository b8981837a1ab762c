"""Arc length along a polyline: the one definition every stage uses (edge lengths, spur pruning,
edge ownership by midpoint, label sampling along a boundary)."""

from __future__ import annotations

import numpy as np


def arc_lengths(points: np.ndarray) -> np.ndarray:
    """(N,) distance along the polyline from its first point to each point (0 for N <= 1)."""
    points = np.asarray(points, float).reshape(-1, 2)
    if len(points) < 2:
        return np.zeros(len(points))
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def polyline_length(points: np.ndarray) -> float:
    """Total length of a polyline (0 for fewer than two points)."""
    cumulative = arc_lengths(points)
    return float(cumulative[-1]) if len(cumulative) else 0.0
