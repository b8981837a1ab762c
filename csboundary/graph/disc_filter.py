"""Largest and smallest value within a disc around every pixel, in at most 160 passes over the
image whatever the radius (up to 200 px), instead of one visit per disc pixel.

OpenCV's dilate and erode with an elliptic kernel visit every kernel pixel for every image pixel:
at a radius of 200 px that is 126,000 visits per pixel (7 s per extreme on an 1100 px patch;
0.15 s here, benchmarks/surface_gate_speed.py). The disc is convex and centrally symmetric, so
its outline is a sum of straight steps (the edges of its convex hull, one of each opposite
pair): the extreme over the disc is taken one step at a time, each over the lattice points of a
segment (doubling: log2 passes). That sum of segments holds every disc pixel but a few near its
rim (where two steps are not unimodular), and those are taken run by run along their rows.
Maxima and minima are exact, so the result is OpenCV's to the bit (same kernel, border
replicated); small discs, as fast through OpenCV, go there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

OPENCV_UP_TO_PX = 12  # radii up to this are as fast through OpenCV's kernel


def disc_kernel(radius: int) -> np.ndarray:
    """OpenCV's elliptic kernel of ``radius`` ((2r + 1) x (2r + 1), uint8): the disc."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


@dataclass(frozen=True)
class DiscPlan:
    """The disc of one radius as ``steps`` ((dx, dy) primitive direction, number of lattice
    points) whose sum, moved by ``-centre``, lies in the disc, and the disc's offsets that the sum
    misses as ``rest`` runs along rows (first dx, dy, length)."""

    steps: tuple[tuple[tuple[int, int], int], ...]
    centre: tuple[int, int]
    rest: tuple[tuple[int, int, int], ...]


def hull_steps(kernel: np.ndarray) -> list[tuple[int, int]]:
    """Half of the edge vectors (dx, dy) of the convex hull of the kernel's pixels, in order
    round it: the other half are their opposites (the kernel is centrally symmetric)."""
    r = kernel.shape[0] // 2
    ends = [(int(cols[0]) - r, y - r) for y, row in enumerate(kernel) if len(cols := np.flatnonzero(row))]
    ends += [(int(cols[-1]) - r, y - r) for y, row in enumerate(kernel) if len(cols := np.flatnonzero(row))]
    points = sorted(set(ends))

    def turn(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for chain, sequence in ((lower, points), (upper, points[::-1])):
        for p in sequence:
            while len(chain) >= 2 and turn(chain[-2], chain[-1], p) <= 0:
                chain.pop()
            chain.append(p)
    hull = lower[:-1] + upper[:-1]
    edges = [(b[0] - a[0], b[1] - a[1]) for a, b in zip(hull, hull[1:] + hull[:1])]
    return edges[: len(edges) // 2]


@lru_cache(maxsize=None)
def disc_plan(radius: int) -> DiscPlan | None:
    """How :func:`disc_max` takes the disc of ``radius`` (None: not as a sum of steps, so
    OpenCV's kernel is used; never the case up to 200 px)."""
    kernel = disc_kernel(radius).astype(bool)
    steps = []
    for dx, dy in hull_steps(kernel.astype(np.uint8)):
        n = math.gcd(dx, dy)
        steps.append(((dx // n, dy // n), n + 1))
    centre = (sum((n - 1) * v[0] for v, n in steps) // 2, sum((n - 1) * v[1] for v, n in steps) // 2)
    delta = np.zeros((2 * radius + 1, 2 * radius + 1), np.uint8)
    delta[radius, radius] = 1
    covered = _sum_of_steps(np.pad(delta, radius), (-radius, -radius), steps, centre, delta.shape, np.maximum) > 0
    if (covered & ~kernel).any():
        return None
    rest = []
    for y, row in enumerate(kernel & ~covered):
        xs = np.flatnonzero(row)
        for run in np.split(xs, np.flatnonzero(np.diff(xs) > 1) + 1) if len(xs) else []:
            rest.append((int(run[0]) - radius, y - radius, len(run)))
    return DiscPlan(tuple(steps), centre, tuple(rest))


def disc_max(image: np.ndarray, radius: int) -> np.ndarray:
    """(H, W) float32: the largest value of ``image`` within the disc of ``radius`` px around each
    pixel, the border replicated (``cv2.dilate`` with :func:`disc_kernel`, to the bit)."""
    return _disc_extreme(image, radius, np.maximum, cv2.dilate)


def disc_min(image: np.ndarray, radius: int) -> np.ndarray:
    """(H, W) float32: the smallest value within the disc (``cv2.erode``, to the bit)."""
    return _disc_extreme(image, radius, np.minimum, cv2.erode)


def _disc_extreme(image: np.ndarray, radius: int, pick, opencv) -> np.ndarray:
    image = np.ascontiguousarray(image, np.float32)
    r = max(int(radius), 0)
    plan = disc_plan(r) if r > OPENCV_UP_TO_PX else None
    if plan is None:
        return opencv(image, disc_kernel(r), borderType=cv2.BORDER_REPLICATE)
    h, w = image.shape
    padded = cv2.copyMakeBorder(image, r, r, r, r, cv2.BORDER_REPLICATE)
    out = np.ascontiguousarray(_sum_of_steps(padded, (-r, -r), plan.steps, plan.centre, (h, w), pick))
    runs = [padded]  # runs[k]: the extreme over 2^k columns from each column
    for dx, dy, n in plan.rest:
        k = n.bit_length() - 1
        while len(runs) <= k:
            shift = 1 << (len(runs) - 1)
            runs.append(pick(runs[-1][:, :-shift], runs[-1][:, shift:]))
        for start in {dx, dx + n - (1 << k)}:  # two overlapping windows of 2^k cover the run
            pick(out, runs[k][r + dy : r + dy + h, r + start : r + start + w], out=out)
    return out


def _sum_of_steps(
    values: np.ndarray, origin: tuple[int, int], steps, centre: tuple[int, int], shape: tuple[int, int], pick
) -> np.ndarray:
    """The extreme over the sum of ``steps`` (moved by ``-centre``) at every pixel of an output
    of ``shape`` whose (0, 0) is ``values``' (-origin[1], -origin[0]) (rows, cols): each step
    taken on the part of the array where all its points are inside (the array shrinks)."""
    a, (ox, oy) = values, origin
    for (vx, vy), n in steps:
        b, bx, by = a, ox, oy
        reach = 1
        while 2 * reach <= n:  # b: the extreme over `reach` consecutive points
            b, bx, by = _shifted_pick(b, bx, by, vx * reach, vy * reach, pick)
            reach *= 2
        if reach < n:  # two overlapping runs of `reach` cover the n points
            b, bx, by = _shifted_pick(b, bx, by, vx * (n - reach), vy * (n - reach), pick)
        a, ox, oy = b, bx, by
    x0, y0 = -centre[0] - ox, -centre[1] - oy
    return a[y0 : y0 + shape[0], x0 : x0 + shape[1]]


def _shifted_pick(a: np.ndarray, ox: int, oy: int, dx: int, dy: int, pick) -> tuple[np.ndarray, int, int]:
    """``pick(a(q), a(q + (dx, dy)))`` wherever both are in ``a`` (whose (0, 0) is the point
    (ox, oy)), and the new array's (0, 0)."""
    h, w = a.shape
    near = a[max(-dy, 0) : h - max(dy, 0), max(-dx, 0) : w - max(dx, 0)]
    far = a[max(dy, 0) : h - max(-dy, 0), max(dx, 0) : w - max(-dx, 0)]
    return pick(near, far), ox + max(-dx, 0), oy + max(-dy, 0)
