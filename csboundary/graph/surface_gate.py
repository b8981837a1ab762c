"""Boundary evidence only where the roadway ends: the FPN's keypoint and boundary maps gated by
the change of its road-surface map.

On real photographs the boundary map fires on every outline (flat roofs, parapets, rows of
parked cars, lots and fields), while the surface map separates roadway from the rest far
better. A road boundary is where roadway meets something else, so its pixels are where the
surface changes: the local range of the surface (largest minus smallest probability within
``radius_px``) is near 1 along a curb, near 0 on a roof (no roadway on either side) and along a
row of cars (roadway on both sides). Multiplying the keypoint and boundary maps by that range,
scaled so that a change of ``full_change`` or more keeps the map as it is, removes the vertices
and skeleton stretches that no roadway edge explains before any graph is built; the boundary
map still places the edge to the pixel inside the band the surface allows.

Roadway pieces of fewer than ``min_piece_px`` pixels that do not reach the window's border
(a lot, a courtyard or a field the surface head mistook for road) are cut off from the network:
they and a 4 px fringe are treated as no roadway before the range is taken.

The disc's extremes come from :mod:`csboundary.graph.disc_filter` (OpenCV's elliptic kernel to
the bit, in time that grows with the radius, not its square: a 200 px gate took 14 s per 1100 px
patch, now 0.3 s), and the gate of a patch is kept for the next call on the same surface (the
maps are gated once to find vertices and again to connect them: it was computed twice).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import cv2
import numpy as np

from csboundary.graph.disc_filter import disc_max, disc_min


@dataclass(frozen=True)
class SurfaceGateConfig:
    radius_px: float = 0.0  # how far from a pixel the surface change is looked for; 0 = no gate
    full_change: float = 0.6  # a surface range this large or larger leaves the maps unchanged
    min_piece_px: int = 20000  # roadway pieces smaller than this, away from the window's border, are not roadway
    level: float = 0.5  # surface probability that counts as roadway when finding pieces
    outline: float = (
        0.0  # the roadway's outline enters the boundary map at this probability where the gated map is weak; 0 = off
    )
    mode: str = (
        "range"  # range: gate = local range of the surface; sides: no-roadway-near x not-inside-roadway (softer)
    )
    far_px: float = 40.0  # sides: roadway is looked for this far
    far_level: float = 0.3  # sides: roadway this sure within far_px keeps the maps
    inside_level: float = 0.3  # sides: 1 - smallest surface within radius_px this large keeps the maps

    @property
    def active(self) -> bool:
        return self.radius_px > 0


def roadway_pieces_kept(surface: np.ndarray, level: float, min_piece_px: int) -> np.ndarray:
    """(H, W) bool: pixels of roadway (``surface >= level``) in 8-connected pieces of at least
    ``min_piece_px`` pixels or touching the border (a piece cut by the window may be large
    beyond it)."""
    road = (surface >= level).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(road, connectivity=8)
    if n <= 1:
        return road.astype(bool)
    h, w = surface.shape
    x, y, bw, bh, area = (stats[:, i] for i in range(5))
    touches = (x == 0) | (y == 0) | (x + bw == w) | (y + bh == h)
    keep = (area >= min_piece_px) | touches
    keep[0] = False  # background
    return keep[labels]


def surface_change(surface: np.ndarray, config: SurfaceGateConfig) -> np.ndarray:
    """(H, W) float32 in [0, 1]: the gate, the local range of the surface probability within a
    disc of ``radius_px`` divided by ``full_change`` and clipped at 1; roadway pieces too small
    to be part of the network read as 0 first."""
    surface = np.asarray(surface, np.float32)
    if config.min_piece_px > 0:
        dropped = ((surface >= config.level) & ~roadway_pieces_kept(surface, config.level, config.min_piece_px)).astype(
            np.uint8
        )
        if dropped.any():  # the piece and its soft fringe read as no roadway
            fringe = cv2.dilate(dropped, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9)))
            surface = np.where(fringe > 0, np.float32(0), surface)
    r = max(int(round(config.radius_px)), 1)
    if config.mode == "sides":
        near_road = disc_max(surface, max(int(round(config.far_px)), 1))
        not_inside = 1.0 - disc_min(surface, r)
        return np.clip(near_road / np.float32(config.far_level), 0, 1) * np.clip(
            not_inside / np.float32(config.inside_level), 0, 1
        )
    spread = disc_max(surface, r) - disc_min(surface, r)
    return np.clip(spread / np.float32(config.full_change), 0.0, 1.0)


_last = threading.local()  # per thread: the last surface gated and its gate


def patch_surface_change(surface: np.ndarray, config: SurfaceGateConfig) -> np.ndarray:
    """:func:`surface_change`, from the last call in this thread when ``surface`` and ``config``
    are the same again (read-only: it is shared)."""
    surface = np.asarray(surface, np.float32)
    kept = getattr(_last, "entry", None)
    if kept is not None and kept[0] == config and kept[1].shape == surface.shape and np.array_equal(kept[1], surface):
        return kept[2]
    gate = surface_change(surface, config)
    gate.flags.writeable = False
    _last.entry = (config, surface.copy(), gate)
    return gate


def roadway_outline(surface: np.ndarray, config: SurfaceGateConfig) -> np.ndarray:
    """(H, W) bool: the 1 px inner outline of the kept roadway (see
    :func:`roadway_pieces_kept`), not along the window's border."""
    road = roadway_pieces_kept(np.asarray(surface, np.float32), config.level, config.min_piece_px).astype(np.uint8)
    inner = cv2.erode(road, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)
    return (road > 0) & (inner == 0)


def gated_maps(maps: np.ndarray, surface_channel: int, config: SurfaceGateConfig) -> np.ndarray:
    """``maps`` (C, H, W) with its keypoint and boundary channels (0 and 1) multiplied by
    :func:`surface_change` of channel ``surface_channel``; with ``outline``, the roadway's outline
    drawn into the boundary channel at that probability wherever the gated boundary map stays
    below 0.5 within ``radius_px`` (a curb under trees or behind cars, which the skeleton fill
    then turns into edges). Unchanged when the gate is off or the maps carry no surface."""
    if not config.active or maps.shape[0] <= surface_channel:
        return maps
    gate = patch_surface_change(maps[surface_channel], config)
    out = np.array(maps, copy=True)
    out[0] *= gate
    out[1] *= gate
    if config.outline > 0:
        near = disc_max(
            out[1], max(int(round(config.radius_px)), 1)
        )  # what OpenCV's dilate gives with its default border
        add = roadway_outline(maps[surface_channel], config) & (near < 0.5)
        out[1] = np.where(add, np.maximum(out[1], np.float32(config.outline)), out[1])
    return out
