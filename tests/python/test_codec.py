"""wmo._core.codec, the residual table coder behind the remote snapshot stream: round
trips through the binding, the side tables, and bad input refused with TypeError or
ValueError naming the argument (the coder itself is tested in
tests/cpp/codec/test_residual_coder.cpp)."""
from __future__ import annotations

import numpy as np
import pytest

from wmo._core import codec


def test_round_trip_with_and_without_side_tables():
    rng = np.random.default_rng(3)
    values = rng.integers(-300, 300, (500, 7))
    motion = rng.integers(-1000, 1000, (500, 7))
    previous = rng.integers(-8, 9, (500, 7)).astype(np.int8)  # any integer dtype
    for m, p in ((None, None), (motion, None), (None, previous), (motion, previous)):
        data = codec.encode_residuals(values, m, p, group_starts=0b10001)
        out = codec.decode_residuals(data, 500, 7, m, p, group_starts=0b10001)
        assert out.dtype == np.int64 and out.shape == (500, 7)
        np.testing.assert_array_equal(out, values)
    # Decoding with other side information than the encoder's does not give the table
    # back (it fails, or decodes to something else): both ends must agree.
    data = codec.encode_residuals(values, motion, previous, group_starts=0b10001)
    try:
        other = codec.decode_residuals(data, 500, 7, None, previous, group_starts=0b10001)
    except ValueError:
        pass
    else:
        assert not np.array_equal(other, values)


def test_largest_magnitudes_and_empty_tables():
    top = codec.MAX_RESIDUAL - 1
    values = np.array([[top, -top], [0, 1]], dtype=np.int64)
    np.testing.assert_array_equal(codec.decode_residuals(codec.encode_residuals(values), 2, 2), values)
    empty = np.zeros((0, 7), dtype=np.int64)
    assert codec.decode_residuals(codec.encode_residuals(empty), 0, 7).shape == (0, 7)


def test_bad_input_names_the_argument():
    values = np.zeros((4, 3), dtype=np.int64)
    with pytest.raises(TypeError, match="residuals"):
        codec.encode_residuals(np.zeros(4, dtype=np.int64))
    with pytest.raises(TypeError, match="residuals"):
        codec.encode_residuals(np.zeros((4, 3)))  # floats are not residuals
    with pytest.raises(TypeError, match="motion"):
        codec.encode_residuals(values, np.zeros((3, 3), dtype=np.int64))
    with pytest.raises(TypeError, match="previous"):
        codec.encode_residuals(values, None, np.zeros((4, 2), dtype=np.int64))
    big = values.copy()
    big[2, 1] = codec.MAX_RESIDUAL
    with pytest.raises(ValueError, match="row 2, column 1"):
        codec.encode_residuals(big)
    with pytest.raises(ValueError, match="columns"):
        codec.encode_residuals(np.zeros((4, 40), dtype=np.int64))
    data = codec.encode_residuals(values)
    with pytest.raises(ValueError, match="rows"):
        codec.decode_residuals(data, -1, 3)
    with pytest.raises(ValueError, match="truncated|after the table"):
        codec.decode_residuals(data + b"\0", 4, 3)
    with pytest.raises(ValueError, match="truncated"):
        codec.decode_residuals(data[:-1], 4, 3)
