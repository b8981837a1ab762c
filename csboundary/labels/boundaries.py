"""Ground-truth boundaries as pixel polylines in the mosaic's frame, resampled for analysis."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from affine import Affine

from csboundary.data.windows import world_to_pixel
from csboundary.graph.polyline import arc_lengths


@dataclass(frozen=True)
class Boundary:
    """One road boundary: vertices (N, 2) as mosaic pixel (col, row); ``closed`` rings repeat
    their first point at the end."""

    points: np.ndarray
    closed: bool

    @property
    def cumulative(self) -> np.ndarray:
        """Arc length at every vertex (N,)."""
        return arc_lengths(self.points)

    @property
    def length(self) -> float:
        return float(self.cumulative[-1])

    def at(self, s: np.ndarray) -> np.ndarray:
        """Points at arc lengths ``s`` (exact: linear interpolation on the original polyline)."""
        cum = self.cumulative
        s = np.clip(np.asarray(s, dtype=float), 0.0, cum[-1])
        return np.stack([np.interp(s, cum, self.points[:, 0]), np.interp(s, cum, self.points[:, 1])], axis=-1)

    def between(self, s0: float, s1: float) -> np.ndarray:
        """The sub-polyline from arc length ``s0`` to ``s1`` (``s1 < s0`` wraps on a ring)."""
        cum = self.cumulative
        if s1 < s0 and self.closed:
            first = self.between(s0, cum[-1])
            second = self.between(0.0, s1)
            return np.concatenate([first, second[1:]])
        inner = (cum > s0) & (cum < s1)
        return np.concatenate([self.at([s0]), self.points[inner], self.at([s1])])


def clean_polyline(points: np.ndarray) -> np.ndarray:
    """Drop consecutive duplicate vertices (zero-length segments carry no direction)."""
    points = np.asarray(points, dtype=float)[:, :2]
    if len(points) < 2:
        return points
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-9])
    return points[keep]


def boundaries_from_world(lines, transform: Affine) -> list[Boundary]:
    """World LineStrings -> pixel Boundaries in the frame of ``transform`` (a mosaic's)."""
    out = []
    for line in lines:
        xy = np.asarray(line.coords)[:, :2]
        cols, rows = world_to_pixel(transform, xy[:, 0], xy[:, 1])
        pts = clean_polyline(np.stack([cols, rows], axis=1))
        if len(pts) >= 2:
            closed = bool(np.allclose(pts[0], pts[-1])) and len(pts) > 3
            if closed:
                pts[-1] = pts[0]
            out.append(Boundary(pts, closed))
    return out
