"""The city-wide patch grid (paper Section IV-A).

One global grid of ``core x core`` patches (default 1000 px) covers the whole mosaic, not each
tile, so patches straddle tile borders freely. Each patch is expanded by ``margin`` px on every
side (default 50 -> 1100x1100) so that neighbours overlap by ``2 * margin`` px; those overlaps are
where keypoint maps are averaged and patch graphs are stitched (paper IV-E).

Cores at the right and bottom edge are clipped to the mosaic so the cores cover every mosaic
pixel exactly once; expanded windows always have the full size and are read padded.

A grid given the mosaic's footprint (groups of tiles kilometres apart: data/footprint.py) plans
only the patches whose cores meet it (``planned``; None when the footprint is the whole mosaic):
iterating, counting and neighbours skip the rest, an unplanned neighbour is treated as the
mosaic's edge, and the gaps between the groups cost nothing. Every patch of the rectangle can
still be asked for by index.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator, Sequence

from affine import Affine

from csboundary.data.footprint import cells_meeting
from csboundary.data.windows import PixelWindow, pixel_to_world, window_transform, world_to_pixel


@dataclass(frozen=True)
class GridConfig:
    """Core patch size and the margin added on every side (paper: 1000 and 50)."""

    core: int = 1000
    margin: int = 50

    def __post_init__(self) -> None:
        if self.core <= 0 or self.margin < 0:
            raise ValueError(f"core must be > 0 and margin >= 0, got core={self.core}, margin={self.margin}")

    @property
    def size(self) -> int:
        """Side of an expanded patch."""
        return self.core + 2 * self.margin


@dataclass(frozen=True)
class Patch:
    """One grid cell: its core (clipped to the mosaic) and its expanded window, in mosaic pixels."""

    row: int
    col: int
    core: PixelWindow
    expanded: PixelWindow
    transform: Affine  # world transform of the expanded window's pixel (0, 0)

    @property
    def index(self) -> tuple[int, int]:
        return self.row, self.col

    @property
    def core_local(self) -> PixelWindow:
        """The core in the expanded patch's own pixel coordinates."""
        return self.core.relative_to(self.expanded)

    def to_local(self, cols, rows):
        """Mosaic pixel coordinates -> this patch's pixel coordinates."""
        return cols - self.expanded.col_off, rows - self.expanded.row_off

    def to_global(self, cols, rows):
        """This patch's pixel coordinates -> mosaic pixel coordinates."""
        return cols + self.expanded.col_off, rows + self.expanded.row_off

    def pixel_to_world(self, cols, rows):
        """Patch-local continuous pixel coordinates -> world coordinates."""
        return pixel_to_world(self.transform, cols, rows)

    def world_to_pixel(self, xs, ys):
        """World coordinates -> patch-local continuous pixel coordinates."""
        return world_to_pixel(self.transform, xs, ys)


class PatchGrid:
    """The global grid of patches over a ``width x height`` mosaic with affine ``transform``."""

    def __init__(
        self,
        width: int,
        height: int,
        transform: Affine = Affine.identity(),
        config: GridConfig = GridConfig(),
        footprint: Sequence[PixelWindow] | None = None,
    ):
        if width <= 0 or height <= 0:
            raise ValueError(f"mosaic must have pixels, got {width}x{height}")
        self.width = width
        self.height = height
        self.transform = transform
        self.config = config
        self.n_rows = math.ceil(height / config.core)
        self.n_cols = math.ceil(width / config.core)
        self._patches: dict[tuple[int, int], Patch] = {}  # made once each: a run asks for every patch many times
        whole = footprint is None or list(footprint) == [PixelWindow(0, 0, width, height)]
        self.planned: list[tuple[int, int]] | None = (
            None if whole else cells_meeting(footprint, config.core, self.n_rows, self.n_cols)
        )
        self._planned = None if self.planned is None else frozenset(self.planned)

    def __getstate__(self) -> dict:
        """Pickled without the patches made so far (a Dask worker makes its own)."""
        return {**self.__dict__, "_patches": {}}

    @classmethod
    def for_mosaic(cls, mosaic, config: GridConfig = GridConfig()) -> "PatchGrid":
        """The grid of ``mosaic``, planned over its footprint."""
        return cls(mosaic.width, mosaic.height, mosaic.transform, config, getattr(mosaic, "footprint", None))

    @property
    def shape(self) -> tuple[int, int]:
        return self.n_rows, self.n_cols

    def __len__(self) -> int:
        """The planned patches."""
        return self.n_rows * self.n_cols if self.planned is None else len(self.planned)

    def __iter__(self) -> Iterator[Patch]:
        """The planned patches in row-major order (the order a streaming pass visits them)."""
        if self.planned is not None:
            yield from (self.patch(row, col) for row, col in self.planned)
            return
        for row in range(self.n_rows):
            for col in range(self.n_cols):
                yield self.patch(row, col)

    def is_planned(self, index: tuple[int, int]) -> bool:
        return index in self if self._planned is None else index in self._planned

    def __contains__(self, index: tuple[int, int]) -> bool:
        row, col = index
        return 0 <= row < self.n_rows and 0 <= col < self.n_cols

    def patch(self, row: int, col: int) -> Patch:
        found = self._patches.get((row, col))
        if found is not None:
            return found
        if (row, col) not in self:
            raise IndexError(f"patch ({row}, {col}) outside grid of {self.n_rows}x{self.n_cols}")
        c, m = self.config.core, self.config.margin
        c0, r0 = col * c, row * c
        core = PixelWindow(c0, r0, min(c, self.width - c0), min(c, self.height - r0))
        expanded = PixelWindow(c0 - m, r0 - m, c + 2 * m, c + 2 * m)
        patch = self._patches[row, col] = Patch(row, col, core, expanded, window_transform(self.transform, expanded))
        return patch

    def neighbours(self, patch: Patch) -> list[Patch]:
        """The planned patches whose expanded windows overlap ``patch``'s: the up to 8 adjacent
        ones, and more when ``2 * margin > core`` makes patches further apart overlap too."""
        reach = max(1, math.ceil(2 * self.config.margin / self.config.core))
        out = []
        for dr in range(-reach, reach + 1):
            for dc in range(-reach, reach + 1):
                index = (patch.row + dr, patch.col + dc)
                if (dr or dc) and self.is_planned(index):
                    out.append(self.patch(*index))
        return out

    def overlap(self, a: Patch, b: Patch) -> PixelWindow | None:
        """Mosaic pixels shared by the expanded windows of ``a`` and ``b`` (None if disjoint)."""
        return a.expanded.intersection(b.expanded)

    def overlap_regions(self, patch: Patch) -> dict[tuple[int, int], PixelWindow]:
        """For each neighbour index, the part of ``patch``'s expanded window it also covers."""
        regions = {}
        for other in self.neighbours(patch):
            shared = self.overlap(patch, other)
            if shared is not None:
                regions[other.index] = shared
        return regions

    def patch_of_pixel(self, col: float, row: float) -> Patch:
        """The patch whose core holds mosaic pixel (col, row)."""
        c = self.config.core
        return self.patch(int(row // c), int(col // c))

    def patches_covering(self, col: float, row: float) -> list[Patch]:
        """Every patch whose expanded window holds mosaic pixel (col, row)."""
        # Patch r's expanded rows are [r*core - margin, (r+1)*core + margin): r lies between
        # floor((row - margin) / core) and floor((row + margin) / core); one extra on each side
        # guards the floating-point division, the exact test below decides.
        c, m = self.config.core, self.config.margin
        rows = range(max(math.floor((row - m) / c) - 1, 0), min(math.floor((row + m) / c) + 1, self.n_rows - 1) + 1)
        cols = range(max(math.floor((col - m) / c) - 1, 0), min(math.floor((col + m) / c) + 1, self.n_cols - 1) + 1)
        candidates = [self.patch(r, k) for r in rows for k in cols]
        return [
            p
            for p in candidates
            if p.expanded.col_off <= col < p.expanded.col_end and p.expanded.row_off <= row < p.expanded.row_end
        ]
