"""The pixels a simulated review works on (:mod:`csboundary.metrics.review_time`): which predicted
pixels are kept and which ground-truth pixels they cover, updated action by action, so that F1@5
after every action is the pixel metric's (:func:`csboundary.metrics.pixel.relaxed_scores`)
without rasterising again.
"""

from __future__ import annotations

import copy

import numpy as np
from scipy.spatial import cKDTree

from csboundary.graph.polyline import points_along
from csboundary.metrics.pixel import f1_score, rasterize
from csboundary.metrics.segments import Segments


def line_pixels(line: np.ndarray) -> np.ndarray:
    """Distinct 1 px raster pixels (P, 2) of one polyline, as :func:`rasterize` draws them."""
    n = len(line)
    return rasterize(Segments(np.asarray(line, float), np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)))


_HALF = 1 << 30  # pixel coordinates within +-2^30 pack into one non-negative int64


def _keys(pixels: np.ndarray) -> np.ndarray:
    """One int64 per pixel (col, row), for sets and sorting."""
    return ((pixels[:, 0].astype(np.int64) + _HALF) << 32) | (pixels[:, 1].astype(np.int64) + _HALF)


def _pixels(keys: np.ndarray) -> np.ndarray:
    return np.stack([(keys >> 32) - _HALF, (keys & ((1 << 32) - 1)) - _HALF], axis=1)


class PixelState:
    """Which predicted pixels are kept and which ground-truth pixels they cover, updated piece by
    piece (``lines``: the pieces of the draft's boundaries) as pieces are deleted and runs drawn:
    F1@5 after every action without re-rasterising."""

    def __init__(self, piece_pixels: list[np.ndarray], gt_pixels: np.ndarray, within_px: float):
        self.within = within_px
        self.gt_tree = cKDTree(gt_pixels) if len(gt_pixels) else None
        self.gt_count = len(gt_pixels)
        rows, owner = [], []
        for k, px in enumerate(piece_pixels):
            rows.append(px)
            owner.append(np.full(len(px), k))
        rows = np.concatenate(rows) if rows else np.zeros((0, 2), np.int64)
        owner = np.concatenate(owner) if owner else np.zeros(0, np.int64)
        keys, pixel_of_row = np.unique(_keys(rows), return_inverse=True)
        self.pixel_of_row, self.owner = pixel_of_row.ravel(), owner
        self.rows_of_edge = np.split(
            np.argsort(owner, kind="stable"), np.cumsum(np.bincount(owner, minlength=len(piece_pixels)))[:-1]
        )
        self.keys = set(keys.tolist())
        self.unique_keys = keys
        unique_px = _pixels(keys)
        self.owners = np.bincount(self.pixel_of_row, minlength=len(keys))  # kept edges through each pixel
        self.pixel_true = self._near_gt(unique_px)
        self.kept, self.kept_true = len(keys), int(self.pixel_true.sum())
        # every (ground-truth pixel, predicted pixel) pair closer than within_px
        self.cover = np.zeros(self.gt_count, np.int64)
        self.pairs_of_pixel: list[np.ndarray] = [np.zeros(0, np.int64)] * len(keys)
        if self.gt_tree is not None and len(keys):
            pairs = cKDTree(unique_px).sparse_distance_matrix(
                self.gt_tree, np.nextafter(within_px, 0), output_type="ndarray"
            )
            p, g = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
            order = np.argsort(p, kind="stable")
            p, g = p[order], g[order]
            self.pairs_of_pixel = np.split(g, np.cumsum(np.bincount(p, minlength=len(keys)))[:-1])
            np.add.at(self.cover, g, 1)
        self.covered = int((self.cover > 0).sum())

    def copy(self) -> "PixelState":
        """An independent state (the arrays that change copied, the rest shared)."""
        other = copy.copy(self)
        other.owners, other.cover, other.keys = self.owners.copy(), self.cover.copy(), set(self.keys)
        return other

    def kept_pixels(self) -> np.ndarray:
        """(P, 2) pixels of the kept edges and of the runs drawn so far."""
        return _pixels(np.fromiter(self.keys, np.int64, len(self.keys)))

    def _near_gt(self, pixels: np.ndarray) -> np.ndarray:
        if self.gt_tree is None or not len(pixels):
            return np.zeros(len(pixels), bool)
        return self.gt_tree.query(pixels, k=1, distance_upper_bound=self.within)[0] < self.within

    def f1(self) -> float:
        p = self.kept_true / self.kept if self.kept else 0.0
        r = self.covered / self.gt_count if self.gt_count else float("nan")
        return f1_score(p, r)

    def edge_pixels(self, k: int) -> np.ndarray:
        """Indices of piece ``k``'s distinct pixels."""
        return np.unique(self.pixel_of_row[self.rows_of_edge[k]])

    def off_truth_px(self, k: int) -> int:
        """Pixels of piece ``k`` farther than ``within_px`` from the ground truth."""
        return int(np.count_nonzero(~self.pixel_true[self.edge_pixels(k)]))

    def delete(self, k: int, off_truth_only: bool = False) -> None:
        """Take piece ``k`` out, or only its pixels off the ground truth (a vertex moved onto the
        boundary: what stays is what was on it)."""
        pixels = self.edge_pixels(k)
        if off_truth_only:
            pixels = pixels[~self.pixel_true[pixels]]
        for pixel in pixels.tolist():
            self.owners[pixel] -= 1
            if self.owners[pixel] == 0:
                self.kept -= 1
                self.keys.discard(int(self.unique_keys[pixel]))
                self.kept_true -= int(self.pixel_true[pixel])
                g = self.pairs_of_pixel[pixel]
                self.cover[g] -= 1
                self.covered -= int(np.count_nonzero(self.cover[g] == 0))

    def draw(self, pixels: np.ndarray) -> None:
        """Add a traced run: its pixels count as kept (and true where near the ground truth), and
        cover the ground truth near them."""
        new = np.array([key not in self.keys for key in _keys(pixels).tolist()], bool)
        if not new.any():
            return
        pixels = pixels[new]
        self.keys.update(_keys(pixels).tolist())
        self.kept += len(pixels)
        self.kept_true += int(self._near_gt(pixels).sum())
        if self.gt_tree is not None:
            for g in self.gt_tree.query_ball_point(pixels, np.nextafter(self.within, 0)):
                g = np.asarray(g, np.int64)
                self.covered += int(np.count_nonzero(self.cover[g] == 0))
                self.cover[g] += 1


def piece_pixels(line: np.ndarray, pieces: list[np.ndarray]) -> list[np.ndarray]:
    """The raster pixels of ``line`` shared out among its ``pieces`` (each pixel to the piece
    nearest its centre), so the pieces together are exactly the line's raster, as the pixel
    metric draws it."""
    pixels = line_pixels(line)
    if len(pieces) == 1:
        return [pixels]
    samples = [points_along(piece, 0.5)[0] for piece in pieces]
    owner = np.concatenate([np.full(len(pts), k) for k, pts in enumerate(samples)])
    nearest = owner[cKDTree(np.concatenate(samples)).query(pixels + 0.5, k=1)[1]]
    return [pixels[nearest == k] for k in range(len(pieces))]
