"""Boundary geometry in tile pixels: re-joining the pieces that the patch cut split, and turning
a pixel chain into a smooth world-coordinate LineString.

Pure: it knows nothing of files or tiles, so the same joining serves patches within a tile
(:mod:`.tiles`) and tiles within a city (:mod:`.seams`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from affine import Affine
from scipy.spatial import cKDTree
from shapely.geometry import LineString

from csboundary.data.windows import pixel_to_world

SIMPLIFY_PX = 0.5  # staircase pixel chains -> straight runs (see pixels_to_line)
SMOOTH_PIXELS = 5
JOIN_TOLERANCE = 1.5  # px; > sqrt(2) so diagonal neighbours across a border are joined


@dataclass(frozen=True)
class Piece:
    """One labelled boundary in tile pixels (``[row, col]``), and the patch it came from."""

    patch: str
    points: np.ndarray  # (n, 2) [row, col] in tile pixels


def join_pieces(pieces: list[Piece], tolerance: float = JOIN_TOLERANCE) -> list[tuple[np.ndarray, list[str]]]:
    """Re-join boundaries that the patch cut split: ``[(points [row, col], source patches)]``.

    An end of a piece is joined to an end of a piece from another patch when the two lie within
    ``tolerance`` px (they then sit on either side of a patch border); the closest pairs are joined
    first and each end joins at most once, so chains never fork. Pieces chain in both directions
    from the earliest piece, keeping its orientation; chains whose ends join close into rings.
    One-point pieces take part (a boundary can clip a patch corner by one pixel); chains with fewer
    than 2 distinct points are dropped.
    """
    if not pieces:
        return []
    ends = np.array([[p.points[0], p.points[-1]] for p in pieces], dtype=float).reshape(-1, 2)
    pairs = cKDTree(ends).query_pairs(tolerance + 1e-9, output_type="ndarray")
    pairs = [(i, j) for i, j in pairs.tolist() if pieces[i // 2].patch != pieces[j // 2].patch]
    pairs.sort(key=lambda ij: (float(np.hypot(*(ends[ij[0]] - ends[ij[1]]))), min(ij), max(ij)))
    link: dict[int, int] = {}  # end index (2 * piece + 0/1) -> joined end index
    for i, j in pairs:
        if i not in link and j not in link:
            link[i], link[j] = j, i

    visited = [False] * len(pieces)
    out = []
    for start in range(len(pieces)):
        if visited[start]:
            continue
        visited[start] = True
        chain: list[tuple[int, bool]] = [(start, True)]  # (piece, forward)
        closed = False
        end = 2 * start + 1  # walk forward from the start piece's last point
        while end in link:
            nxt = link[end]
            piece, entered = divmod(nxt, 2)
            if piece == start:
                closed = True
                break
            if visited[piece]:
                break
            visited[piece] = True
            chain.append((piece, entered == 0))
            end = 2 * piece + (1 - entered)
        if not closed:
            end = 2 * start  # and backward from its first point
            while end in link:
                piece, entered = divmod(link[end], 2)
                if visited[piece]:
                    break
                visited[piece] = True
                chain.insert(0, (piece, entered == 1))
                end = 2 * piece + (1 - entered)
        points = np.concatenate([pieces[k].points if fwd else pieces[k].points[::-1] for k, fwd in chain])
        if closed:
            points = np.concatenate([points, points[:1]])
        points = _drop_repeats(points)
        if len(points) < 2:
            continue
        sources = list(dict.fromkeys(pieces[k].patch for k, _ in chain))
        out.append((points, sources))
    return out


def _drop_repeats(points: np.ndarray) -> np.ndarray:
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.any(points[1:] != points[:-1], axis=1)
    return points[keep]


def pixels_to_line(transform: Affine, points: np.ndarray, simplify_px: float = SIMPLIFY_PX) -> LineString:
    """A LineString through the centres of tile pixels ``[row, col]`` in world coordinates.

    The labels are chains of every pixel, i.e. staircases whose direction jumps by 45 or 90
    degrees at each step; curvature keypoints need the boundary's real direction. So, unless
    ``simplify_px`` is 0, the chain is first averaged over ``SMOOTH_PIXELS`` consecutive pixels
    (ends kept; rings wrap), which removes the steps while moving a 40 px curb return by
    < 0.1 px, then simplified (Douglas-Peucker, ``simplify_px``).
    """
    xy = np.column_stack([points[:, 1] + 0.5, points[:, 0] + 0.5]).astype(float)
    if simplify_px > 0 and len(xy) > 2:
        xy = _smooth_chain(xy, SMOOTH_PIXELS)
        xy = np.asarray(LineString(xy).simplify(simplify_px, preserve_topology=True).coords)
    xs, ys = pixel_to_world(transform, xy[:, 0], xy[:, 1])
    return LineString(np.column_stack([xs, ys]))


def _smooth_chain(xy: np.ndarray, window: int) -> np.ndarray:
    """Moving average along a chain; rings (first == last) wrap, open chains keep their ends."""
    half = window // 2
    if len(xy) <= window:
        return xy
    closed = np.array_equal(xy[0], xy[-1])
    body = xy[:-1] if closed else xy
    kernel = np.ones(window) / window
    if closed:
        padded = np.concatenate([body[-half:], body, body[:half]])
        out = np.column_stack([np.convolve(padded[:, k], kernel, mode="valid") for k in (0, 1)])
        return np.vstack([out, out[:1]])
    out = body.copy()
    out[half:-half] = np.column_stack([np.convolve(body[:, k], kernel, mode="valid") for k in (0, 1)])
    return out
