"""Raster labels of a window: boundary segmentation, orientation, and keypoint heat.

Lines are rasterised by dense sampling in global pixel coordinates (a sample at continuous
(col, row) marks pixel [floor(row), floor(col)]) rather than by a line-drawing routine: a
routine clips at the image edge and starts its stepping there, which can shift pixels by one
between two patches. Every map is computed on the window grown by its reach and then cropped,
so overlapping patches get identical values in their overlap.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from csboundary.data.windows import PixelWindow
from csboundary.graph.polyline import dense_samples
from csboundary.labels.boundaries import Boundary
from csboundary.labels.keypoints import BoundaryKeypoints
from csboundary.labels.select import near_window

SAMPLE_STEP = 0.25  # px between samples along a line: every crossed pixel gets at least one


def _grown(window: PixelWindow, pad: int) -> PixelWindow:
    return PixelWindow(window.col_off - pad, window.row_off - pad, window.width + 2 * pad, window.height + 2 * pad)


def _burn(image: np.ndarray, origin: PixelWindow, samples: np.ndarray, values) -> None:
    """Set the pixels under ``samples`` (global coordinates) to ``values``, inside ``origin``."""
    cols = np.floor(samples[:, 0]).astype(np.int64) - origin.col_off
    rows = np.floor(samples[:, 1]).astype(np.int64) - origin.row_off
    ok = (cols >= 0) & (cols < origin.width) & (rows >= 0) & (rows < origin.height)
    image[rows[ok], cols[ok]] = values[ok] if isinstance(values, np.ndarray) else values


def _widen(image: np.ndarray, width: int) -> np.ndarray:
    """Grow 1 px lines to ``width`` px with a round structuring element."""
    if width <= 1:
        return image
    return cv2.dilate(image, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (width, width)))


def segmentation_label(
    boundaries: list[Boundary], bounds: np.ndarray, window: PixelWindow, width: int = 3
) -> np.ndarray:
    """(h, w) uint8, 1 on boundary pixels: boundaries drawn ``width`` px wide."""
    pad = width
    big = _grown(window, pad)
    out = np.zeros((big.height, big.width), np.uint8)
    for b in near_window(bounds, big):
        samples, _ = dense_samples(boundaries[b].points, SAMPLE_STEP)
        _burn(out, big, samples, 1)
    return _widen(out, width)[pad:-pad, pad:-pad]


def orientation_label(
    boundaries: list[Boundary], bounds: np.ndarray, window: PixelWindow, width: int = 3, bins: int = 64
) -> tuple[np.ndarray, np.ndarray]:
    """Boundary direction on boundary pixels (Batra et al. 2019).

    Returns (2, h, w) float32 unit vectors (d col, d row), 0 off the boundary, and (h, w) uint8
    bin codes as Topo-boundary stores them: 0 background, else 1 + floor(angle / (360/bins)) with
    angle measured counter-clockwise from +col with rows pointing down (atan2(-d row, d col)).
    Direction follows the vertex order of the ground-truth LineString; where two boundaries
    come within ``width`` px, the later segment wins.
    """
    pad = width
    big = _grown(window, pad)
    index = np.zeros((big.height, big.width), np.float32)  # segment ids; exact below 2**24
    tables = [np.zeros((1, 2))]
    offset = 1
    for b in near_window(bounds, big):
        pts = boundaries[b].points
        seg = np.diff(pts, axis=0)
        norm = np.linalg.norm(seg, axis=1, keepdims=True)
        tables.append(seg / np.where(norm > 0, norm, 1.0))
        samples, which = dense_samples(pts, SAMPLE_STEP)
        _burn(index, big, samples, (which + offset).astype(np.float32))
        offset += len(seg)
    index = _widen(index, width)[pad:-pad, pad:-pad].astype(np.int64)
    table = np.concatenate(tables).astype(np.float32)
    vectors = np.moveaxis(table[index], -1, 0)
    angle = np.degrees(np.arctan2(-table[:, 1], table[:, 0])) % 360.0
    codes = np.minimum(1 + np.floor(angle / (360.0 / bins)), bins).astype(np.uint8)
    codes[0] = 0
    return vectors, codes[index]


def keypoint_heat(
    keypoints: list[BoundaryKeypoints], bounds: np.ndarray, window: PixelWindow, sigma: float = 3.0
) -> np.ndarray:
    """(h, w) float32 in [0, 1]: exp(-d^2 / 2 sigma^2), d = distance from the pixel to the nearest
    keypoint pixel or gathered-run pixel ("keypoint map", paper IV-B). Seeds up to 4 sigma
    outside the window count too."""
    pad = int(math.ceil(4 * sigma)) + 1
    big = _grown(window, pad)
    seeds = np.zeros((big.height, big.width), np.uint8)
    for b in near_window(bounds, big):
        kp = keypoints[b]
        _burn(seeds, big, kp.points, 1)
        for a, e in kp.runs:
            samples, _ = dense_samples(kp.boundary.between(a, e), SAMPLE_STEP)
            _burn(seeds, big, samples, 1)
    if not seeds.any():
        return np.zeros((window.height, window.width), np.float32)
    distance = cv2.distanceTransform((seeds == 0).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    heat = np.exp(-(distance**2) / (2 * sigma * sigma)).astype(np.float32)
    return heat[pad : pad + window.height, pad : pad + window.width]
