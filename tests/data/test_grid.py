"""The city-wide patch grid (csboundary.data.grid)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from affine import Affine
from conftest import ORIGIN
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.data.grid import GridConfig, PatchGrid
from csboundary.data.raster import Mosaic
from csboundary.data.windows import PixelWindow as W
from helpers import north_up

X0, Y0 = ORIGIN
UTM = Affine(0.5, 0.0, 500000.0, 0.0, -0.5, 4400000.0)


@st.composite
def grid_params(draw):
    """(width, height, core, margin) with at most 8x8 patches, sizes often not a multiple of core."""
    core = draw(st.integers(1, 60))
    width = draw(st.integers(1, 8 * core))
    height = draw(st.integers(1, 8 * core))
    margin = draw(st.integers(0, 40))
    return width, height, core, margin


# -- configuration ---------------------------------------------------------------------------------


def test_default_config_is_the_papers():
    cfg = GridConfig()
    assert (cfg.core, cfg.margin, cfg.size) == (1000, 50, 1100)
    assert GridConfig(core=256, margin=0).size == 256


@pytest.mark.parametrize("core,margin", [(0, 10), (-5, 0), (100, -1)])
def test_bad_config_rejected(core, margin):
    with pytest.raises(ValueError):
        GridConfig(core=core, margin=margin)


@pytest.mark.parametrize("width,height", [(0, 10), (10, 0), (-3, 5)])
def test_empty_mosaic_rejected(width, height):
    with pytest.raises(ValueError):
        PatchGrid(width, height)


def test_shape_and_clipped_edge_cores():
    grid = PatchGrid(2500, 1800)  # 3 columns (1000, 1000, 500), 2 rows (1000, 800)
    assert grid.shape == (2, 3) and len(grid) == 6
    p = grid.patch(1, 2)
    assert p.index == (1, 2)
    assert p.core == W(2000, 1000, 500, 800)
    assert p.expanded == W(1950, 950, 1100, 1100)
    assert p.core_local == W(50, 50, 500, 800)
    assert grid.patch(0, 0).core == W(0, 0, 1000, 1000)
    assert grid.patch(0, 0).expanded == W(-50, -50, 1100, 1100)


def test_exact_multiple_has_no_sliver_patch():
    assert PatchGrid(3000, 2000).shape == (2, 3)
    assert PatchGrid(3001, 2000).shape == (2, 4)
    assert PatchGrid(3001, 2000).patch(1, 3).core == W(3000, 1000, 1, 1000)


def test_iteration_is_row_major_and_membership():
    grid = PatchGrid(2500, 1800)
    assert [p.index for p in grid] == [(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2)]
    assert (1, 2) in grid and (0, 0) in grid
    assert (2, 0) not in grid and (0, 3) not in grid and (-1, 0) not in grid
    with pytest.raises(IndexError):
        grid.patch(2, 0)
    with pytest.raises(IndexError):
        grid.patch(0, -1)


# -- coverage and sizes ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "width,height,core,margin",
    [(3000, 2000, 1000, 50), (2500, 1800, 1000, 50), (1, 1, 1000, 50), (1001, 999, 1000, 50), (7, 13, 3, 2)],
)
def test_cores_cover_mosaic_exactly_once_examples(width, height, core, margin):
    grid = PatchGrid(width, height, config=GridConfig(core, margin))
    count = np.zeros((height, width), dtype=np.int32)
    for p in grid:
        count[p.core.slices()] += 1
    assert (count == 1).all()


@settings(max_examples=150, deadline=None)
@given(grid_params())
def test_cores_cover_mosaic_exactly_once(params):
    width, height, core, margin = params
    grid = PatchGrid(width, height, config=GridConfig(core, margin))
    assert len(grid) == -(-width // core) * -(-height // core)
    mosaic = W(0, 0, width, height)
    count = np.zeros((height, width), dtype=np.int32)
    for p in grid:
        assert mosaic.contains(p.core) and not p.core.is_empty  # so slicing below is faithful
        count[p.core.slices()] += 1
    assert (count == 1).all()


@settings(max_examples=100, deadline=None)
@given(grid_params())
def test_expanded_windows_are_full_size_squares_around_the_core(params):
    width, height, core, margin = params
    grid = PatchGrid(width, height, config=GridConfig(core, margin))
    for p in grid:
        assert p.expanded.width == p.expanded.height == core + 2 * margin
        assert (p.expanded.col_off, p.expanded.row_off) == (p.col * core - margin, p.row * core - margin)
        assert p.expanded.contains(p.core)
        assert (p.core_local.col_off, p.core_local.row_off) == (margin, margin)


# -- overlaps --------------------------------------------------------------------------------------


def test_default_neighbours_overlap_by_100_px():
    grid = PatchGrid(3000, 3000)
    centre = grid.patch(1, 1)
    assert centre.expanded == W(950, 950, 1100, 1100)
    assert grid.overlap(centre, grid.patch(1, 2)) == W(1950, 950, 100, 1100)  # horizontal
    assert grid.overlap(centre, grid.patch(2, 1)) == W(950, 1950, 1100, 100)  # vertical
    assert grid.overlap(centre, grid.patch(2, 2)) == W(1950, 1950, 100, 100)  # diagonal
    assert grid.overlap(centre, grid.patch(0, 2)) == W(1950, 950, 100, 100)  # anti-diagonal
    assert grid.overlap(centre, grid.patch(0, 0)) == W(950, 950, 100, 100)
    assert grid.overlap(grid.patch(0, 0), grid.patch(0, 2)) is None  # two apart: disjoint


@settings(max_examples=100, deadline=None)
@given(st.integers(1, 60), st.integers(1, 40), st.integers(0, 3), st.integers(0, 3))
def test_adjacent_overlap_is_two_margins(core, margin, row, col):
    grid = PatchGrid(5 * core, 5 * core, config=GridConfig(core, margin))
    p = grid.patch(row, col)
    size = core + 2 * margin
    right, down, diag = grid.patch(row, col + 1), grid.patch(row + 1, col), grid.patch(row + 1, col + 1)
    assert grid.overlap(p, right) == W((col + 1) * core - margin, row * core - margin, 2 * margin, size)
    assert grid.overlap(p, down) == W(col * core - margin, (row + 1) * core - margin, size, 2 * margin)
    assert grid.overlap(p, diag) == W((col + 1) * core - margin, (row + 1) * core - margin, 2 * margin, 2 * margin)


@pytest.mark.parametrize(
    "index,expected",
    [
        ((0, 0), {(0, 1), (1, 0), (1, 1)}),  # corner
        ((2, 2), {(1, 1), (1, 2), (2, 1)}),
        ((0, 1), {(0, 0), (0, 2), (1, 0), (1, 1), (1, 2)}),  # edge
        ((1, 0), {(0, 0), (2, 0), (0, 1), (1, 1), (2, 1)}),
        ((1, 1), {(r, c) for r in range(3) for c in range(3)} - {(1, 1)}),  # interior
    ],
)
def test_neighbours_corner_edge_interior(index, expected):
    grid = PatchGrid(3000, 3000)
    got = [p.index for p in grid.neighbours(grid.patch(*index))]
    assert len(got) == len(expected)
    assert set(got) == expected


def test_neighbours_of_degenerate_grids():
    assert PatchGrid(500, 500).neighbours(PatchGrid(500, 500).patch(0, 0)) == []
    row = PatchGrid(3000, 900)  # 1 x 3
    assert [len(row.neighbours(p)) for p in row] == [1, 2, 1]


def test_overlap_regions_by_hand():
    grid = PatchGrid(3000, 3000)
    assert grid.overlap_regions(grid.patch(0, 0)) == {
        (0, 1): W(950, -50, 100, 1100),
        (1, 0): W(-50, 950, 1100, 100),
        (1, 1): W(950, 950, 100, 100),
    }
    regions = grid.overlap_regions(grid.patch(1, 1))
    assert len(regions) == 8
    assert regions[(0, 1)] == W(950, 950, 1100, 100)
    assert regions[(1, 0)] == W(950, 950, 100, 1100)
    assert regions[(2, 0)] == W(950, 1950, 100, 100)
    assert all(grid.patch(1, 1).expanded.contains(w) for w in regions.values())


def test_overlap_regions_without_margin_are_empty():
    grid = PatchGrid(3000, 3000, config=GridConfig(1000, 0))
    assert len(grid.neighbours(grid.patch(1, 1))) == 8  # still adjacent
    assert grid.overlap_regions(grid.patch(1, 1)) == {}  # but expanded windows only touch


def test_wide_margin_reaches_patches_two_apart():
    """With 2 * margin > core, patches two apart overlap too and must be listed."""
    grid = PatchGrid(50, 50, config=GridConfig(core=10, margin=8))  # 5x5 patches of 26 px
    centre = grid.patch(2, 2)
    assert len(grid.neighbours(centre)) == 24
    regions = grid.overlap_regions(centre)
    # patch (2, 4): cols [32, 58) vs centre [12, 38) -> [32, 38)
    assert regions[(2, 4)] == W(32, 12, 6, 26)
    assert len(regions) == 24


@settings(max_examples=100, deadline=None)
@given(grid_params(), st.data())
def test_overlap_regions_match_brute_force(params, data):
    width, height, core, margin = params
    grid = PatchGrid(width, height, config=GridConfig(core, margin))
    p = grid.patch(data.draw(st.integers(0, grid.n_rows - 1)), data.draw(st.integers(0, grid.n_cols - 1)))
    expected = {}
    for q in grid:
        if q.index != p.index:
            shared = p.expanded.intersection(q.expanded)
            if shared is not None:
                expected[q.index] = shared
    assert grid.overlap_regions(p) == expected
    if margin > 0:
        assert {q.index for q in grid.neighbours(p)} == set(expected)


# -- pixel lookup ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "col,row,index",
    [
        (0, 0, (0, 0)),
        (999, 999, (0, 0)),
        (999.5, 0, (0, 0)),
        (1000, 0, (0, 1)),
        (0, 1000, (1, 0)),
        (2499, 1799, (1, 2)),
    ],
)
def test_patch_of_pixel(col, row, index):
    assert PatchGrid(2500, 1800).patch_of_pixel(col, row).index == index


@pytest.mark.parametrize(
    "col,row,indices",
    [
        (500, 500, {(0, 0)}),  # deep inside one core
        (960, 500, {(0, 0), (0, 1)}),  # in the vertical overlap strip
        (500, 1049, {(0, 0), (1, 0)}),  # last row of (0, 0)'s expanded window
        (500, 1050, {(1, 0)}),  # first row beyond it (half-open)
        (1000, 1000, {(0, 0), (0, 1), (1, 0), (1, 1)}),  # at a grid corner: four patches
        (2400, 1700, {(1, 2)}),
        (-10, 20, {(0, 0)}),  # outside the mosaic, but in (0, 0)'s margin
        (-60, 20, set()),  # beyond every expanded window
    ],
)
def test_patches_covering(col, row, indices):
    grid = PatchGrid(2500, 1800)
    got = [p.index for p in grid.patches_covering(col, row)]
    assert len(got) == len(set(got))
    assert set(got) == indices


@settings(max_examples=150, deadline=None)
@given(grid_params(), st.data())
def test_pixel_lookup_matches_brute_force(params, data):
    width, height, core, margin = params
    grid = PatchGrid(width, height, config=GridConfig(core, margin))
    col = data.draw(st.integers(0, width - 1)) + data.draw(st.sampled_from([0.0, 0.5, 0.999]))
    row = data.draw(st.integers(0, height - 1)) + data.draw(st.sampled_from([0.0, 0.5, 0.999]))
    home = grid.patch_of_pixel(col, row)
    assert home.core.col_off <= col < home.core.col_end and home.core.row_off <= row < home.core.row_end
    expected = {
        p.index
        for p in grid
        if p.expanded.col_off <= col < p.expanded.col_end and p.expanded.row_off <= row < p.expanded.row_end
    }
    got = [p.index for p in grid.patches_covering(col, row)]
    assert len(got) == len(set(got))
    assert set(got) == expected
    assert home.index in expected


# -- coordinates -----------------------------------------------------------------------------------


def test_local_global_and_core_local():
    p = PatchGrid(3000, 3000).patch(1, 2)
    assert p.to_local(2000, 1000) == (50, 50)
    assert p.to_global(0, 0) == (1950, 950)
    cols, rows = p.to_local(np.array([1950.5, 3049.0]), np.array([950.0, 2049.5]))
    np.testing.assert_array_equal(cols, [0.5, 1099.0])
    np.testing.assert_array_equal(rows, [0.0, 1099.5])
    assert p.core_local == W(50, 50, 1000, 1000)


def test_patch_transform_maps_margin_corner_to_core_top_left():
    grid = PatchGrid(3000, 3000, UTM)
    p = grid.patch(1, 2)
    # core top-left = mosaic pixel (2000, 1000) -> world (500000 + 1000, 4400000 - 500)
    x, y = p.pixel_to_world(50, 50)
    assert (float(x), float(y)) == pytest.approx((501000.0, 4399500.0), abs=1e-9)
    # the expanded window starts at mosaic pixel (1950, 950)
    assert (p.transform.c, p.transform.f) == pytest.approx((500975.0, 4399525.0), abs=1e-9)
    assert (p.transform.a, p.transform.e) == (0.5, -0.5)
    cols, rows = p.world_to_pixel(501000.0, 4399500.0)
    assert (float(cols), float(rows)) == pytest.approx((50.0, 50.0), abs=1e-9)


def test_grid_on_a_real_mosaic(shared_tiles):
    cfg = GridConfig(core=50, margin=10)
    with Mosaic.open(shared_tiles.directory) as m:
        grid = PatchGrid.for_mosaic(m, cfg)
        assert grid.shape == (2, 3)  # 80 rows -> 50 + 30, 120 cols -> 50 + 50 + 20
        assert grid.transform == m.transform
        p = grid.patch(1, 1)
        assert p.core == W(50, 50, 50, 30)
        x, y = p.pixel_to_world(10, 10)  # local (margin, margin)
        assert (float(x), float(y)) == pytest.approx((X0 + 25.0, Y0 - 25.0), abs=1e-9)
        xs, ys = m.pixel_to_world(p.core.col_off, p.core.row_off)
        assert (float(x), float(y)) == pytest.approx((float(xs), float(ys)), abs=1e-9)
        r = m.read(p.expanded)
    assert r.data.shape == (4, 70, 70)
    np.testing.assert_array_equal(r.data[(slice(None), *p.core_local.slices())], shared_tiles.full[:, 50:80, 50:100])
    # the expanded window runs 10 rows past the mosaic's bottom edge (mosaic rows 40..110)
    assert r.valid[:40].all() and not r.valid[40:].any()

    with Mosaic.open(shared_tiles.directory) as m:
        whole = PatchGrid.for_mosaic(m)  # default 1000/50: one patch for the small mosaic
    only = whole.patch(0, 0)
    assert len(whole) == 1 and only.core == W(0, 0, 120, 80)
    assert (only.transform.c, only.transform.f) == pytest.approx((X0 - 25.0, Y0 + 25.0), abs=1e-9)
    x, y = only.pixel_to_world(50, 50)
    assert (float(x), float(y)) == pytest.approx((X0, Y0), abs=1e-9)


@settings(max_examples=150, deadline=None)
@given(north_up, grid_params(), st.data())
def test_patch_pixel_world_round_trip(transform, params, data):
    width, height, core, margin = params
    grid = PatchGrid(width, height, transform, GridConfig(core, margin))
    p = grid.patch(data.draw(st.integers(0, grid.n_rows - 1)), data.draw(st.integers(0, grid.n_cols - 1)))
    size = core + 2 * margin
    cols = np.array(data.draw(st.lists(st.floats(-5.0, size + 5.0), min_size=1, max_size=5)))
    rows = np.array(data.draw(st.lists(st.floats(-5.0, size + 5.0), min_size=len(cols), max_size=len(cols))))
    xs, ys = p.pixel_to_world(cols, rows)
    back_c, back_r = p.world_to_pixel(xs, ys)
    assert np.abs(back_c - cols).max() < 1e-6 and np.abs(back_r - rows).max() < 1e-6
    # the patch's world frame agrees with the mosaic's through to_global
    gx, gy = p.to_global(cols, rows)
    mx = transform.a * gx + transform.c
    my = transform.e * gy + transform.f
    assert np.allclose(xs, mx, rtol=0, atol=1e-6)
    assert np.allclose(ys, my, rtol=0, atol=1e-6)
    # pixel (margin, margin) of the patch is the core's top-left corner
    x, y = p.pixel_to_world(margin, margin)
    assert math.isclose(float(x), transform.a * p.core.col_off + transform.c, rel_tol=0, abs_tol=1e-6)
    assert math.isclose(float(y), transform.e * p.core.row_off + transform.f, rel_tol=0, abs_tol=1e-6)
