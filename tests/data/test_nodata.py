"""Filling a window's missing pixels from the nearest imagery."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from csboundary.data.nodata import fill_nodata


def test_a_strip_beyond_the_imagery_repeats_the_last_valid_column():
    data = np.zeros((2, 3, 6), np.uint8)
    data[0, :, :4] = [[1, 2, 3, 4]] * 3
    data[1, :, :4] = [[10, 20, 30, 40]] * 3
    valid = np.zeros((3, 6), bool)
    valid[:, :4] = True
    out = fill_nodata(data, valid)
    assert out[0].tolist() == [[1, 2, 3, 4, 4, 4]] * 3
    assert out[1].tolist() == [[10, 20, 30, 40, 40, 40]] * 3


def test_a_hole_takes_its_nearest_valid_neighbour():
    data = np.arange(25, dtype=np.float32).reshape(1, 5, 5)
    valid = np.ones((5, 5), bool)
    valid[2, 1] = False  # nearest valid: (2, 0) and (2, 2) at 1, (1, 1) and (3, 1) at 1: one of them
    out = fill_nodata(data, valid)
    assert out[0, 2, 1] in (data[0, 2, 0], data[0, 2, 2], data[0, 1, 1], data[0, 3, 1])
    assert np.array_equal(np.delete(out.ravel(), 11), np.delete(data.ravel(), 11))


def test_all_valid_or_none_valid_is_returned_unchanged():
    data = np.random.default_rng(0).integers(0, 255, (4, 7, 9), dtype=np.uint8)
    assert fill_nodata(data, np.ones((7, 9), bool)) is data
    assert fill_nodata(data, np.zeros((7, 9), bool)) is data


@given(arrays(bool, (9, 11)), st.integers(0, 2**31 - 1))
@settings(max_examples=60, deadline=None)
def test_valid_pixels_are_kept_and_every_filled_value_comes_from_a_nearest_valid_pixel(valid, seed):
    data = np.random.default_rng(seed).integers(0, 255, (2, 9, 11), dtype=np.uint8)
    out = fill_nodata(data, valid)
    assert np.array_equal(out[:, valid], data[:, valid])
    if valid.any() and not valid.all():
        vr, vc = np.nonzero(valid)
        for r, c in zip(*np.nonzero(~valid)):
            d2 = (vr - r) ** 2 + (vc - c) ** 2
            nearest = d2 == d2.min()
            assert any(np.array_equal(out[:, r, c], data[:, a, b]) for a, b in zip(vr[nearest], vc[nearest]))


@given(st.integers(0, 8), st.integers(1, 9), st.integers(0, 10), st.integers(1, 11), st.integers(0, 2**31 - 1))
@settings(max_examples=60, deadline=None)
def test_a_rectangle_of_imagery_is_filled_as_the_nearest_pixel_rule_says(r0, rows, c0, cols, seed):
    from scipy import ndimage

    valid = np.zeros((9, 11), bool)
    valid[r0:r0 + rows, c0:c0 + cols] = True  # the fast path: a window reaching beyond the mosaic
    data = np.random.default_rng(seed).integers(0, 255, (3, 9, 11), dtype=np.uint8)
    r, c = ndimage.distance_transform_edt(~valid, return_distances=False, return_indices=True)
    expected = data if valid.all() else data[:, r, c]
    assert np.array_equal(fill_nodata(data, valid), expected)
