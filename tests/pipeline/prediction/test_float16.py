"""The float16 helpers give NumPy's bits (round to nearest even, overflow, NaN, subnormals)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from csboundary.pipeline.prediction.float16 import add_float32, to_float16

EDGES = np.array(
    [0.0, -0.0, 1.0, 0.5, 1 / 3, 2 / 3, 65504.0, 65520.0, 1e6, -1e6, 6e-8, 3e-8, 1e-40, np.inf, -np.inf, np.nan],
    np.float32,
)


def test_to_float16_edge_values_equal_numpy_bits():
    with np.errstate(over="ignore"):
        ours, numpy = to_float16(EDGES), EDGES.astype(np.float16)
    assert ours.dtype == np.float16
    assert np.array_equal(ours.view(np.uint16), numpy.view(np.uint16))


@settings(max_examples=50, deadline=None)
@given(
    arrays(
        np.float32,
        st.tuples(st.integers(1, 3), st.integers(1, 40), st.integers(1, 40)),
        elements=st.floats(-70000, 70000, width=32, allow_nan=False),
    )
)
def test_to_float16_equals_numpy(values):
    with np.errstate(over="ignore"):
        expected = values.astype(np.float16)
    assert np.array_equal(to_float16(values).view(np.uint16), expected.view(np.uint16))


@settings(max_examples=50, deadline=None)
@given(
    arrays(np.float32, (2, 30, 30), elements=st.floats(0, 1, width=32)),
    arrays(np.float16, (2, 30, 30), elements=st.floats(0, 1, width=16)),
    st.integers(0, 29),
    st.integers(1, 30),
)
def test_add_float32_into_a_view_equals_numpy(total, part, start, stop):
    """A float16 part added into a strided float32 view: NumPy's float32 sum, and only there."""
    expected = total.copy()
    expected[:, start:stop, 3:] += part[:, start:stop, 3:]
    add_float32(total[:, start:stop, 3:], part[:, start:stop, 3:])
    assert np.array_equal(total, expected)


@settings(max_examples=50, deadline=None)
@given(
    arrays(
        np.float32,
        st.tuples(st.integers(1, 3), st.integers(1, 30), st.integers(1, 30)),
        elements=st.floats(0, 1, width=32),
    ),
    st.integers(1, 100),
    st.data(),
)
def test_pieces_give_the_whole_operation(values, step, data):
    """Cut into pieces of ``step`` values (so that PyTorch keeps them on the calling thread),
    both helpers still touch every value once and only inside the view."""
    part = data.draw(arrays(np.float16, values.shape, elements=st.floats(0, 1, width=16)))
    assert np.array_equal(to_float16(values, step=step).view(np.uint16), values.astype(np.float16).view(np.uint16))
    total = np.zeros((values.shape[0], values.shape[1] + 2, values.shape[2] + 3), np.float32)
    expected = total.copy()
    expected[:, 1:-1, 2:-1] += part
    add_float32(total[:, 1:-1, 2:-1], part, step=step)
    assert np.array_equal(total, expected)


def test_add_float32_refuses_other_shapes():
    with pytest.raises(ValueError, match="cannot add"):
        add_float32(np.zeros((2, 3), np.float32), np.zeros((3, 2), np.float16))
