"""Filling a window's missing pixels with the imagery mirrored across its border."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from csboundary.data.nodata import fill_nodata, mirror_fill


def test_a_strip_beyond_the_imagery_mirrors_the_columns_before_the_border():
    data = np.zeros((2, 3, 6), np.uint8)
    data[0, :, :4] = [[1, 2, 3, 4]] * 3
    data[1, :, :4] = [[10, 20, 30, 40]] * 3
    valid = np.zeros((3, 6), bool)
    valid[:, :4] = True
    out = fill_nodata(data, valid)
    assert out[0].tolist() == [[1, 2, 3, 4, 3, 2]] * 3
    assert out[1].tolist() == [[10, 20, 30, 40, 30, 20]] * 3


def test_a_corner_beyond_the_imagery_is_mirrored_through_the_corner_pixel():
    data = np.arange(16, dtype=np.float32).reshape(1, 4, 4)
    valid = np.zeros((4, 4), bool)
    valid[1:, 1:] = True  # missing: row 0 and column 0
    out = fill_nodata(data, valid)
    assert out[0, 0, 0] == data[0, 2, 2]  # (0, 0) through the corner (1, 1)
    assert out[0, 0, 3] == data[0, 2, 3] and out[0, 3, 0] == data[0, 3, 2]


def test_a_one_pixel_strip_of_imagery_is_repeated_across_itself():
    data = np.zeros((1, 3, 4), np.uint8)
    data[0, 1] = [5, 6, 7, 8]
    valid = np.zeros((3, 4), bool)
    valid[1] = True
    assert fill_nodata(data, valid)[0].tolist() == [[5, 6, 7, 8]] * 3


def test_a_hole_takes_the_pixel_across_its_nearest_neighbour():
    data = np.arange(25, dtype=np.float32).reshape(1, 5, 5)
    valid = np.ones((5, 5), bool)
    valid[2, 2] = False  # nearest valid: the four 4-neighbours; across each, the pixel two steps away
    out = fill_nodata(data, valid)
    assert out[0, 2, 2] in (data[0, 2, 0], data[0, 2, 4], data[0, 0, 2], data[0, 4, 2])
    assert np.array_equal(np.delete(out.ravel(), 12), np.delete(data.ravel(), 12))


def test_all_valid_or_none_valid_is_returned_unchanged():
    data = np.random.default_rng(0).integers(0, 255, (4, 7, 9), dtype=np.uint8)
    assert fill_nodata(data, np.ones((7, 9), bool)) is data
    assert fill_nodata(data, np.zeros((7, 9), bool)) is data


def _nearest_valid(valid: np.ndarray, r: int, c: int) -> list[tuple[int, int]]:
    vr, vc = np.nonzero(valid)
    d2 = (vr - r) ** 2 + (vc - c) ** 2
    return [(int(a), int(b)) for a, b in zip(vr[d2 == d2.min()], vc[d2 == d2.min()])]


@given(arrays(bool, (9, 11)), st.integers(0, 2**31 - 1))
@settings(max_examples=60, deadline=None)
def test_every_filled_value_is_the_mirror_of_the_pixel_across_its_nearest_valid_neighbour(valid, seed):
    data = np.random.default_rng(seed).integers(0, 255, (2, 9, 11), dtype=np.uint8)
    out = fill_nodata(data, valid)
    assert np.array_equal(out[:, valid], data[:, valid])
    if valid.any() and not valid.all():
        for r, c in zip(*np.nonzero(~valid)):
            candidates = []
            for br, bc in _nearest_valid(valid, r, c):  # any of the tied nearest pixels
                mr, mc = min(max(2 * br - r, 0), 8), min(max(2 * bc - c, 0), 10)
                candidates += [(mr, mc)] if valid[mr, mc] else _nearest_valid(valid, mr, mc)
            assert any(np.array_equal(out[:, r, c], data[:, a, b]) for a, b in candidates)


@given(st.integers(1, 6), st.integers(1, 7), st.data())
@settings(max_examples=80, deadline=None)
def test_a_rectangle_of_imagery_is_filled_as_the_general_rule_says(rows, cols, draw):
    top, bottom = draw.draw(st.integers(0, 7)), draw.draw(st.integers(0, 7))
    left, right = draw.draw(st.integers(0, 7)), draw.draw(st.integers(0, 7))
    valid = np.zeros((top + rows + bottom, left + cols + right), bool)
    valid[top : top + rows, left : left + cols] = (
        True  # a window reaching beyond the mosaic (the fast path when it is wide enough)
    )
    data = np.random.default_rng(rows * cols).integers(0, 255, (3, *valid.shape), dtype=np.uint8)
    expected = data if valid.all() else mirror_fill(data, valid)
    assert np.array_equal(fill_nodata(data, valid), expected)
