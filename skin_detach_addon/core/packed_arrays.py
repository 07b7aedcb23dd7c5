"""Arrays packed losslessly into bytes for a record: a 16-byte header, then one zlib stream per
column of the array's bit patterns, its bytes split into planes (every first byte, then every
second, ...: a float's sign and exponent bytes lie together, and zlib finds their repeats). Bit for bit: what :func:`unpack` returns is the array :func:`pack` was given. Rest
positions (n, 3) float32 pack to about 70 % of their size, where a .blend's own compression of
the raw floats gets about 92 %.

    pack(values (k,) or (k, c)) -> bytes
    unpack(data, source) -> (k,) or (k * c,) flat array of the packed type
    is_packed(value) -> bool ; packed_size(data, source) -> k * c

Header: :data:`MAGIC` (4 bytes), the format version, the type (2 bytes, "f4" ...), the columns c,
a flags byte (0), the element count k * c (uint64, little-endian), then c stream lengths
(uint64 each) before the streams. Damaged data (a wrong header, a stream that does not inflate
or inflates to the wrong size) raises :class:`SkinDetachError` naming ``source``.
"""

import struct
import zlib

import numpy as np

from . import threads
from .errors import SkinDetachError

MAGIC = b"SDPK"
VERSION = 1
#: Types an array may be packed in (numpy's kind and width, as in ``dtype.str``), by their unsigned
#: twin of the same width.
TYPES = {"f4": np.uint32, "f8": np.uint64, "i1": np.uint8, "u1": np.uint8, "i2": np.uint16, "u2": np.uint16,
         "i4": np.uint32, "u4": np.uint32, "i8": np.uint64}
#: zlib's level: 1 packs rest positions within 2 % of level 6's size in a third of its time.
LEVEL = 1
_HEADER = struct.Struct("<4sB2sBBQ")
#: Columns above this many are refused (the header's lengths would outgrow the data).
MOST_COLUMNS = 16
#: Columns of at least this many bytes are (de)compressed on the pool's threads (zlib releases the GIL).
PARALLEL_BYTES = 1 << 20


def is_packed(value):
    """Whether ``value`` is bytes that :func:`pack` made (by its header's magic)."""
    return isinstance(value, (bytes, bytearray)) and len(value) >= _HEADER.size and value[:4] == MAGIC


def pack(values):
    """Bytes of ``values`` (k,) or (k, c) of a type in :data:`TYPES`, each of the c columns a zlib
    stream of its byte planes. (A delta along the vertex order was tried on rest positions: 0.6 %
    smaller, not worth its decoding.)"""
    values = np.asarray(values)
    kind = values.dtype.str[1:]
    if kind not in TYPES or values.ndim not in (1, 2):
        raise SkinDetachError(f"values: expected a 1-d or 2-d array of one of the types {sorted(TYPES)}, got "
                              f"{values.ndim}-d {values.dtype}")
    columns = 1 if values.ndim == 1 else values.shape[1]
    if not 1 <= columns <= MOST_COLUMNS:
        raise SkinDetachError(f"values: expected 1 to {MOST_COLUMNS} columns, got {columns}")
    width = values.dtype.itemsize
    bits = np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("<")).view(TYPES[kind]).reshape(-1, columns)

    def stream(column):
        data = np.ascontiguousarray(bits[:, column])
        planes = data.view(np.uint8).reshape(-1, width).T  # byte planes
        return zlib.compress(np.ascontiguousarray(planes).tobytes(), LEVEL)

    streams = _each(stream, columns, bits.size * width)
    header = _HEADER.pack(MAGIC, VERSION, kind.encode(), columns, 0, values.size)
    return b"".join([header, struct.pack(f"<{columns}Q", *map(len, streams)), *streams])


def _each(function, columns, nbytes):
    """[function(column) for each column], on the pool's threads when the array is large."""
    if columns > 1 and nbytes >= PARALLEL_BYTES * columns:
        return list(threads.pool().map(function, range(columns)))
    return [function(column) for column in range(columns)]


def _header(data, source):
    """(type character, columns, flags, element count, stream lengths) of ``data``, checked."""
    if not isinstance(data, (bytes, bytearray)):
        raise SkinDetachError(f"{source}: expected packed bytes, got {type(data).__name__}; press Rebuild")
    if not is_packed(data):
        raise SkinDetachError(f"{source}: expected packed bytes starting {MAGIC!r}, got {bytes(data[:4])!r} "
                              f"({len(data)} bytes); press Rebuild")
    _, version, kind, columns, flags, count = _HEADER.unpack_from(data)
    kind = kind.decode("latin-1")
    if version != VERSION or kind not in TYPES or not 1 <= columns <= MOST_COLUMNS or count % columns \
            or flags or len(data) < _HEADER.size + 8 * columns:
        raise SkinDetachError(f"{source}: expected packed arrays of format {VERSION}, a type of {sorted(TYPES)} and "
                              f"1 to {MOST_COLUMNS} columns, got format {version}, type {kind!r}, {columns} "
                              f"columns, flags {flags}, {count} values; press Rebuild")
    lengths = struct.unpack_from(f"<{columns}Q", data, _HEADER.size)
    if _HEADER.size + 8 * columns + sum(lengths) != len(data):
        raise SkinDetachError(f"{source}: expected packed bytes of the length their header gives "
                              f"({_HEADER.size + 8 * columns + sum(lengths)}), got {len(data)} (truncated or damaged); "
                              f"press Rebuild")
    return kind, columns, flags, count, lengths


def packed_size(data, source="packed array"):
    """The number of values :func:`unpack` returns for ``data`` (its header read, nothing inflated)."""
    return _header(data, source)[3]


def unpack(data, source="packed array"):
    """The flat array ``data`` (:func:`pack`'s bytes) holds: (k * c,) of the packed type, the
    columns interleaved again as they were. Damage raises :class:`SkinDetachError` naming ``source``."""
    kind, columns, flags, count, lengths = _header(data, source)
    width = np.dtype(kind).itemsize
    rows = count // columns
    view = memoryview(data)
    starts = np.concatenate([[0], np.cumsum(lengths)]) + _HEADER.size + 8 * columns
    out = np.empty((rows, columns), dtype=TYPES[kind])

    def column(index):
        try:
            raw = zlib.decompress(view[int(starts[index]):int(starts[index + 1])], bufsize=max(rows * width, 1))
        except zlib.error as exc:
            return f"column {index} does not inflate ({exc})"
        if len(raw) != rows * width:
            return f"column {index} inflates to {len(raw)} bytes, expected {rows * width}"
        out[:, index] = np.frombuffer(raw, dtype=np.uint8).reshape(width, rows).T.copy().view(TYPES[kind]).ravel()
        return None

    errors = [error for error in _each(column, columns, count * width) if error is not None]
    if errors:
        raise SkinDetachError(f"{source}: expected packed data that inflates, got damaged data: {errors[0]}; "
                              f"press Rebuild")
    return out.view(np.dtype("<" + kind)).ravel()
