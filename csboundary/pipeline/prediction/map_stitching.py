"""Map stitching: a window's maps are the average of every patch that covers its pixels.

Paper IV-E: "we stitch predicted keypoint maps by averaging the intersection areas". A patch's
stitched window needs the maps of the patch and of all its neighbours, so it is final once they
are all predicted; :class:`WindowSchedule` says when that happens and when a patch's maps are no
longer needed by any pending window (in the grid's row-major order: one patch row and one patch
later, so two rows of patches and three more are held, whatever the city's height).

:func:`stitch_window` sums the float16-stored maps in float32 over the covering patches in a
fixed (row, col) order, so the two patches sharing an overlap compute bit-identical values there
(the condition for their vertices to coincide), whichever process computes them and in whatever
order the patches were predicted. Pixels outside the mosaic are 0; a patch without imagery
counts as maps of zeros.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from csboundary.data.grid import Patch, PatchGrid
from csboundary.data.windows import PixelWindow
from csboundary.pipeline.prediction.float16 import add_float32

Index = tuple[int, int]


def stitch_window(
    grid: PatchGrid, patch: Patch, load: Callable[[Index], np.ndarray | None], channels: int
) -> np.ndarray:
    """The (C, S, S) float32 stitched maps of ``patch``'s expanded window; ``load(index)`` gives a
    covering patch's stored (C, S, S) maps, or None for a window without imagery (zeros)."""
    win = patch.expanded
    mosaic = PixelWindow(0, 0, grid.width, grid.height)
    total = np.zeros((channels, win.height, win.width), np.float32)
    count = np.zeros((win.height, win.width), np.float32)
    for q in sorted([patch, *grid.neighbours(patch)], key=lambda q: q.index):
        part = win.intersection(q.expanded)
        part = part.intersection(mosaic) if part is not None else None
        if part is None:
            continue
        rows, cols = part.relative_to(win).slices()
        maps = load(q.index)
        if maps is not None:
            if maps.shape != (channels, win.height, win.width):
                raise ValueError(
                    f"maps of patch {q.index} must be ({channels}, {win.height}, {win.width}), got {maps.shape}"
                )
            srows, scols = part.relative_to(q.expanded).slices()
            add_float32(total[:, rows, cols], maps[:, srows, scols])
        count[rows, cols] += 1
    return np.divide(total, np.maximum(count, 1)[None], out=total)  # in place: no second window-sized array


class WindowSchedule:
    """Which windows can be stitched and which patches' maps can be dropped, as the maps and
    graphs of patches arrive in any order (and from earlier, interrupted runs)."""

    def __init__(self, grid: PatchGrid, maps_done: set[Index] = frozenset(), graphs_done: set[Index] = frozenset()):
        self.grid = grid
        self._neighbourhood = {p.index: [p.index, *(q.index for q in grid.neighbours(p))] for p in grid}
        self.neighbourhoods = self._neighbourhood  # window -> the patches covering it (itself first)
        self.maps_done: set[Index] = set(maps_done)
        self.graphs_done: set[Index] = set(graphs_done)

    @property
    def done(self) -> bool:
        return len(self.graphs_done) == len(self.grid)

    def is_ready(self, index: Index) -> bool:
        """Every patch covering the window is predicted and its graph is not done yet."""
        return index not in self.graphs_done and all(q in self.maps_done for q in self._neighbourhood[index])

    def ready(self) -> list[Index]:
        """All windows that can be stitched now, in (row, col) order."""
        return sorted(i for i in self._neighbourhood if self.is_ready(i))

    def add_maps(self, index: Index) -> list[Index]:
        """Record a patch's maps; return the windows this made ready, in (row, col) order."""
        if index in self.maps_done:
            raise ValueError(f"maps of patch {index} added twice")
        self.maps_done.add(index)
        return sorted(i for i in self._neighbourhood[index] if self.is_ready(i))

    def add_graph(self, index: Index) -> list[Index]:
        """Record a window's graph; return the patches whose maps no pending window needs any more."""
        self.graphs_done.add(index)
        return sorted(q for q in self._neighbourhood[index] if self.releasable(q))

    def releasable(self, index: Index) -> bool:
        return all(w in self.graphs_done for w in self._neighbourhood[index])
