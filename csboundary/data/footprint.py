"""Where a mosaic's imagery lies: the windows of its files, not their bounding box.

Eight 1000 px tiles kilometres apart make one mosaic whose bounding box is 146 G pixels for 8 M
pixels of imagery. What samples windows (adapt, finetune), plans patches (predict) or draws
review tiles works from the footprint instead, so its cost follows the imagery, not the box. A
mosaic whose files fill their bounding box has that box as its one-window footprint, and draws
from it exactly as it always did.

Pure functions of :class:`~csboundary.data.windows.PixelWindow` lists.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from csboundary.data.windows import PixelWindow


def clipped(windows: Sequence[PixelWindow], bounds: PixelWindow) -> list[PixelWindow]:
    """The parts of ``windows`` inside ``bounds``, in order; windows outside it are left out."""
    return [part for part in (w.intersection(bounds) for w in windows) if part is not None]


def _cells(windows: Sequence[PixelWindow]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The windows' union on the grid their edges make: (covered cells (rows, cols) bool, the
    column edges, the row edges). Exact for any layout; 2,000 tiles make at most 4,000 x 4,000 cells."""
    cols = np.unique([v for w in windows for v in (w.col_off, w.col_end)])
    rows = np.unique([v for w in windows for v in (w.row_off, w.row_end)])
    covered = np.zeros((max(len(rows) - 1, 0), max(len(cols) - 1, 0)), bool)
    for w in windows:
        c0, c1 = np.searchsorted(cols, [w.col_off, w.col_end])
        r0, r1 = np.searchsorted(rows, [w.row_off, w.row_end])
        covered[r0:r1, c0:c1] = True
    return covered, cols, rows


def union_area(windows: Sequence[PixelWindow]) -> int:
    """Pixels covered by at least one of ``windows`` (overlaps counted once)."""
    windows = [w for w in windows if not w.is_empty]
    if not windows:
        return 0
    covered, cols, rows = _cells(windows)
    return int((np.diff(rows)[:, None] * np.diff(cols)[None, :] * covered).sum())


def footprint(windows: Sequence[PixelWindow], bounds: PixelWindow) -> list[PixelWindow]:
    """``[bounds]`` when ``windows`` cover all of it, else their parts inside it: where windows
    may be drawn and patches planned."""
    parts = clipped(windows, bounds)
    return [bounds] if union_area(parts) == bounds.area else parts


def meets(parts: Sequence[PixelWindow], window: PixelWindow) -> bool:
    """Whether ``window`` shares a pixel with any of ``parts``."""
    return any(window.intersection(p) is not None for p in parts)


def draw_window(rng: np.random.Generator, parts: Sequence[PixelWindow], size: int) -> PixelWindow:
    """A ``size`` square drawn where the imagery is: a part chosen in proportion to its area, then
    every window inside it alike (a part smaller than ``size`` is covered from its top-left).
    With one part this draws exactly what two ``rng.integers`` over that part always drew."""
    if len(parts) == 1:
        part = parts[0]
    else:
        areas = np.array([p.area for p in parts], float)
        part = parts[int(rng.choice(len(parts), p=areas / areas.sum()))]
    col = part.col_off + int(rng.integers(0, max(1, part.width - size + 1)))
    row = part.row_off + int(rng.integers(0, max(1, part.height - size + 1)))
    return PixelWindow(col, row, size, size)


def scaled(parts: Sequence[PixelWindow], fx: float, fy: float, bounds: PixelWindow) -> list[PixelWindow]:
    """``parts`` given in pixels ``fx`` x ``fy`` times smaller than ``bounds``' pixels, as the
    smallest windows of ``bounds``' pixels that hold them, clipped to ``bounds``."""
    out = []
    for p in parts:
        c0, r0 = int(np.floor(p.col_off / fx)), int(np.floor(p.row_off / fy))
        c1, r1 = int(np.ceil(p.col_end / fx)), int(np.ceil(p.row_end / fy))
        out.append(PixelWindow(c0, r0, c1 - c0, r1 - r0))
    return clipped(out, bounds)


def groups(parts: Sequence[PixelWindow]) -> list[PixelWindow]:
    """The bounding windows of the groups of ``parts`` that touch or overlap (side by side tiles
    are one group, tiles kilometres apart one group each), row-major by their corners."""
    parent = list(range(len(parts)))

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for i, a in enumerate(parts):  # touching: the windows grown by one pixel share one
        grown = PixelWindow(a.col_off - 1, a.row_off - 1, a.width + 2, a.height + 2)
        for j in range(i):
            if grown.intersection(parts[j]) is not None:
                parent[root(i)] = root(j)
    members: dict[int, list[PixelWindow]] = {}
    for k, part in enumerate(parts):
        members.setdefault(root(k), []).append(part)
    boxes = []
    for group in members.values():
        c0, r0 = min(p.col_off for p in group), min(p.row_off for p in group)
        boxes.append(PixelWindow(c0, r0, max(p.col_end for p in group) - c0, max(p.row_end for p in group) - r0))
    return sorted(boxes, key=lambda w: (w.row_off, w.col_off))
