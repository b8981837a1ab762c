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
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class SurfaceGateConfig:
    radius_px: float = 0.0  # how far from a pixel the surface change is looked for; 0 = no gate
    full_change: float = 0.6  # a surface range this large or larger leaves the maps unchanged
    min_piece_px: int = 20000  # roadway pieces smaller than this, away from the window's border, are not roadway
    level: float = 0.5  # surface probability that counts as roadway when finding pieces
    outline: float = 0.0  # the roadway's outline enters the boundary map at this probability where the gated map is weak; 0 = off
    mode: str = "range"  # range: gate = local range of the surface; sides: no-roadway-near x not-inside-roadway (softer)
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
        dropped = ((surface >= config.level) & ~roadway_pieces_kept(surface, config.level, config.min_piece_px)).astype(np.uint8)
        if dropped.any():  # the piece and its soft fringe read as no roadway
            fringe = cv2.dilate(dropped, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9)))
            surface = np.where(fringe > 0, np.float32(0), surface)
    r = max(int(round(config.radius_px)), 1)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    if config.mode == "sides":
        f = max(int(round(config.far_px)), 1)
        near_road = cv2.dilate(surface, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * f + 1, 2 * f + 1)),
                               borderType=cv2.BORDER_REPLICATE)
        not_inside = 1.0 - cv2.erode(surface, disc, borderType=cv2.BORDER_REPLICATE)
        return np.clip(near_road / np.float32(config.far_level), 0, 1) * np.clip(not_inside / np.float32(config.inside_level), 0, 1)
    spread = cv2.dilate(surface, disc, borderType=cv2.BORDER_REPLICATE) - cv2.erode(surface, disc, borderType=cv2.BORDER_REPLICATE)
    return np.clip(spread / np.float32(config.full_change), 0.0, 1.0)


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
    gate = surface_change(maps[surface_channel], config)
    out = np.array(maps, copy=True)
    out[0] *= gate
    out[1] *= gate
    if config.outline > 0:
        r = max(int(round(config.radius_px)), 1)
        near = cv2.dilate(out[1], cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)))
        add = roadway_outline(maps[surface_channel], config) & (near < 0.5)
        out[1] = np.where(add, np.maximum(out[1], np.float32(config.outline)), out[1])
    return out
