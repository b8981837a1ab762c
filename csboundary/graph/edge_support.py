"""Edges the image supports: AfANet's candidate edges checked against the boundary map.

AfANet scores a pair of vertices from their embeddings; nothing in it asks whether a boundary
actually runs between them. On imagery unlike its training data it links distant vertices
with straight edges across blocks. A real boundary edge between two consecutive vertices lies
on the predicted boundary, so the mean boundary probability along the segment (the map
max-filtered over ``radius_px`` first, since a straight chord of a curved curb strays a few
pixels from it) tells the two apart; an edge longer than any plausible vertex spacing is
dropped outright.

Coordinates are continuous (x, y) pixels of the map, pixel [r, c] centred at (c + 0.5, r + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class EdgeSupportConfig:
    min_support: float = 0.0  # mean boundary probability along an edge; 0 = no check
    max_length_px: float = 0.0  # longest edge kept; 0 = no limit
    radius_px: int = 2  # max-filter radius of the boundary map before sampling
    max_gap_px: float = 0.0  # longest stretch of an edge below ``gap_level``; 0 = no check
    gap_level: float = 0.3  # boundary probability below which a sample is a gap

    @property
    def active(self) -> bool:
        return self.min_support > 0 or self.max_length_px > 0 or self.max_gap_px > 0


def widened(boundary: np.ndarray, radius_px: int) -> np.ndarray:
    """(h, w) boundary probability max-filtered over a (2r+1)-pixel square."""
    if radius_px <= 0:
        return np.asarray(boundary, np.float32)
    kernel = np.ones((2 * radius_px + 1, 2 * radius_px + 1), np.uint8)
    return cv2.dilate(np.asarray(boundary, np.float32), kernel)


def points_along(starts: np.ndarray, ends: np.ndarray):
    """Points every pixel (at least both ends) along each segment (K, 2) -> (K, 2): (points (N, 2),
    the segment of each point (N,), each segment's first point (K,), points per segment (K,))."""
    counts = np.maximum(2, np.ceil(np.linalg.norm(ends - starts, axis=1)).astype(int) + 1)
    segment = np.repeat(np.arange(len(starts)), counts)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    t = (np.arange(len(segment)) - first[segment]) / (counts - 1)[segment]
    return starts[segment] + (ends - starts)[segment] * t[:, None], segment, first, counts


def _sample_segments(support: np.ndarray, starts: np.ndarray, ends: np.ndarray):
    """``support`` sampled every pixel along each segment: (values, first sample of each segment,
    samples per segment). Samples outside the map are 0; a zero-length segment samples its point twice."""
    h, w = support.shape
    points, segment, first, counts = points_along(starts, ends)
    cols, rows = np.floor(points[:, 0]).astype(int), np.floor(points[:, 1]).astype(int)
    inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
    values = np.zeros(len(points))
    values[inside] = support[rows[inside], cols[inside]]
    return values, first, counts


def segment_support(support: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Mean of ``support`` (h, w) sampled every pixel along each segment (K, 2) -> (K,).

    Samples outside the map count as 0 (no evidence); a zero-length segment samples its point.
    """
    return segment_stats(support, starts, ends)[0]


def longest_gap(support: np.ndarray, starts: np.ndarray, ends: np.ndarray, level: float) -> np.ndarray:
    """Longest run of consecutive samples below ``level`` along each segment (K, 2) -> (K,), in
    samples (about pixels). A boundary occluded by a car or a crown has short gaps; a chord across
    a block has one long one, even where a roof outline lifts its mean."""
    return segment_stats(support, starts, ends, level)[1]


def segment_stats(
    support: np.ndarray, starts: np.ndarray, ends: np.ndarray, level: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """(mean, longest gap below ``level``) of ``support`` along each segment, from one sampling."""
    starts, ends = np.asarray(starts, float).reshape(-1, 2), np.asarray(ends, float).reshape(-1, 2)
    if len(starts) == 0:
        return np.zeros(0), np.zeros(0, np.int64)
    values, first, counts = _sample_segments(support, starts, ends)
    low = values < level
    index = np.arange(len(values))
    last_break = np.where(low, -1, index)  # the last sample at or before i that is not low
    last_break[first] = np.maximum(last_break[first], first - 1)  # runs restart at each segment
    run = np.where(low, index - np.maximum.accumulate(last_break), 0)
    return np.add.reduceat(values, first) / counts, np.maximum.reduceat(run, first)


def unsupported_pairs(
    vertices: np.ndarray, probs: np.ndarray, boundary: np.ndarray, threshold: float, config: EdgeSupportConfig
) -> np.ndarray:
    """(K, 2) vertex pairs (i < j) whose adjacency probability reaches ``threshold`` but whose
    edge is too long or not supported by the boundary map."""
    candidates = np.argwhere(np.triu(np.maximum(probs, probs.T) >= threshold, 1))
    if not config.active or len(candidates) == 0:
        return np.zeros((0, 2), np.int64)
    starts, ends = vertices[candidates[:, 0]], vertices[candidates[:, 1]]
    bad = np.zeros(len(candidates), bool)
    if config.max_length_px > 0:
        bad |= np.linalg.norm(ends - starts, axis=1) > config.max_length_px
    if config.min_support > 0 or config.max_gap_px > 0:
        check = ~bad  # too long already: no need to sample it
        mean, gap = segment_stats(widened(boundary, config.radius_px), starts[check], ends[check], config.gap_level)
        failed = np.zeros(len(mean), bool)
        if config.min_support > 0:
            failed |= mean < config.min_support
        if config.max_gap_px > 0:
            failed |= gap > config.max_gap_px
        bad[check] = failed
    return candidates[bad]
