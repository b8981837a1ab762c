import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from csboundary.graph.pixel_index import nonzero_pixels


def test_hand_computed_pixels_in_raster_order():
    image = np.zeros((3, 4), np.int32)
    image[2, 0] = 5
    image[0, 3] = 1
    image[1, 1] = -2
    rows, cols = nonzero_pixels(image)
    assert rows.tolist() == [0, 1, 2] and cols.tolist() == [3, 1, 0]


@settings(max_examples=200, deadline=None)
@given(
    arrays(
        st.sampled_from([np.bool_, np.int32, np.float32]),
        st.tuples(st.integers(0, 12), st.integers(0, 12)),
        elements=st.sampled_from([0, 1]),
    )
)
def test_same_as_numpy_nonzero(image):
    rows, cols = nonzero_pixels(image)
    expected = np.nonzero(image)
    assert np.array_equal(rows, expected[0]) and np.array_equal(cols, expected[1])


def test_not_two_dimensional_is_refused():
    with pytest.raises(ValueError, match="2-D"):
        nonzero_pixels(np.zeros(5))
