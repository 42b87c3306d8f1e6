"""Compiled (numba) loops over many protobuf messages at once: scan their fields, gather and assemble bytes.

Imported lazily by :mod:`imulog.archive.block_encode` and :mod:`imulog.archive.block_decode` (commands that
only read summaries do not pay for numba). Every function works on one uint8 buffer holding all messages
(``b"".join(payloads)``) and int64 offset tables, so a chunk of blocks costs one call, not one per block.

The count formulas (counts_check, quantize_counts, apply_counts) use ``error_model="numpy"``: a division is the
IEEE one (the same bits as numpy's; a zero parameter gives inf and the value fails the check) without numba's
ZeroDivisionError branch, which kept the loops from compiling tight (5x slower). Their inlined helpers take
scalars: an array argument costs an atomic reference count per call (10x the arithmetic).
"""

from __future__ import annotations

import numpy as np
from numba import njit

# scan_many status codes (0: every message scanned)
BAD_WIRE = 1  # malformed: truncated, over-long varint, group wire types
REPEATED = 2  # a field given twice in one message (unpacked repeated values or concatenated messages)


@njit(cache=True, nogil=True, inline="always")
def _varint(pool, pos, end):  # pragma: no cover - compiled
    """The varint at ``pool[pos:end]``: (value, position after it); position -1 when truncated or over-long."""
    v = np.int64(0)
    shift = 0
    while True:
        if pos >= end or shift > 63:
            return v, -1
        c = pool[pos]
        pos += 1
        v |= np.int64(c & 0x7F) << shift
        if c < 0x80:
            return v, pos
        shift += 7


@njit(cache=True, nogil=True)
def scan_many(pool, starts, ends, nfields, multi):  # pragma: no cover - compiled
    """Fields 1..nfields-1 of each message ``pool[starts[b]:ends[b]]``.

    Returns (status, value, offset, length, wire, hash): varint fields' values in ``value``; length-delimited
    fields' payload ``offset`` (absolute in pool, -1 when absent) and ``length``; ``wire`` the wire type seen
    (-1 absent). Fields with ``multi[f]`` (repeated strings) may occur many times: their (number, bytes) go
    into an FNV-1a ``hash`` per message instead, so callers can check they are the same in every block.
    Unknown field numbers (>= nfields) are skipped, as protobuf does.
    """
    nb = len(starts)
    value = np.zeros((nb, nfields), np.int64)
    offset = np.full((nb, nfields), -1, np.int64)
    length = np.zeros((nb, nfields), np.int64)
    wire = np.full((nb, nfields), -1, np.int8)
    hashes = np.zeros(nb, np.uint64)
    prime = np.uint64(1099511628211)
    for b in range(nb):
        pos = starts[b]
        end = ends[b]
        h = np.uint64(14695981039346656037)
        while pos < end:
            key, pos = _varint(pool, pos, end)
            if pos < 0:
                return BAD_WIRE, value, offset, length, wire, hashes
            number = key >> 3
            wt = key & 7
            if wt == 0:
                v, pos = _varint(pool, pos, end)
                if pos < 0:
                    return BAD_WIRE, value, offset, length, wire, hashes
                if number < nfields:
                    if wire[b, number] != -1:
                        return REPEATED, value, offset, length, wire, hashes
                    wire[b, number] = 0
                    value[b, number] = v
            elif wt == 2:
                n, pos = _varint(pool, pos, end)
                if pos < 0:
                    return BAD_WIRE, value, offset, length, wire, hashes
                if n < 0 or pos + n > end:
                    return BAD_WIRE, value, offset, length, wire, hashes
                if number < nfields:
                    if multi[number]:
                        h = (h ^ np.uint64(number)) * prime
                        h = (h ^ np.uint64(n)) * prime
                        for k in range(pos, pos + n):
                            h = (h ^ np.uint64(pool[k])) * prime
                        if wire[b, number] == -1:
                            offset[b, number] = pos
                            length[b, number] = n
                        wire[b, number] = 2
                    else:
                        if wire[b, number] != -1:
                            return REPEATED, value, offset, length, wire, hashes
                        wire[b, number] = 2
                        offset[b, number] = pos
                        length[b, number] = n
                pos += n
            elif wt == 1:
                pos += 8
                if number < nfields:
                    wire[b, number] = 1
            elif wt == 5:
                pos += 4
                if number < nfields:
                    wire[b, number] = 5
            else:
                return BAD_WIRE, value, offset, length, wire, hashes
        if pos != end:
            return BAD_WIRE, value, offset, length, wire, hashes
        hashes[b] = h
    return 0, value, offset, length, wire, hashes


@njit(cache=True, nogil=True)
def gather(pool, offset, length):  # pragma: no cover - compiled
    """The byte ranges ``pool[offset[b]:offset[b] + length[b]]`` joined (ranges with offset -1 are empty)."""
    total = 0
    for b in range(len(offset)):
        if offset[b] >= 0:
            total += length[b]
    out = np.empty(total, np.uint8)
    k = 0
    for b in range(len(offset)):
        o = offset[b]
        if o < 0:
            continue
        n = length[b]
        out[k : k + n] = pool[o : o + n]
        k += n
    return out


@njit(cache=True, nogil=True)
def assemble(pool, seg_start, seg_len):  # pragma: no cover - compiled
    """Messages made of segments: row b is ``pool[seg_start[b, s]:][:seg_len[b, s]]`` for s in order.

    Returns (bytes of every message joined, start offset of each message, N + 1).
    """
    nb, ns = seg_start.shape
    bounds = np.zeros(nb + 1, np.int64)
    for b in range(nb):
        t = 0
        for s in range(ns):
            t += seg_len[b, s]
        bounds[b + 1] = bounds[b] + t
    out = np.empty(bounds[nb], np.uint8)
    for b in range(nb):
        k = bounds[b]
        for s in range(ns):
            o = seg_start[b, s]
            n = seg_len[b, s]
            if n > 32:
                out[k : k + n] = pool[o : o + n]
            else:  # tags and varints: a few bytes, no slice objects
                for i in range(n):
                    out[k + i] = pool[o + i]
            k += n
    return out, bounds


@njit(cache=True, nogil=True)
def zigzag_encode(values):  # pragma: no cover - compiled
    """Packed ``sint64`` bytes of int64 ``values`` (zigzag LEB128) and each value's byte length."""
    n = len(values)
    lengths = np.empty(n, np.int64)
    out = np.empty(n * 10, np.uint8)
    k = 0
    for i in range(n):
        v = values[i]
        z = np.uint64((v << 1) ^ (v >> 63))
        start = k
        while z >= 0x80:
            out[k] = np.uint8((z & np.uint64(0x7F)) | np.uint64(0x80))
            z >>= np.uint64(7)
            k += 1
        out[k] = np.uint8(z)
        k += 1
        lengths[i] = k - start
    return out[:k], lengths


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _rounded_count(x, shift, divisor, scale, offset, u0, u1, u2, u3):  # pragma: no cover - compiled
    """The inverse formula on one value in the order of :func:`imulog.archive.numbers._counts_of`, rounded
    (float64; ``u0..u3``: whether shift, divisor, scale, offset apply). Scalars only: an array argument would
    cost an atomic reference count per call (10x the arithmetic)."""
    c = x - offset if u3 else x
    if u2:
        c = c / scale
    if u1:
        c = c * divisor
    if u0:
        c = c - shift
    return np.rint(c)


@njit(cache=True, nogil=True, inline="always", error_model="numpy")
def _value_of(c, shift, divisor, scale, offset, u0, u1, u2, u3):  # pragma: no cover - compiled
    """The forward formula on the float64 count ``c``, in the order of :func:`imulog.archive.numbers.apply`
    (no fast-math: the same bits; scalars only, as :func:`_rounded_count`)."""
    if u0:
        c = c + shift
    if u1:
        c = c / divisor
    if u2:
        c = c * scale
    if u3:
        c = c + offset
    return c


@njit(cache=True, nogil=True, error_model="numpy")
def counts_check(values, shift, divisor, scale, offset, use):  # pragma: no cover - compiled
    """Counts of (N, C) ``values`` under the parameters (``use``: which of the 4 apply) and rows given back.

    The inverse formula rounded to a whole number (0 outside sfixed32), then the forward formula in float64
    in the order of :func:`imulog.archive.numbers.apply`; values it does not give back exactly get count 0.
    """
    n, w = values.shape
    counts = np.zeros((n, w), np.int32)
    ok = np.ones(n, np.bool_)
    u0, u1, u2, u3 = use[0], use[1], use[2], use[3]
    for i in range(n):
        for j in range(w):
            x = values[i, j]
            sh, dv, sc, of = shift[j], divisor[j], scale[j], offset[j]
            c = _rounded_count(x, sh, dv, sc, of, u0, u1, u2, u3)
            if not abs(c) < 2147483648.0:
                c = 0.0
            if _value_of(c, sh, dv, sc, of, u0, u1, u2, u3) == x:
                counts[i, j] = np.int32(c)
            else:
                ok[i] = False
    return counts, ok


@njit(cache=True, nogil=True, error_model="numpy")
def quantize_counts(values, shift, divisor, scale, offset, use):  # pragma: no cover - compiled
    """Counts of (N, C) ``values`` rounded onto the parameters' grid (``use``: which of the 4 apply) and the rows
    that have them: the inverse formula in the order of :func:`imulog.archive.numbers._counts_of`, rounded; a row
    with a value that is not finite or beyond sfixed32 is not ok and gets counts 0."""
    n, w = values.shape
    counts = np.zeros((n, w), np.int32)
    ok = np.ones(n, np.bool_)
    u0, u1, u2, u3 = use[0], use[1], use[2], use[3]
    for i in range(n):
        good = True  # a local flag, not ok[i] read back: 5x faster
        for j in range(w):
            x = values[i, j]
            c = _rounded_count(x, shift[j], divisor[j], scale[j], offset[j], u0, u1, u2, u3)
            if abs(c) < 2147483648.0:  # NaN and inf fail too
                counts[i, j] = np.int32(c)
            else:
                good = False
        if not good:
            ok[i] = False
            for j in range(w):
                counts[i, j] = 0
    return counts, ok


@njit(cache=True, nogil=True, error_model="numpy")
def apply_counts(counts, shift, divisor, scale, offset, use):  # pragma: no cover - compiled
    """float64 values of (N, C) int32 ``counts``: :func:`imulog.archive.numbers.apply` in one pass (the same
    operations in the same order, no fast-math: bit-identical); ``use`` says which of the 4 parameters apply."""
    n, w = counts.shape
    out = np.empty((n, w), np.float64)
    u0, u1, u2, u3 = use[0], use[1], use[2], use[3]
    for i in range(n):
        for j in range(w):
            out[i, j] = _value_of(np.float64(counts[i, j]), shift[j], divisor[j], scale[j], offset[j], u0, u1, u2, u3)
    return out


@njit(cache=True, nogil=True)
def zigzag_decode(data, n):  # pragma: no cover - compiled
    """int64 values of ``n`` packed ``sint64`` varints; (values, 0) or (partial, 1) when the bytes do not hold
    exactly ``n`` varints of at most 10 bytes each."""
    out = np.zeros(n, np.int64)
    pos = 0
    end = len(data)
    for i in range(n):
        z = np.uint64(0)
        shift = 0
        while True:
            if pos >= end or shift > 63:
                return out, 1
            c = data[pos]
            pos += 1
            z |= np.uint64(c & 0x7F) << np.uint64(shift)
            if c < 0x80:
                break
            shift += 7
        out[i] = np.int64(z >> np.uint64(1)) ^ -np.int64(z & np.uint64(1))
    if pos != end:
        return out, 1
    return out, 0
