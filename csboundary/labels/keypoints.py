"""Keypoints of road boundaries (paper Section IV-B), uniquely determined in global coordinates.

Paper: "we ... define pixels whose orientation has large enough differences with adjacent
pixels as keypoints"; "within each image patch, we define the intersection points of the
road-boundary and image edges as keypoints"; "we add extra lines to create more intersection
points as auxiliary keypoints"; corner keypoints "could be gathered keypoints at rounded-corners
... or isolated keypoints locating at curve road boundaries with sharp corners or gradual
curvature changes". Each rule below quotes the sentence it implements.

Everything is computed on whole boundaries in mosaic pixels, against global lines (the 1000 px
grid, the 1100 px expanded edges, a finer auxiliary grid), never per patch, so two patches see
identical keypoints wherever they overlap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from csboundary.labels.boundaries import Boundary
from csboundary.labels.config import LabelConfig

ISOLATED = "isolated"  # a sharp corner, or a gradual curve that has turned enough
CORNER = "corner"  # an endpoint of a gathered run (rounded corner)
INTERSECTION = "intersection"  # a crossing with a patch edge or an auxiliary line
END = "end"  # where an open boundary ends (the edge of the data)
_PRIORITY = {END: 3, CORNER: 2, INTERSECTION: 1, ISOLATED: 0}


@dataclass
class BoundaryKeypoints:
    """Keypoints of one boundary as sorted arc lengths ``s``, their kinds, and gathered runs."""

    boundary: Boundary
    s: np.ndarray
    kinds: list[str]
    runs: list[tuple[float, float]] = field(default_factory=list)  # (start, end); end < start wraps a ring

    @property
    def points(self) -> np.ndarray:
        return self.boundary.at(self.s)

    def in_run(self, s: float) -> bool:
        for a, b in self.runs:
            if (a <= s <= b) if a <= b else (s >= a or s <= b):
                return True
        return False

    def stretches(self) -> list[tuple[int, int]]:
        """Index pairs of consecutive keypoints (with the wrap-around pair on a ring)."""
        k = len(self.s)
        pairs = [(i, i + 1) for i in range(k - 1)]
        if self.boundary.closed and k >= 2:
            pairs.append((k - 1, 0))
        return pairs

    def stretch_midpoint(self, i: int, j: int) -> float:
        a, b = self.s[i], self.s[j]
        if b < a:  # wraps on a ring
            length = self.boundary.length
            return float((a + (b + length - a) / 2) % length)
        return float((a + b) / 2)


def compute_keypoints(boundaries: list[Boundary], config: LabelConfig = LabelConfig()) -> list[BoundaryKeypoints]:
    """Keypoints of every boundary: curvature (gathered and isolated), intersections, ends."""
    return [boundary_keypoints(b, config) for b in boundaries]


def boundary_keypoints(boundary: Boundary, config: LabelConfig = LabelConfig()) -> BoundaryKeypoints:
    length = boundary.length
    candidates: list[tuple[float, str]] = []
    runs, isolated = curvature_keypoints(boundary, config)
    for a, b in runs:
        candidates += [(a, CORNER), (b, CORNER)]
    candidates += [(s, ISOLATED) for s in isolated]
    candidates += [(s, INTERSECTION) for s in intersection_keypoints(boundary, config)]
    if not boundary.closed:
        candidates += [(0.0, END), (length, END)]
    s, kinds = _merge(candidates, config.min_separation_px, length if boundary.closed else None)
    if boundary.closed:
        s, kinds = _at_least_three(s, kinds, length)
    return BoundaryKeypoints(boundary, s, kinds, runs)


def _at_least_three(s: np.ndarray, kinds: list[str], length: float) -> tuple[np.ndarray, list[str]]:
    """A ring needs three vertices to be a polygon in a graph (two give one edge, i.e. half of
    it): split the longest gap between keypoints until there are three."""
    s, kinds = list(s), list(kinds)
    while len(s) < 3:
        if not s:
            s, kinds = [0.0], [ISOLATED]
            continue
        gaps = [((s[(i + 1) % len(s)] - s[i]) % length or length, i) for i in range(len(s))]
        gap, i = max(gaps)
        s.append((s[i] + gap / 2) % length)
        kinds.append(ISOLATED)
        order = np.argsort(s)
        s, kinds = [s[k] for k in order], [kinds[k] for k in order]
    return np.array(s, dtype=float), kinds


def _merge(
    candidates: list[tuple[float, str]], separation: float, ring_length: float | None
) -> tuple[np.ndarray, list[str]]:
    """Keypoints closer than ``separation`` along the boundary are one; the higher kind wins."""
    if ring_length is not None:
        candidates = [(s % ring_length, k) for s, k in candidates]
    candidates.sort(key=lambda c: (c[0], -_PRIORITY[c[1]]))
    kept: list[list] = []
    for s, kind in candidates:
        if kept and s - kept[-1][0] < separation:
            if _PRIORITY[kind] > _PRIORITY[kept[-1][1]]:
                kept[-1] = [s, kind]
            continue
        kept.append([s, kind])
    if ring_length is not None and len(kept) > 1 and kept[0][0] + ring_length - kept[-1][0] < separation:
        last = kept.pop()
        if _PRIORITY[last[1]] > _PRIORITY[kept[0][1]]:
            kept[0] = last
            kept.sort(key=lambda c: c[0])
    return np.array([k[0] for k in kept], dtype=float), [k[1] for k in kept]


# -- curvature ------------------------------------------------------------------------------------


def _turning(boundary: Boundary) -> tuple[np.ndarray, np.ndarray, float]:
    """Resample at ~1 px ("neighbouring pixels") and return (arc lengths, signed turn per sample, step)."""
    length = boundary.length
    n = max(int(round(length)), 2)
    step = length / n
    if boundary.closed:
        s = np.arange(n) * step
        pts = boundary.at(s)
        before, after = pts - np.roll(pts, 1, axis=0), np.roll(pts, -1, axis=0) - pts
    else:
        s = np.arange(n + 1) * step
        pts = boundary.at(s)
        before = np.vstack([[np.nan, np.nan], pts[1:-1] - pts[:-2], [np.nan, np.nan]])
        after = np.vstack([[np.nan, np.nan], pts[2:] - pts[1:-1], [np.nan, np.nan]])
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    dot = (before * after).sum(axis=1)
    turn = np.nan_to_num(np.arctan2(cross, dot))
    turn[np.abs(turn) < 1e-9] = 0.0  # straight up to rounding
    return s, turn, step


def _headings(boundary: Boundary, s: np.ndarray, half: float) -> np.ndarray:
    """Unwrapped direction of the chord from s - half to s + half at every arc length ``s``."""
    if boundary.closed:
        length = boundary.length
        ahead, behind = boundary.at((s + half) % length), boundary.at((s - half) % length)
    else:
        ahead, behind = boundary.at(s + half), boundary.at(s - half)
    d = ahead - behind
    return np.unwrap(np.arctan2(d[:, 1], d[:, 0]))


def _middle_of_longest(mask: np.ndarray) -> int:
    """Index in the middle of the longest cyclic stretch where ``mask`` is True (0 if none)."""
    if not mask.any():
        return 0
    if mask.all():
        return 0
    start = int(np.argmin(mask))  # a False index: no True stretch wraps past it
    rolled = np.roll(mask, -start)
    a, b = max(_true_runs(rolled), key=lambda r: r[1] - r[0])
    return (start + (a + b) // 2) % len(mask)


def _true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal [start, end] index intervals where ``mask`` is True (linear)."""
    padded = np.concatenate([[False], mask, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]


def curvature_keypoints(
    boundary: Boundary, config: LabelConfig = LabelConfig()
) -> tuple[list[tuple[float, float]], list[float]]:
    """Gathered runs (start, end arc lengths) and isolated curvature keypoints (arc lengths).

    Paper: "pixels whose orientation has large enough differences with adjacent pixels" are
    keypoints. The turning between 1 px steps is averaged over ``smoothing_px`` steps so that
    polygonised arcs read as a steady turn; where it exceeds ``turn_rate_deg_per_px`` the
    boundary is a corner. Runs of one sign closer than ``merge_gap_px`` are one corner; each
    run's ends are then refined to the first and last step that actually turns.
    """
    s, turn, step = _turning(boundary)
    width = max(1, int(config.smoothing_px))
    rate = _turn_rate(turn, boundary.closed, width, step)
    threshold = math.radians(config.turn_rate_deg_per_px)

    calm = np.abs(rate) <= threshold
    if boundary.closed and not calm.any() and abs(turn.sum()) > math.pi:  # a round island
        half = boundary.length / 2
        return [(0.0, half), (half, 0.0)], []
    # On a ring, work in a frame that starts in the middle of the longest calm stretch, so that
    # no corner straddles index 0.
    shift = _middle_of_longest(calm) if boundary.closed else 0
    order = np.roll(np.arange(len(s)), -shift)
    turn_o = turn[order]
    merged = _merged_turning_runs(rate[order], threshold, config.merge_gap_px / step)
    corners = _corners(merged, turn_o, width // 2 + 1, config.min_corner_turn_deg)
    runs: list[tuple[float, float]] = []
    isolated: list[float] = []
    busy = np.zeros(len(s), dtype=bool)
    for a, b in corners:
        busy[a : b + 1] = True
        if (b - a) * step >= config.gather_min_length_px:
            runs.append((float(s[order[a]]), float(s[order[b]])))
        else:  # "isolated keypoints locating at ... sharp corners": the turn-weighted centre
            w = np.abs(turn_o[a : b + 1])
            centre = float(np.sum((np.arange(a, b + 1)) * w) / w.sum())
            isolated.append(float((s[order[0]] + centre * step) % (boundary.length if boundary.closed else np.inf)))
    isolated += _gradual_keypoints(boundary, s[order], busy, step, width, config.gradual_turn_deg)
    return runs, isolated


def _turn_rate(turn: np.ndarray, closed: bool, width: int, step: float) -> np.ndarray:
    """The turning per px, averaged over ``width`` steps of ``step`` px (wrapping round a ring)."""
    kernel = np.ones(width) / (width * step)
    if closed:
        padded = np.concatenate([turn[-width:], turn, turn[:width]])
        return np.convolve(padded, kernel, mode="same")[width:-width]
    return np.convolve(turn, kernel, mode="same")


def _merged_turning_runs(rate: np.ndarray, threshold: float, gap: float) -> list[list[int]]:
    """(start, end, sign) of the steps turning faster than ``threshold``, sorted; runs of one sign
    at most ``gap`` steps apart are one, merged per sign so that a blip of the other sign cannot
    split a corner."""
    merged: list[list[int]] = []
    for sign in (1, -1):
        for a, b in _true_runs(sign * rate > threshold):
            if merged and merged[-1][2] == sign and a - merged[-1][1] <= gap:
                merged[-1][1] = b
            else:
                merged.append([a, b, sign])
    merged.sort()
    return merged


def _corners(merged: list[list[int]], turn: np.ndarray, reach: int, min_turn_deg: float) -> list[tuple[int, int]]:
    """Each merged run's first and last step that truly turns its way (looking ``reach`` steps
    beyond it, where the averaging smeared it), kept when it turns at least ``min_turn_deg``."""
    n, corners = len(turn), []
    for a, b, sign in merged:
        idx = np.arange(max(0, a - reach), min(n - 1, b + reach) + 1)
        turning = idx[sign * turn[idx] > 1e-6]
        if len(turning) == 0:
            continue
        a, b = int(turning[0]), int(turning[-1])
        if not abs(float(turn[a : b + 1].sum())) < math.radians(min_turn_deg):
            corners.append((a, b))
    return corners


def _gradual_keypoints(
    boundary: Boundary, s: np.ndarray, busy: np.ndarray, step: float, width: int, turn_deg: float
) -> list[float]:
    """ "isolated keypoints locating at curve road boundaries with ... gradual curvature changes":
    outside corners (``busy`` steps and those whose chord reaches into one), one keypoint each
    time the boundary's direction (a chord over +-width/2, robust to polygonised or pixel-chain
    input) has turned ``turn_deg`` since the last curvature keypoint. ``s``: the steps' arc
    lengths in the order they are walked."""
    limit = math.radians(turn_deg)
    half = max(1.0, width / 2)
    heading = _headings(boundary, s, half)
    near = int(math.ceil(half / step)) + 1  # chords reaching into a corner still see it turn
    busy = np.convolve(busy.astype(int), np.ones(2 * near + 1, dtype=int), mode="same") > 0
    keypoints, reference = [], None
    for i in range(len(s)):
        if busy[i]:
            reference = None
        elif reference is None:
            reference = heading[i]
        elif abs(heading[i] - reference) >= limit:
            keypoints.append(float(s[i]))
            reference = heading[i]
    return keypoints


# -- intersections -------------------------------------------------------------------------------


def keypoint_lines(lo: float, hi: float, config: LabelConfig = LabelConfig()) -> np.ndarray:
    """Global line positions (one axis) between ``lo`` and ``hi``: patch core edges (k*core),
    expanded edges (k*core +- margin) and auxiliary lines (k*aux_spacing)."""
    core, margin, aux = config.grid.core, config.grid.margin, config.aux_spacing_px
    k_core = np.arange(math.floor((lo - margin) / core) - 1, math.ceil((hi + margin) / core) + 2) * core
    values = [k_core, k_core - margin, k_core + margin]
    if aux > 0:
        values.append(np.arange(math.floor(lo / aux) - 1, math.ceil(hi / aux) + 2) * aux)
    v = np.unique(np.concatenate(values).astype(float))
    return v[(v >= lo) & (v <= hi)]


def intersection_keypoints(boundary: Boundary, config: LabelConfig = LabelConfig()) -> list[float]:
    """Arc lengths where the boundary meets a global keypoint line (either axis).

    Paper: "we define the intersection points of the road-boundary and image edges as
    keypoints" (edges of this and the adjacent patches) and "we add extra lines to create more
    intersection points as auxiliary keypoints".
    """
    pts, cum = boundary.points, boundary.cumulative
    out: list[float] = []
    for axis in (0, 1):
        x = pts[:, axis]
        lines = keypoint_lines(float(x.min()), float(x.max()), config)
        if len(lines) == 0:
            continue
        x0, x1 = x[:-1], x[1:]
        lo, hi = np.minimum(x0, x1), np.maximum(x0, x1)
        first = np.searchsorted(lines, lo, side="left")
        last = np.searchsorted(lines, hi, side="right")
        for i in np.flatnonzero(last > first):
            if x1[i] == x0[i]:
                continue  # runs along the line: its ends are where it meets the crossing lines
            v = lines[first[i] : last[i]]
            t = (v - x0[i]) / (x1[i] - x0[i])
            out.extend((cum[i] + t * (cum[i + 1] - cum[i])).tolist())
    return out
