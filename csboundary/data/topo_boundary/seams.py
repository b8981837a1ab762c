"""Where placed tiles meet: their boundaries re-joined across shared tile edges into one frame,
and the share of border ends that find a partner in the neighbour.

The second is the check on the placement from tile ids: right, most boundaries continue; wrong,
almost none do. Both serve the split cities (:mod:`.cities`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from affine import Affine
from scipy.spatial import cKDTree
from shapely.geometry import LineString

from csboundary.data.topo_boundary.boundaries import Piece, join_pieces, pixels_to_line
from csboundary.data.topo_boundary.tiles import AssembledTile


def border_continuity(tiles: list[AssembledTile], tolerance: float = 3.0, band: float = 2.0) -> dict[str, Any]:
    """How well the placement lets boundaries continue across shared tile edges.

    For each boundary end within ``band`` px of a tile edge that a neighbouring tile shares, is
    there an end of a boundary of the neighbour within ``tolerance`` px of it? A wrong placement
    leaves almost every border end alone; the right one matches most (a few end at a missing
    patch). Returns ``{"border_ends": n, "matched": m, "share": m / n}`` (share None without ends).
    """
    if not tiles:
        return {"border_ends": 0, "matched": 0, "share": None}
    gsd = tiles[0].transform.a
    west = min(t.transform.c for t in tiles)
    north = max(t.transform.f for t in tiles)
    ends, owner, near_edge = [], [], []
    boxes = {}
    for k, tile in enumerate(tiles):
        size = tile.patch_size * tile.splits
        off = np.array([(north - tile.transform.f) / gsd, (tile.transform.c - west) / gsd])
        boxes[k] = (off[0], off[1], off[0] + size, off[1] + size)
        for chain in tile.chains:
            for point in (chain[0], chain[-1]):
                local = point
                edge = min(local[0], local[1], size - 1 - local[0], size - 1 - local[1]) <= band
                ends.append(point + off)
                owner.append(k)
                near_edge.append(edge)
    ends, owner, near_edge = np.array(ends).reshape(-1, 2), np.array(owner), np.array(near_edge, dtype=bool)
    shared = np.zeros(len(ends), dtype=bool)
    for i in np.flatnonzero(near_edge):  # only ends on an edge some other tile lies beyond
        r, c = ends[i]
        shared[i] = any(
            k != owner[i] and b[0] - band - 1 <= r <= b[2] + band and b[1] - band - 1 <= c <= b[3] + band
            for k, b in boxes.items()
        )
    if not shared.any():
        return {"border_ends": 0, "matched": 0, "share": None}
    tree = cKDTree(ends)
    matched = 0
    for i in np.flatnonzero(shared):
        partners = tree.query_ball_point(ends[i], tolerance)
        matched += any(owner[j] != owner[i] for j in partners)
    n = int(shared.sum())
    return {"border_ends": n, "matched": int(matched), "share": matched / n}


def join_tiles(tiles: list[AssembledTile]) -> tuple[Affine, list[LineString], list[list[str]]]:
    """The tiles' boundaries in one frame, re-joined across shared tile edges: (transform of the
    frame's top-left, LineStrings in world coordinates, source tile ids per line)."""
    gsd = tiles[0].transform.a
    west = min(t.transform.c for t in tiles)
    north = max(t.transform.f for t in tiles)
    pieces = []
    for tile in tiles:
        off = np.array([round((north - tile.transform.f) / gsd), round((tile.transform.c - west) / gsd)], dtype=float)
        pieces.extend(Piece(tile.tile_id, chain + off) for chain in tile.chains)
    frame = Affine(gsd, 0.0, west, 0.0, -gsd, north)
    joined = join_pieces(pieces)
    return frame, [pixels_to_line(frame, points) for points, _ in joined], [sources for _, sources in joined]
