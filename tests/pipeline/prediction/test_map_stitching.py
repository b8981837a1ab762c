"""Map stitching: every window is the whole-mosaic mean, in any order, with about two patch rows
of maps held; the schedule says when a window is ready and when maps can go."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.data.grid import GridConfig, PatchGrid
from csboundary.data.windows import PixelWindow
from csboundary.pipeline.prediction.map_stitching import WindowSchedule, stitch_window
from csboundary.pipeline.prediction.run_store import RunStore

CONFIG = GridConfig(core=20, margin=4)  # 28 px windows overlapping by 8 px


def _maps(grid: PatchGrid, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    size = grid.config.size
    return {p.index: rng.random((2, size, size)).astype(np.float32) for p in grid}


def _reference(grid: PatchGrid, maps: dict) -> np.ndarray:
    """Whole-mosaic mean of the (float16-stored) maps covering each pixel."""
    total = np.zeros((2, grid.height, grid.width), np.float64)
    count = np.zeros((grid.height, grid.width))
    for p in grid:
        m = maps[p.index].astype(np.float16).astype(np.float64)
        for r in range(grid.height):
            lr = r - p.expanded.row_off
            if not 0 <= lr < grid.config.size:
                continue
            c0 = max(p.expanded.col_off, 0)
            c1 = min(p.expanded.col_end, grid.width)
            total[:, r, c0:c1] += m[:, lr, c0 - p.expanded.col_off : c1 - p.expanded.col_off]
            count[r, c0:c1] += 1
    return total / count


class _Averager:
    """The pipeline's loop without a model: store maps, stitch ready windows, drop what is done."""

    def __init__(self, grid, root=None):
        self.grid, self.store, self.schedule = grid, RunStore(root), WindowSchedule(grid)
        self.peak_bytes = 0

    def add(self, patch, maps):
        self.store.save_maps(patch.index, maps)
        self.peak_bytes = max(self.peak_bytes, self.store.held_map_bytes())
        out = []
        for index in self.schedule.add_maps(patch.index):
            out.append(
                (self.grid.patch(*index), stitch_window(self.grid, self.grid.patch(*index), self.store.load_maps, 2))
            )
            for q in self.schedule.add_graph(index):
                self.store.drop_maps(q)
        return out


@settings(max_examples=25, deadline=None)
@given(width=st.integers(1, 75), height=st.integers(1, 75), shuffle=st.booleans(), seed=st.integers(0, 1000))
def test_every_window_is_the_mosaic_mean_and_comes_once(width, height, shuffle, seed):
    grid = PatchGrid(width, height, config=CONFIG)
    maps = _maps(grid, seed)
    order = [p for p in grid]
    if shuffle:
        np.random.default_rng(seed).shuffle(order)
    averager = _Averager(grid)
    emitted = {}
    for p in order:
        for q, window in averager.add(p, maps[p.index]):
            assert q.index not in emitted
            emitted[q.index] = window
    assert averager.schedule.done and set(emitted) == {p.index for p in grid}
    assert averager.store.held_map_bytes() == 0  # everything released at the end
    reference = _reference(grid, maps)
    for index, window in emitted.items():
        p = grid.patch(*index)
        inside = p.expanded.intersection(PixelWindow(0, 0, width, height))
        rows, cols = inside.relative_to(p.expanded).slices()
        grows, gcols = inside.slices()
        assert np.allclose(window[:, rows, cols], reference[:, grows, gcols], atol=1e-6)
        outside = np.ones(window.shape[1:], bool)
        outside[rows, cols] = False
        assert (window[:, outside] == 0).all()


def test_neighbours_agree_bit_for_bit_on_their_overlap(tmp_path):
    grid = PatchGrid(60, 60, config=CONFIG)
    maps = _maps(grid, 1)
    averager = _Averager(grid, tmp_path / "store")  # on disk, as a resumable or distributed run
    windows = {q.index: w for p in grid for q, w in averager.add(p, maps[p.index])}
    for p in grid:
        for q in grid.neighbours(p):
            shared = grid.overlap(p, q)
            a = windows[p.index][(slice(None), *shared.relative_to(p.expanded).slices())]
            b = windows[q.index][(slice(None), *shared.relative_to(q.expanded).slices())]
            assert np.array_equal(a, b)


def test_a_pixel_covered_by_two_patches_is_their_mean():
    grid = PatchGrid(40, 20, config=CONFIG)  # 1 x 2 patches
    a = np.full((2, 28, 28), 0.25, np.float32)
    b = np.full((2, 28, 28), 0.75, np.float32)
    averager = _Averager(grid)
    assert averager.add(grid.patch(0, 0), a) == []  # its neighbour is still missing
    out = dict((p.index, w) for p, w in averager.add(grid.patch(0, 1), b))
    # Mosaic column 18 is in patch 0's window [-4, 24) and patch 1's [16, 44): local 22 and 2.
    assert out[(0, 0)][0, 10, 22] == pytest.approx(0.5) and out[(0, 1)][0, 10, 2] == pytest.approx(0.5)
    assert out[(0, 0)][0, 10, 10] == pytest.approx(0.25)  # covered by patch 0 alone
    assert out[(0, 0)][0, 2, 10] == 0  # row -2 lies outside the mosaic


def test_a_patch_without_imagery_counts_as_zeros():
    grid = PatchGrid(40, 20, config=CONFIG)
    store = RunStore()
    store.save_maps((0, 0), np.full((2, 28, 28), 0.75, np.float32))  # exact in float16
    store.save_maps((0, 1), None)
    window = stitch_window(grid, grid.patch(0, 0), store.load_maps, 2)
    assert window[0, 10, 22] == 0.375 and window[0, 10, 10] == 0.75
    assert store.empty_patches() == {(0, 1)}


def test_maps_held_are_bounded_by_the_width_not_the_height():
    peaks = []
    for rows in (2, 6, 12):
        grid = PatchGrid(5 * 20, rows * 20, config=CONFIG)
        averager = _Averager(grid)
        size = CONFIG.size
        for p in grid:
            averager.add(p, np.zeros((2, size, size), np.float32))
        peaks.append(averager.peak_bytes)
    assert peaks[1] == peaks[2]
    full = 2 * CONFIG.size**2 * 2  # one patch's maps in float16
    assert peaks[2] <= (2 * 5 + 3) * full  # (r, c) waits for window (r+1, c+1), which waits for (r+2, c+2)


def test_the_schedule_resumes_from_what_is_done():
    grid = PatchGrid(60, 60, config=CONFIG)  # 3 x 3 patches
    schedule = WindowSchedule(grid, maps_done={(0, 0), (0, 1), (1, 0), (1, 1)})
    assert schedule.ready() == [(0, 0)]  # its whole neighbourhood is predicted
    assert schedule.add_maps((0, 2)) == []  # (0, 1) still needs (1, 2)
    assert schedule.add_maps((1, 2)) == [(0, 1), (0, 2)]
    with pytest.raises(ValueError, match="twice"):
        schedule.add_maps((1, 2))
    for index in [(0, 0), (0, 1)]:
        assert schedule.add_graph(index) == []  # (1, 0) and (1, 1) still wait for (0, 0)'s maps
    assert schedule.add_graph((1, 0)) == []
    assert schedule.add_graph((1, 1)) == [(0, 0)]  # every window reading (0, 0) is done


def test_bad_maps_are_refused():
    grid = PatchGrid(40, 20, config=CONFIG)
    store = RunStore()
    store.save_maps((0, 0), np.zeros((2, 10, 10)))
    store.save_maps((0, 1), np.zeros((2, 28, 28)))
    with pytest.raises(ValueError, match="must be"):
        stitch_window(grid, grid.patch(0, 0), store.load_maps, 2)
