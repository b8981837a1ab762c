"""Streaming map stitching: overlapping patch maps averaged with memory bounded by a band of patches.

Paper IV-E: "we stitch predicted keypoint maps by averaging the intersection areas". A patch's
stitched window is final once it and all its neighbours have been predicted; in the grid's
row-major order that is one patch row and one patch later. So the averager keeps only the maps
that pending windows still need:

* a patch's own maps until its window has been emitted;
* after that, only the part that overlaps neighbours not yet emitted (its bottom 100 px strip
  once its right-hand neighbour is done), and nothing once they all are.

Held memory is therefore about one row of patches plus one row of strips, whatever the city's
height, and maps are stored as float16 (probabilities to ~5e-4) to halve that. Sums run in
float32 over the covering patches in a fixed (row, col) order, so the two patches sharing an
overlap compute bit-identical values there: the condition for their vertices to coincide.
Pixels outside the mosaic are 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from csboundary.data.grid import Patch, PatchGrid
from csboundary.data.windows import PixelWindow


@dataclass
class _Stored:
    window: PixelWindow  # mosaic pixels held by ``maps``
    maps: np.ndarray  # (C, h, w)


class StreamingMapAverager:
    """Feed each patch's maps (``add``, any order); receive each patch's stitched window as soon
    as it is final. ``held_bytes`` / ``peak_bytes`` report the map memory held."""

    def __init__(self, grid: PatchGrid, store_dtype=np.float16):
        self.grid = grid
        self.store_dtype = np.dtype(store_dtype)
        self._stored: dict[tuple[int, int], _Stored] = {}
        self._added: set[tuple[int, int]] = set()
        self._emitted: set[tuple[int, int]] = set()
        self._mosaic = PixelWindow(0, 0, grid.width, grid.height)
        self.peak_bytes = 0

    @property
    def held_bytes(self) -> int:
        return sum(s.maps.nbytes for s in self._stored.values())

    @property
    def done(self) -> bool:
        return len(self._emitted) == len(self.grid)

    def add(self, patch: Patch, maps: np.ndarray) -> list[tuple[Patch, np.ndarray]]:
        """Store ``patch``'s (C, S, S) maps; return ``[(patch, stitched (C, S, S) float32)]`` for
        every window that became final, in (row, col) order."""
        size = self.grid.config.size
        if maps.ndim != 3 or maps.shape[1:] != (size, size):
            raise ValueError(f"maps of patch {patch.index} must be (C, {size}, {size}), got {maps.shape}")
        if patch.index in self._added:
            raise ValueError(f"patch {patch.index} added twice")
        self._added.add(patch.index)
        self._stored[patch.index] = _Stored(patch.expanded, maps.astype(self.store_dtype))
        self.peak_bytes = max(self.peak_bytes, self.held_bytes)
        ready = sorted(p.index for p in [patch, *self.grid.neighbours(patch)] if self._is_final(p))
        out = []
        for index in ready:
            p = self.grid.patch(*index)
            out.append((p, self._stitch(p)))
            self._emitted.add(index)
            self._release_around(p)
        return out

    def _is_final(self, patch: Patch) -> bool:
        if patch.index in self._emitted or patch.index not in self._added:
            return False
        return all(q.index in self._added for q in self.grid.neighbours(patch))

    def _stitch(self, patch: Patch) -> np.ndarray:
        win = patch.expanded
        channels = self._stored[patch.index].maps.shape[0]
        total = np.zeros((channels, win.height, win.width), np.float32)
        count = np.zeros((win.height, win.width), np.float32)
        for q in sorted([patch, *self.grid.neighbours(patch)], key=lambda q: q.index):
            part = win.intersection(q.expanded)
            part = part.intersection(self._mosaic) if part is not None else None
            if part is None:
                continue
            stored = self._stored[q.index]
            rows, cols = part.relative_to(win).slices()
            srows, scols = part.relative_to(stored.window).slices()
            total[:, rows, cols] += stored.maps[:, srows, scols]
            count[rows, cols] += 1
        return total / np.maximum(count, 1)[None]

    def _release_around(self, patch: Patch) -> None:
        """Crop or drop the stored maps that the emitted ``patch`` no longer needs."""
        for q in [patch, *self.grid.neighbours(patch)]:
            stored = self._stored.get(q.index)
            if stored is None:
                continue
            pending = [r for r in [q, *self.grid.neighbours(q)] if r.index not in self._emitted]
            if not pending:
                del self._stored[q.index]
                continue
            parts = [q.expanded.intersection(r.expanded) for r in pending]
            keep = _bounding(parts)
            if keep != stored.window:
                rows, cols = keep.relative_to(stored.window).slices()
                stored.maps = stored.maps[:, rows, cols].copy()
                stored.window = keep


def _bounding(windows: list[PixelWindow]) -> PixelWindow:
    c0 = min(w.col_off for w in windows)
    r0 = min(w.row_off for w in windows)
    c1 = max(w.col_end for w in windows)
    r1 = max(w.row_end for w in windows)
    return PixelWindow(c0, r0, c1 - c0, r1 - r0)
