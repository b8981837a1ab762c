"""PixelWindow arithmetic and the pixel <-> world conversions of csboundary.data.windows."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from csboundary.data.windows import (
    PixelWindow,
    pixel_to_world,
    window_from_bounds,
    window_transform,
    world_to_pixel,
)
from helpers import north_up

W = PixelWindow

small_windows = st.builds(
    PixelWindow,
    col_off=st.integers(-20, 20),
    row_off=st.integers(-20, 20),
    width=st.integers(0, 15),
    height=st.integers(0, 15),
)


def cells(w: PixelWindow) -> set[tuple[int, int]]:
    """Every (col, row) pixel of a window, by brute force."""
    return {(c, r) for c in range(w.col_off, w.col_end) for r in range(w.row_off, w.row_end)}


# -- basic properties ------------------------------------------------------------------------------


def test_ends_area_and_emptiness():
    w = W(3, -2, 5, 4)
    assert (w.col_end, w.row_end, w.area) == (8, 2, 20)
    assert not w.is_empty
    assert W(3, 3, 0, 4).is_empty and W(3, 3, 4, 0).is_empty
    assert W(3, 3, 0, 4).area == 0


@pytest.mark.parametrize("width,height", [(-1, 0), (0, -1), (-5, 5)])
def test_negative_size_rejected(width, height):
    with pytest.raises(ValueError, match="size"):
        W(0, 0, width, height)


def test_windows_are_hashable_values():
    assert W(1, 2, 3, 4) == W(1, 2, 3, 4)
    assert len({W(1, 2, 3, 4), W(1, 2, 3, 4), W(1, 2, 3, 5)}) == 2
    with pytest.raises(dataclasses.FrozenInstanceError):
        W(1, 2, 3, 4).width = 7  # frozen


def test_slices_index_the_right_pixels():
    arr = np.arange(10 * 12).reshape(10, 12)  # arr[r, c] = 12 r + c
    w = W(col_off=2, row_off=3, width=4, height=2)
    cut = arr[w.slices()]
    assert cut.shape == (2, 4)
    assert cut[0, 0] == 12 * 3 + 2
    assert cut[1, 3] == 12 * 4 + 5


def test_shifted():
    assert W(1, 2, 3, 4).shifted(10, -5) == W(11, -3, 3, 4)


def test_contains():
    outer = W(0, 0, 10, 10)
    assert outer.contains(W(0, 0, 10, 10))
    assert outer.contains(W(2, 3, 4, 5))
    assert not outer.contains(W(-1, 0, 5, 5))
    assert not outer.contains(W(6, 0, 5, 5))  # col_end 11 > 10
    assert not outer.contains(W(0, 9, 1, 2))  # row_end 11 > 10


# -- intersection ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "a,b,expected",
    [
        (W(0, 0, 10, 10), W(5, 5, 10, 10), W(5, 5, 5, 5)),  # corner overlap
        (W(0, 0, 10, 10), W(2, 3, 4, 5), W(2, 3, 4, 5)),  # b inside a
        (W(0, 0, 10, 10), W(0, 0, 10, 10), W(0, 0, 10, 10)),  # identical
        (W(-5, -5, 10, 10), W(0, 0, 3, 20), W(0, 0, 3, 5)),  # negative offsets
        (W(0, 0, 10, 4), W(3, -2, 2, 10), W(3, 0, 2, 4)),  # cross shape
        (W(0, 0, 10, 10), W(10, 0, 5, 5), None),  # touching edge: no shared pixel
        (W(0, 0, 10, 10), W(0, 10, 5, 5), None),
        (W(0, 0, 10, 10), W(10, 10, 5, 5), None),  # touching corner
        (W(0, 0, 10, 10), W(20, 20, 5, 5), None),  # far apart
        (W(0, 0, 10, 10), W(3, 3, 0, 5), None),  # empty window shares nothing
    ],
)
def test_intersection_examples(a, b, expected):
    assert a.intersection(b) == expected
    assert b.intersection(a) == expected


@given(small_windows, small_windows)
def test_intersection_is_exactly_the_common_pixels(a, b):
    got = a.intersection(b)
    common = cells(a) & cells(b)
    if got is None:
        assert not common
    else:
        assert a.contains(got) and b.contains(got)
        assert not got.is_empty
        assert cells(got) == common
    assert b.intersection(a) == got


# -- relative_to -----------------------------------------------------------------------------------


def test_relative_to_examples():
    outer = W(100, 200, 50, 50)
    assert W(110, 230, 5, 6).relative_to(outer) == W(10, 30, 5, 6)
    assert outer.relative_to(outer) == W(0, 0, 50, 50)
    # a window left of / above the frame gets negative offsets
    assert W(90, 195, 5, 6).relative_to(outer) == W(-10, -5, 5, 6)


@given(small_windows, small_windows)
def test_relative_to_indexes_the_same_pixels(inner, outer):
    """Slicing the outer frame's array with the relative window gives the inner window's pixels."""
    world = np.arange(100 * 100).reshape(100, 100)  # frame of reference offset by 50 px so all fits
    frame = world[50 + outer.row_off :, 50 + outer.col_off :]
    rel = inner.relative_to(outer)
    assert rel.shifted(outer.col_off, outer.row_off) == inner
    if outer.contains(inner):
        np.testing.assert_array_equal(frame[rel.slices()], world[inner.shifted(50, 50).slices()])


# -- parse -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "text,expected",
    [
        ("1,2,3,4", W(1, 2, 3, 4)),
        (" 10 , 20,30 ,40 ", W(10, 20, 30, 40)),
        ("-5,-6,0,7", W(-5, -6, 0, 7)),
    ],
)
def test_parse(text, expected):
    assert W.parse(text) == expected


@pytest.mark.parametrize("text", ["1,2,3", "1,2,3,4,5", "", "a,b,c,d", "1.5,2,3,4", "1,2,-3,4", "1;2;3;4"])
def test_parse_rejects(text):
    with pytest.raises(ValueError):
        W.parse(text)


@given(small_windows)
def test_parse_round_trip(w):
    assert W.parse(f"{w.col_off},{w.row_off},{w.width},{w.height}") == w


# -- transforms ------------------------------------------------------------------------------------

T = Affine(0.5, 0.0, 100.0, 0.0, -0.5, 200.0)  # 0.5 units/px, top-left corner at (100, 200)


def test_pixel_to_world_by_hand():
    xs, ys = pixel_to_world(T, [0, 2, 2.5], [0, 4, 1])
    np.testing.assert_allclose(xs, [100.0, 101.0, 101.25])
    np.testing.assert_allclose(ys, [200.0, 198.0, 199.5])


def test_world_to_pixel_by_hand():
    cols, rows = world_to_pixel(T, [100.0, 101.0, 101.25], [200.0, 198.0, 199.5])
    np.testing.assert_allclose(cols, [0, 2, 2.5])
    np.testing.assert_allclose(rows, [0, 4, 1])


def test_conversions_accept_scalars_and_keep_shape():
    x, y = pixel_to_world(T, 2, 4)
    assert float(x) == 101.0 and float(y) == 198.0
    cols, rows = world_to_pixel(T, np.zeros((2, 3)) + 101.0, np.zeros((2, 3)) + 198.0)
    assert cols.shape == (2, 3)
    assert np.all(cols == 2) and np.all(rows == 4)


def test_window_transform_maps_window_origin():
    t = window_transform(T, W(10, 20, 5, 5))
    xs, ys = pixel_to_world(t, [0, 1], [0, 1])
    np.testing.assert_allclose(xs, [105.0, 105.5])
    np.testing.assert_allclose(ys, [190.0, 189.5])
    assert (t.a, t.e) == (T.a, T.e)


@given(north_up, st.floats(-1e4, 6e4), st.floats(-1e4, 6e4))
def test_pixel_world_pixel_round_trip(transform, col, row):
    xs, ys = pixel_to_world(transform, [col], [row])
    cols, rows = world_to_pixel(transform, xs, ys)
    assert abs(cols[0] - col) < 1e-6 and abs(rows[0] - row) < 1e-6


# -- window_from_bounds ----------------------------------------------------------------------------


def test_window_from_bounds_on_pixel_edges():
    # x 101..105 -> cols 2..10; y 199..190 -> rows 2..20
    assert window_from_bounds(T, 101.0, 190.0, 105.0, 199.0) == W(2, 2, 8, 18)


def test_window_from_bounds_rounds_outwards():
    # cols 2.2..9.8 -> 2..10; rows 2.2..20.2 -> 2..21
    assert window_from_bounds(T, 101.1, 189.9, 104.9, 198.9) == W(2, 2, 8, 19)


def test_window_from_bounds_outside_and_degenerate():
    # left of / above the raster: negative offsets
    assert window_from_bounds(T, 99.0, 199.0, 100.5, 201.0) == W(-2, -2, 3, 4)
    # zero-area rectangle exactly on a pixel edge covers no pixel
    assert window_from_bounds(T, 101.0, 195.0, 101.0, 195.0).is_empty
    # a point inside a pixel needs that pixel
    # (col 2.4, row 9.6) -> pixel [9, 2]
    assert window_from_bounds(T, 101.2, 195.2, 101.2, 195.2) == W(2, 9, 1, 1)


def test_window_from_bounds_identity_transform():
    assert window_from_bounds(Affine.identity(), 3, 4, 10, 12) == W(3, 4, 7, 8)


@settings(max_examples=300)
@given(
    st.sampled_from([0.1, 0.15, 0.25, 0.3, 0.5, 0.6, 1 / 3, 1.0, 2.5]),
    st.floats(1e5, 9e5),
    st.floats(1e6, 9e6),
    st.integers(-100, 50_000),
    st.integers(-100, 50_000),
    st.integers(0, 2_000),
    st.integers(0, 2_000),
)
def test_window_from_bounds_round_trips_pixel_windows(gsd, x0, y0, col, row, width, height):
    """The world bounds of a pixel window give that window back, at UTM-sized coordinates."""
    transform = Affine(gsd, 0.0, x0, 0.0, -gsd, y0)
    w = W(col, row, width, height)
    xs, ys = pixel_to_world(transform, [w.col_off, w.col_end], [w.row_off, w.row_end])
    assert window_from_bounds(transform, xs.min(), ys.min(), xs.max(), ys.max()) == w
