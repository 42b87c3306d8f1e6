"""Protobuf wire format for imulog's block messages, written and scanned without per-sample Python objects.

A packed ``repeated sfixed64`` / ``repeated double`` field is the tag, the byte length and the values as
little-endian 8-byte numbers; a packed ``repeated bool`` is one byte (0 or 1) per value. That is exactly
the layout of a numpy ``<i8`` / ``<f8`` / ``u1`` array, so blocks are written by joining array bytes and
read back with ``numpy.frombuffer`` on views of the payload. The bytes equal what protobuf's own
serializer produces for the same message (fields in number order), which ``tests/test_schemas.py`` checks.
"""

from __future__ import annotations

from typing import Any

import numpy as np

WIRE_VARINT, WIRE_I64, WIRE_LEN, WIRE_I32 = 0, 1, 2, 5


class Fallback(Exception):
    """The fast scan met something it does not handle (e.g. unpacked repeated values): use protobuf."""


def varint(value: int) -> bytes:
    """Unsigned LEB128 varint (protobuf's encoding of a uint32/uint64/bool/enum and of tags and lengths)."""
    if 0 <= value < _SMALL_N:
        return _SMALL[value]
    return _varint(value)


def _varint(value: int) -> bytes:
    out = bytearray()
    value &= (1 << 64) - 1
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


_SMALL_N = 1 << 14  # the varints of 0 .. 16383 (tags, counts, block lengths), computed once
_SMALL = [_varint(i) for i in range(_SMALL_N)]


def tag(number: int, wire: int) -> bytes:
    return varint(number << 3 | wire)


def len_field(number: int, data: bytes | memoryview) -> bytes:
    """A length-delimited field (bytes, string, packed repeated, sub-message); b"" when empty (proto3)."""
    if not len(data):
        return b""
    return tag(number, WIRE_LEN) + varint(len(data)) + bytes(data)


def packed(number: int, array: np.ndarray | None, dtype: np.dtype) -> bytes:
    """A packed repeated numeric field from a numpy array (row-major), b"" when None or empty."""
    if array is None:
        return b""
    return len_field(number, np.ascontiguousarray(array, dtype=dtype).tobytes())


def uint_field(number: int, value: int) -> bytes:
    return tag(number, WIRE_VARINT) + varint(value) if value else b""


def string_field(number: int, value: str) -> bytes:
    return len_field(number, value.encode("utf-8"))


def read_varint(mv: memoryview, pos: int) -> tuple[int, int]:
    result = shift = 0
    while True:
        b = mv[pos]
        pos += 1
        result |= (b & 0x7F) << shift
        if b < 0x80:
            return result, pos
        shift += 7
        if shift > 63:
            raise Fallback


def scan(payload: bytes | memoryview) -> list[tuple[int, int, Any]]:
    """``(field number, wire type, value)`` for every field: varints as int, length-delimited as views.

    Fixed-width scalar fields (wire types 1 and 5) come back as None (the block schemas have none at top
    level except inside packed arrays). Raises :class:`Fallback` on anything malformed.
    """
    mv = memoryview(payload)
    n = len(mv)
    pos = 0
    out = []
    append = out.append
    try:
        while pos < n:
            key = mv[pos]  # one-byte keys and lengths are the common case: no call for them
            if key < 0x80:
                pos += 1
            else:
                key, pos = read_varint(mv, pos)
            wire = key & 7
            if wire == WIRE_LEN:
                length = mv[pos]
                if length < 0x80:
                    pos += 1
                else:
                    length, pos = read_varint(mv, pos)
                end = pos + length
                if end > n:
                    raise Fallback
                append((key >> 3, wire, mv[pos:end]))
                pos = end
            elif wire == WIRE_VARINT:
                value = mv[pos]
                if value < 0x80:
                    pos += 1
                else:
                    value, pos = read_varint(mv, pos)
                append((key >> 3, wire, value))
            elif wire == WIRE_I64:
                append((key >> 3, wire, None))
                pos += 8
            elif wire == WIRE_I32:
                append((key >> 3, wire, None))
                pos += 4
            else:
                raise Fallback
    except IndexError:
        raise Fallback from None
    if pos != n:
        raise Fallback
    return out


# ------------------------------------------------------------------------------------- many messages at once


def varint_rows(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """LEB128 varints of N integers at once: (N, W) uint8 bytes and (N, W) bool mask of the bytes used.

    W is the longest varint among the values (at most 10); negative values are encoded as protobuf encodes
    int64 (two's complement, 10 bytes).
    """
    v = np.asarray(values).astype(np.int64, copy=False).view(np.uint64)
    top = int(v.max()) if len(v) else 0
    width = max(1, (top.bit_length() + 6) // 7)
    shifts = np.arange(width, dtype=np.uint64) * np.uint64(7)
    length = np.ones(len(v), dtype=np.int64)
    for k in range(1, width):
        length += v >= np.uint64(1 << (7 * k))
    col = np.arange(width)
    mask = col[None, :] < length[:, None]
    out = ((v[:, None] >> shifts[None, :]) & np.uint64(0x7F)).astype(np.uint8)
    out |= (col[None, :] < (length - 1)[:, None]).view(np.uint8) << np.uint8(7)
    return out, mask


class Rows:
    """N protobuf messages built field by field as columns: bytes (N, W) and a mask of the bytes each uses.

    Every field method appends a fixed-width column block; a message is its row's masked bytes in order.
    Fields must be added in field-number order (as protobuf serializes them). Scalars follow proto3: a zero
    value is left out (``omit_zero``); sub-messages are always present, as protobuf writes a set sub-message.
    """

    def __init__(self, n: int) -> None:
        self.n = n
        self._cols: list[np.ndarray] = []
        self._masks: list[np.ndarray | None] = []

    def raw(self, data: bytes) -> Rows:
        """The same bytes in every message."""
        if data:
            self._cols.append(np.broadcast_to(np.frombuffer(data, np.uint8), (self.n, len(data))))
            self._masks.append(None)
        return self

    def _add(self, cols: np.ndarray, mask: np.ndarray | None) -> None:
        self._cols.append(cols)
        self._masks.append(mask)

    def varint(self, number: int, values: np.ndarray, omit_zero: bool = True) -> Rows:
        v = np.asarray(values).astype(np.int64, copy=False)
        body, mask = varint_rows(v)
        key = np.broadcast_to(np.frombuffer(tag(number, WIRE_VARINT), np.uint8), (self.n, len(tag(number, 0))))
        present = (v != 0) if omit_zero else np.ones(self.n, dtype=bool)
        self._add(
            np.concatenate([key, body], axis=1),
            np.concatenate([np.repeat(present[:, None], key.shape[1], 1), mask & present[:, None]], axis=1),
        )
        return self

    def double(self, number: int, values: np.ndarray, omit_zero: bool = True) -> Rows:
        v = np.ascontiguousarray(values, dtype="<f8")
        key = np.frombuffer(tag(number, WIRE_I64), np.uint8)
        cols = np.concatenate([np.broadcast_to(key, (self.n, len(key))), v.view(np.uint8).reshape(self.n, 8)], axis=1)
        if omit_zero:
            present = v.view(np.uint64) != 0  # +0.0 is left out, -0.0 is not (protobuf compares the bits)
            self._add(cols, np.repeat(present[:, None], cols.shape[1], 1))
        else:
            self._add(cols, None)
        return self

    def message(self, number: int, sub: Rows) -> Rows:
        """A length-delimited field holding ``sub``'s messages (a sub-message, or ``bytes`` built as Rows)."""
        cols, mask = sub.build()
        lengths = np.count_nonzero(mask, axis=1) if mask is not None else np.full(self.n, cols.shape[1])
        head, head_mask = varint_rows(lengths)
        key = np.broadcast_to(np.frombuffer(tag(number, WIRE_LEN), np.uint8), (self.n, len(tag(number, 2))))
        full = np.ones(cols.shape, dtype=bool) if mask is None else mask
        self._add(
            np.concatenate([key, head, cols], axis=1),
            np.concatenate([np.ones(key.shape, dtype=bool), head_mask, full], axis=1),
        )
        return self

    def data(self, number: int, values: np.ndarray, mask: np.ndarray | None = None) -> Rows:
        """A ``bytes`` field from (N, K) uint8 (``mask`` keeps some of them), left out when empty (proto3)."""
        values = np.asarray(values, dtype=np.uint8).reshape(self.n, -1)
        sub = Rows(self.n)
        sub._add(values, mask)
        self.message(number, sub)
        present = mask.any(axis=1) if mask is not None else np.full(self.n, values.shape[1] > 0)
        if not present.all():
            self._masks[-1] = self._masks[-1] & present[:, None]  # message() always leaves a mask
        return self

    def build(self) -> tuple[np.ndarray, np.ndarray | None]:
        """(N, W) uint8 and the (N, W) mask (None when every byte is used)."""
        if not self._cols:
            return np.zeros((self.n, 0), dtype=np.uint8), None
        cols = np.concatenate(self._cols, axis=1)
        if all(m is None for m in self._masks):
            return cols, None
        mask = np.concatenate(
            [np.ones(c.shape, dtype=bool) if m is None else m for c, m in zip(self._cols, self._masks, strict=True)],
            axis=1,
        )
        return cols, mask


def row_messages(rows: np.ndarray, mask: np.ndarray | None) -> list[bytes]:
    """The messages of :meth:`Rows.build` as one ``bytes`` each."""
    if mask is None:
        return [r.tobytes() for r in rows]
    flat = rows[mask].tobytes()
    ends = np.cumsum(np.count_nonzero(mask, axis=1)).tolist()
    starts = [0, *ends[:-1]]
    return [flat[a:b] for a, b in zip(starts, ends, strict=True)]


# ------------------------------------------------------------------------- packed varints as numpy arrays


def zigzag_varints(values: np.ndarray) -> tuple[bytes, np.ndarray]:
    """Packed ``sint64`` bytes of ``values`` (zigzag LEB128, row-major) and the byte length of each value.

    One pass of numpy per byte position over the whole array: the bytes of any run of values are the slice
    between the cumulative sums of the lengths (how :mod:`imulog.archive.codec` cuts blocks without a
    per-block encode).
    """
    v = np.ascontiguousarray(values, dtype=np.int64).reshape(-1)
    if len(v) >= 65536:  # compiled: one pass instead of one numpy pass per byte position
        from imulog.archive.wire_kernels import zigzag_encode

        data, lengths = zigzag_encode(np.require(v, np.int64, ["C", "W"]))
        return data.tobytes(), lengths
    z = ((v << np.int64(1)) ^ (v >> np.int64(63))).view(np.uint64)
    if not len(z):
        return b"", np.zeros(0, dtype=np.int64)
    top = int(z.max())
    width = max(1, (top.bit_length() + 6) // 7)
    if width == 1:
        return z.astype(np.uint8).tobytes(), np.ones(len(z), dtype=np.int64)
    if width <= 4:
        z = z.astype(np.uint32)  # values < 2**28: cheaper shifts
    length = np.ones(len(z), dtype=np.int8)
    for k in range(1, width):
        length += z >= (1 << (7 * k))
    rows = np.empty((len(z), width), dtype=np.uint8)  # byte k of each value, then the used ones compacted
    for k in range(width):
        rows[:, k] = ((z >> (7 * k)) & 0x7F).astype(np.uint8) | ((length > k + 1).view(np.uint8) << np.uint8(7))
    used = np.arange(width, dtype=np.int8)[None, :] < length[:, None]
    return rows[used].tobytes(), length.astype(np.int64)


def read_zigzag_varints(data: bytes | bytearray | memoryview, n: int, what: str) -> np.ndarray:
    """int64 array of the ``n`` packed ``sint64`` varints in ``data`` (the inverse of :func:`zigzag_varints`).

    Raises ValueError naming ``what`` when the bytes do not hold exactly ``n`` varints of at most 10 bytes.
    """
    b = np.frombuffer(data, dtype=np.uint8)
    if n == 0:
        if len(b):
            raise ValueError(f"{what}: {len(b)} bytes for 0 values")
        return np.zeros(0, dtype=np.int64)
    if n >= 65536 and len(b) != n:  # compiled: one pass
        from imulog.archive.wire_kernels import zigzag_decode

        values, bad = zigzag_decode(np.require(b, np.uint8, ["C", "W"]), n)
        if not bad:
            return values
    if len(b) == n:  # every value one byte
        if b.max() >= 0x80:
            raise ValueError(f"{what}: a varint runs past the end of the data")
        z = b.astype(np.int64)
        return (z >> 1) ^ -(z & 1)
    ends = np.flatnonzero(b < 0x80)
    if len(ends) != n or ends[-1] != len(b) - 1:
        raise ValueError(f"{what}: {len(ends)} varints in {len(b)} bytes for {n} values")
    starts = np.empty(n, dtype=np.int64)
    starts[0] = 0
    starts[1:] = ends[:-1] + 1
    length = ends - starts + 1
    top = int(length.max())
    if top > 10:
        raise ValueError(f"{what}: a varint longer than 10 bytes")
    low = np.concatenate([b & np.uint8(0x7F), np.zeros(top, dtype=np.uint8)])
    kind = np.uint32 if top <= 4 else np.uint64
    z = low[starts].astype(kind)
    for k in range(1, top):
        part = low[starts + k].astype(kind)
        part[length <= k] = 0
        z |= part << kind(7 * k)
    z = z.astype(np.uint64)
    return ((z >> np.uint64(1)).view(np.int64)) ^ -((z & np.uint64(1)).view(np.int64))
