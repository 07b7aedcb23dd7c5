"""Packed arrays (issue 52 item 4, a rigged .blend within 1.3x its plain file): what is unpacked is
bit for bit what was packed, whatever the floats (signed zeros, subnormals, NaN payloads); damage
is refused naming the record's field, never a zlib error; positions pack smaller than their raw
floats by at least their constant byte plane."""

import zlib

import numpy as np
import pytest

from skin_detach_addon.core import packed_arrays
from skin_detach_addon.core.errors import SkinDetachError


def awkward_floats(rng, n):
    """(n, 3) float32 positions holding the floats a plain cast or a float compare would lose."""
    points = rng.normal(size=(n, 3)).astype(np.float32)
    special = np.array([0.0, -0.0, 1e-45, -1e-45, 1.17e-38, np.float32(3.4e38), np.inf, -np.inf], dtype=np.float32)
    points.ravel()[:special.size] = special
    bits = points.view(np.uint32)
    bits.ravel()[special.size:special.size + 2] = (0x7FC00001, 0xFFA00005)  # NaNs with payloads
    return points


@pytest.mark.parametrize("dtype", ["float32", "float64", "int8", "uint8", "int16", "int32", "int64"])
def test_unpacked_is_bit_for_bit_what_was_packed(dtype):
    rng = np.random.default_rng(5)
    if dtype == "float32":
        values = awkward_floats(rng, 4000)
    elif dtype == "float64":
        values = rng.normal(size=(3000, 3)) * 10.0 ** rng.integers(-300, 300, size=(3000, 1))
    else:
        info = np.iinfo(dtype)
        values = rng.integers(info.min, info.max, size=5000, dtype=dtype, endpoint=True)
    unpacked = packed_arrays.unpack(packed_arrays.pack(values), "rest")
    assert unpacked.dtype == values.dtype and unpacked.shape == (values.size,)
    assert unpacked.tobytes() == np.ascontiguousarray(values).tobytes()
    assert packed_arrays.packed_size(packed_arrays.pack(values)) == values.size


def test_an_empty_array_and_one_row_round_trip():
    for values in (np.zeros((0, 3), dtype=np.float32), np.array([[1.5, -0.0, 2.0]], dtype=np.float32)):
        assert packed_arrays.unpack(packed_arrays.pack(values)).tobytes() == values.tobytes()


def test_positions_pack_smaller_than_the_raw_floats_by_their_constant_byte_plane():
    """Positions within [1, 2) share their sign and exponent: of a float32's four byte planes (low
    byte first) the last is one repeated byte and the third has one constant bit, so the packed
    bytes are at most 2 7/8 of the 4 bytes of each float (zlib's Huffman codes take 7 bits for 128
    equally likely bytes), and some header; zlib of the raw floats finds none of it."""
    rng = np.random.default_rng(2)
    n = 60_000
    points = (1.0 + rng.random((n, 3))).astype(np.float32)
    packed = packed_arrays.pack(points)
    assert len(packed) <= 3 * n * (2 + 7 / 8) * 1.02 + 200
    assert len(packed) < 0.75 * points.nbytes < len(zlib.compress(points.tobytes(), packed_arrays.LEVEL))


def test_damaged_packed_data_is_refused_naming_the_field():
    packed = packed_arrays.pack(np.arange(3000, dtype=np.float32).reshape(-1, 3))
    flipped = bytearray(packed)
    flipped[-3] ^= 0xFF                                        # the last stream's checksum
    moved = bytearray(packed)
    moved[len(packed) // 2] ^= 0x55                            # inside a stream
    cases = [(bytes(flipped), "expected packed data that inflates"), (bytes(moved), "expected packed data"),
             (packed[:-7], "expected packed bytes of the length their header gives"),
             (b"XXXX" + packed[4:], "expected packed bytes starting"),
             (packed[:5] + b"z9" + packed[7:], "expected packed arrays of format 1"),
             (packed[:5], "expected packed bytes starting"), ("text", "expected packed bytes, got str")]
    for data, expected in cases:
        with pytest.raises(SkinDetachError, match=r"^binding of 'spot' rest: " + expected) as caught:
            packed_arrays.unpack(data, "binding of 'spot' rest")
        assert not isinstance(caught.value.__cause__, zlib.error)


def test_only_plain_arrays_are_packed():
    with pytest.raises(SkinDetachError, match=r"values: expected a 1-d or 2-d array of one of the types .* got "
                                              r"1-d complex128"):
        packed_arrays.pack(np.zeros(4, dtype=complex))
    with pytest.raises(SkinDetachError, match="values: expected 1 to 16 columns, got 20"):
        packed_arrays.pack(np.zeros((2, 20), dtype=np.float32))
    assert not packed_arrays.is_packed(b"\x01\x02") and not packed_arrays.is_packed(np.zeros(3))
