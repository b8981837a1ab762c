"""Arc length along a polyline and the nearest point on one: the definitions every stage uses
(edge lengths, spur pruning, edge ownership by midpoint, label sampling along a boundary,
mending seams, the iCurb expert), and points along one at a fixed spacing."""

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


def segment_feet(a: np.ndarray, b: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Foot points of ``q`` on the segments a -> b ((N, 2) each): parameter t in [0, 1], foot, distance."""
    ab = b - a
    t = np.clip(((q - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0, 1)
    foot = a + t[:, None] * ab
    return t, foot, np.linalg.norm(q - foot, axis=-1)


def nearest_on_polyline(points: np.ndarray, q: np.ndarray) -> tuple[float, int, np.ndarray]:
    """Distance from ``q`` to a polyline of two or more points, the index k of the segment
    (points[k] -> points[k + 1]) that holds the nearest point, and that point (the first of equals)."""
    points = np.asarray(points, float).reshape(-1, 2)
    _, feet, distance = segment_feet(points[:-1], points[1:], np.asarray(q, float))
    k = int(np.argmin(distance))
    return float(distance[k]), k, feet[k]


def split_polyline(points: np.ndarray, k: int, at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two pieces of a polyline cut at ``at``, a point of its segment ``k``: points[:k + 1] + at
    and at + points[k + 1:]. A point equal to the cut is not repeated."""
    points = np.asarray(points, float).reshape(-1, 2)
    at = np.asarray(at, float).reshape(1, 2)
    head, tail = points[: k + 1], points[k + 1 :]
    if np.array_equal(head[-1:], at):
        head = head[:-1]
    if np.array_equal(tail[:1], at):
        tail = tail[1:]
    return np.concatenate([head, at]), np.concatenate([at, tail])


def dense_samples(points: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every <= ``step`` px along a polyline (ends included), and each one's segment index."""
    points = np.asarray(points, dtype=float)
    seg = np.diff(points, axis=0)
    lengths = np.linalg.norm(seg, axis=1)
    counts = np.maximum(np.ceil(lengths / step).astype(int), 1)
    index = np.repeat(np.arange(len(seg)), counts)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    t = (np.arange(counts.sum()) - np.repeat(starts, counts)) / np.repeat(counts, counts)
    samples = points[index] + seg[index] * t[:, None]
    return np.vstack([samples, points[-1:]]), np.concatenate([index, [len(seg) - 1]])


def points_along(line: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``step`` px along a polyline (middles of equal pieces) and the unit normal
    of the segment each lies on (left of the direction of travel in image axes; (0, 0) on a
    zero-length line)."""
    line = np.asarray(line, float)
    seg = np.diff(line, axis=0)
    cum = arc_lengths(line)
    seg_len, total = np.diff(cum), float(cum[-1]) if len(cum) else 0.0
    if total <= 0:
        return line[:1], np.zeros((1, 2))
    m = max(1, int(np.ceil(total / step)))
    at = (np.arange(m) + 0.5) * (total / m)
    which = np.clip(np.searchsorted(cum, at, side="right") - 1, 0, len(seg) - 1)
    t = (at - cum[which]) / np.maximum(seg_len[which], 1e-12)
    pts = line[which] + t[:, None] * seg[which]
    direction = seg[which] / np.maximum(seg_len[which], 1e-12)[:, None]
    return pts, np.stack([direction[:, 1], -direction[:, 0]], axis=1)


def polyline_between(points: np.ndarray, start: float, stop: float) -> np.ndarray:
    """The piece of a polyline from arc length ``start`` to ``stop`` (clipped to the line): its two
    ends interpolated, the vertices between them kept."""
    points = np.asarray(points, float).reshape(-1, 2)
    cum = arc_lengths(points)
    total = float(cum[-1]) if len(cum) else 0.0
    start, stop = min(max(start, 0.0), total), min(max(stop, 0.0), total)
    ends = np.stack([np.interp([start, stop], cum, points[:, 0]), np.interp([start, stop], cum, points[:, 1])], axis=1)
    inside = points[(cum > start) & (cum < stop)]
    return np.concatenate([ends[:1], inside, ends[1:]])
