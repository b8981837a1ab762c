"""One whole tile rebuilt from its patches: pixels in place, missing patches masked, boundaries
re-joined across patch borders and put on the map.

The step between reading files (:mod:`.files`) and writing cities (:mod:`.cities`); it writes
nothing, so a tile can be inspected or joined with its neighbours before anything is stored.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import geopandas as gpd
import numpy as np
from affine import Affine
from shapely.geometry import LineString

from csboundary.data.raster_files import BANDS
from csboundary.data.topo_boundary.boundaries import Piece, join_pieces, pixels_to_line
from csboundary.data.topo_boundary.files import (
    LABEL_MARGIN,
    PATCH_SIZE,
    SPLITS,
    Patch,
    TopoBoundaryIndex,
    check_grid,
    clip_to_patch,
    inside_patch,
    parse_patch_id,
    patch_id,
    read_dense_seq,
    read_patch,
)
from csboundary.data.topo_boundary.placement import FALLBACK_CRS, FALLBACK_GSD, placed_transform, tile_georeference
from csboundary.errors import InputError, InputWarning


@dataclass
class AssembledTile:
    """A whole tile rebuilt from its patches, with its boundaries as world-coordinate LineStrings."""

    tile_id: str
    image: np.ndarray  # (4, H, W) uint8, 0 where no patch
    valid: np.ndarray  # (H, W) bool, False where a patch is missing
    transform: Affine
    crs: str
    georeferenced: bool
    patch_size: int
    splits: int
    patches: dict[str, Path]  # present patch id -> file
    missing: list[str]  # patch ids without an image
    unlabelled: list[str]  # present patch ids without a label file
    lines: list[LineString] = field(default_factory=list)
    line_sources: list[list[str]] = field(default_factory=list)  # patch ids each line came from
    chains: list[np.ndarray] = field(default_factory=list)  # the lines as joined [row, col] tile pixels
    placed: bool = False  # put on the map from its tile id (:func:`placed_transform`)

    @property
    def gsd(self) -> float:
        return float(self.transform.a)

    def ground_truth(self) -> gpd.GeoDataFrame:
        """The boundaries as the project's ground-truth frame (``source_patch``: comma-separated ids)."""
        return gpd.GeoDataFrame(
            {
                "source_patch": np.array([",".join(s) for s in self.line_sources], dtype=object),
                "tile_id": np.array([self.tile_id] * len(self.lines), dtype=object),
            },
            geometry=gpd.GeoSeries(self.lines, crs=self.crs),
            crs=self.crs,
        )


def assemble_tile(
    index: TopoBoundaryIndex, tile_id: str, patch_size: int = PATCH_SIZE, splits: int = SPLITS, placement: bool = True
) -> AssembledTile:
    """Reassemble tile ``tile_id``: patch (R, C) goes to rows R*ps.., cols C*ps..; boundaries re-joined.
    Without a georeference in the files, ``placement`` puts it on the map from its id."""
    check_grid(patch_size, splits)
    found = index.patches.get(tile_id, {})
    for (row, col), path in found.items():
        if row >= splits or col >= splits:
            raise InputError(path, f"block {row}{col} lies outside the {splits}x{splits} split")
    size = patch_size * splits
    image = np.zeros((BANDS, size, size), dtype=np.uint8)
    valid = np.zeros((size, size), dtype=bool)
    read: list[Patch] = []
    for (row, col), path in sorted(found.items()):
        patch = read_patch(path, row, col, patch_size)
        rows = slice(row * patch_size, (row + 1) * patch_size)
        cols = slice(col * patch_size, (col + 1) * patch_size)
        image[:, rows, cols] = patch.pixels
        valid[rows, cols] = True
        read.append(patch)
    transform, crs, georeferenced = tile_georeference(read, patch_size)
    placed = False
    if not georeferenced and placement and placed_transform(tile_id, FALLBACK_GSD, patch_size * splits) is not None:
        transform, placed = placed_transform(tile_id, FALLBACK_GSD, patch_size * splits), True
    elif not georeferenced:
        where = read[0].path if read else tile_id
        warnings.warn(
            f"{where}: tile {tile_id} is not georeferenced; placed at {FALLBACK_GSD} ft/px in {FALLBACK_CRS} "
            "with its top-left corner at (0, 0) (tile id recorded)",
            InputWarning,
            stacklevel=2,
        )

    all_ids = [patch_id(tile_id, r, c) for r in range(splits) for c in range(splits)]
    present = {patch_id(tile_id, r, c): p for (r, c), p in sorted(found.items())}
    missing = [pid for pid in all_ids if pid not in present]
    unlabelled = [pid for pid in present if pid not in index.labels]
    pieces = []
    for pid in all_ids:
        if pid in index.labels:
            _, row, col = parse_patch_id(pid)
            offset = np.array([row * patch_size, col * patch_size], dtype=float)
            seqs = read_dense_seq(index.labels[pid])
            kept = [part for seq in seqs if len(seq) for part in clip_to_patch(seq, patch_size)]
            outside = sum(int((~inside_patch(seq, patch_size)).sum()) for seq in seqs)
            if outside:
                warnings.warn(
                    f"{index.labels[pid]}: {outside} label point(s) lie more than {LABEL_MARGIN:g} px outside the "
                    f"{patch_size} px patch; the boundaries are clipped to it",
                    InputWarning,
                    stacklevel=2,
                )
            pieces.extend(Piece(pid, part + offset) for part in kept)
    joined = join_pieces(pieces)
    lines = [pixels_to_line(transform, points) for points, _ in joined]
    return AssembledTile(
        tile_id,
        image,
        valid,
        transform,
        crs,
        georeferenced,
        patch_size,
        splits,
        present,
        missing,
        unlabelled,
        lines,
        [sources for _, sources in joined],
        [points for points, _ in joined],
        placed,
    )
