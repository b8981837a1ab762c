"""Vertices where the predicted boundary crosses the auxiliary grid lines (an inference option).

The paper gives straight boundaries their keypoints where they cross patch edges and "extra
lines". Those lines are a global grid, invisible in the pixels, so the FPN cannot learn them and
smears its keypoint heat along straight curbs instead; on real photographs that heat is weak and
straight road edges get no vertex. At inference the grid is known: with the standard patch grid
every 1100 px window starts 50 px before a 1000 px core, so the global lines every 250 px sit at
the same window columns and rows (50, 300, 550, ...) in every window, and the crossings two
overlapping windows find agree. Here they are the centres of the runs of the boundary map's
skeleton along those columns and rows, kept where no extracted vertex is already near.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from skimage.morphology import skeletonize


@dataclass(frozen=True)
class CrossingConfig:
    spacing_px: int = 0  # distance of the lines; 0 = off
    offset_px: int = 50  # first line's column/row in the window (the expanded patch's margin)
    threshold: float = 0.5  # boundary probability of the skeletonised mask
    min_distance_px: float = 12.0  # no crossing vertex this close to another vertex


def crossing_points(boundary: np.ndarray, config: CrossingConfig, existing: np.ndarray | None = None) -> np.ndarray:
    """(K, 2) continuous (x, y) points where the skeleton of ``boundary >= threshold`` crosses
    the lines x = offset + k * spacing and y = offset + k * spacing (pixel centres)."""
    if config.spacing_px <= 0:
        return np.zeros((0, 2))
    skeleton = skeletonize(np.asarray(boundary) >= config.threshold)
    h, w = skeleton.shape
    points = []
    for x in range(config.offset_px, w, config.spacing_px):
        points += [(x + 0.5, c + 0.5) for c in run_centres(skeleton[:, x])]
    for y in range(config.offset_px, h, config.spacing_px):
        points += [(c + 0.5, y + 0.5) for c in run_centres(skeleton[y, :])]
    kept: list[tuple[float, float]] = []
    others = np.asarray(existing, float).reshape(-1, 2) if existing is not None else np.zeros((0, 2))
    tree = cKDTree(others) if len(others) else None
    for p in points:
        if tree is not None and tree.query(p)[0] < config.min_distance_px:
            continue
        if any((p[0] - q[0]) ** 2 + (p[1] - q[1]) ** 2 < config.min_distance_px**2 for q in kept):
            continue
        kept.append(p)
    return np.array(kept, float).reshape(-1, 2)


def added_crossings(found, boundary: np.ndarray, config: CrossingConfig) -> np.ndarray:
    """(K, 2) crossings of ``boundary`` away from the extracted graph ``found``: its vertices and
    its corner runs' polylines (a run already traces the stretch it covers)."""
    if config.spacing_px <= 0:
        return np.zeros((0, 2))
    covered = np.concatenate([found.vertices, *(p for p in (found.edge_polylines or []) if p is not None)])
    return crossing_points(boundary, config, covered)


def run_centres(line: np.ndarray) -> list[float]:
    """Centres (indices) of the runs of True in a 1-D boolean array."""
    padded = np.concatenate([[False], line.astype(bool), [False]])
    edges = np.flatnonzero(padded[1:] != padded[:-1])
    starts, ends = edges[0::2], edges[1::2]
    return [(s + e - 1) / 2 for s, e in zip(starts, ends)]
