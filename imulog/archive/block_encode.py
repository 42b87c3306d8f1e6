"""The block messages of one stream, built for all blocks at once (numpy plans, one compiled assembly pass).

A block message is a sequence of segments: constant bytes (tags, the head of strings), varints computed per
block (counts, lengths, start and span), and slices of the stream's packed arrays. Each segment is one column
of a (blocks, segments) table of source offsets and lengths into one byte pool (lengths 0 where a block leaves
the field out); :func:`imulog.archive.wire_kernels.assemble` copies them into the messages in one call. The
bytes equal those of the per-block encoder that preceded it (``tests/test_codec_fast.py`` compares them).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from imulog.archive import numbers, wire

SCHEMA_VERSION = 2
SCHEMA_VERSION_V1 = 1
BLOCK_NS = 1_000_000_000
_I8 = np.dtype("<i8")
_F8 = np.dtype("<f8")


class Layout:
    """Field numbers of one block schema: head (strings), count, t_ns, compact time, arrays (f64 and Numbers)."""

    def __init__(
        self,
        head: bytes,
        count: int,
        t_field: int,
        time_fields: tuple[int, int, int],
        arrays: list[tuple[int, int, np.ndarray | None, Any]],
        precision: str,
        extra: list[tuple[int, np.ndarray, np.dtype]] | None = None,
        f64_values: dict[int, np.ndarray] | None = None,
    ) -> None:
        self.head, self.count, self.t_field, self.time_fields = head, count, t_field, time_fields
        self.arrays, self.precision, self.extra = arrays, precision, extra or []
        # float64 field number -> what a block that stays float64 writes there, when it differs from the array
        # planned for counts (markers: NaN at invalid samples, planned as 0 so occlusions do not block counts)
        self.f64_values = f64_values or {}
        self.compact = True


def block_bounds(t_ns: np.ndarray, block_ns: int = BLOCK_NS) -> list[tuple[int, int]]:
    """Index ranges of consecutive samples falling in the same ``block_ns`` window (from the first sample)."""
    first, last = block_edges(t_ns, block_ns)
    return list(zip(first.tolist(), last.tolist(), strict=True))


def block_edges(t_ns: np.ndarray, block_ns: int = BLOCK_NS) -> tuple[np.ndarray, np.ndarray]:
    """(first, end) index arrays of the blocks of :func:`block_bounds`."""
    n = len(t_ns)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    window = (np.asarray(t_ns) - t_ns[0]) // block_ns
    cuts = np.flatnonzero(np.diff(window)) + 1
    return np.concatenate([[0], cuts]).astype(np.int64), np.concatenate([cuts, [n]]).astype(np.int64)


def varint_lengths(values: np.ndarray) -> np.ndarray:
    """Bytes of the unsigned LEB128 varint of each value (int64 read as uint64)."""
    v = np.asarray(values, dtype=np.int64).view(np.uint64)
    out = np.ones(len(v), dtype=np.int64)
    for k in range(1, 10):
        above = v >= np.uint64(1 << (7 * k))
        if not above.any():
            break
        out += above
    return out


class _Segments:
    """Columns of (source offset, length) per block into one pool of bytes, in message order."""

    def __init__(self, nb: int) -> None:
        self.nb = nb
        self.parts: list[np.ndarray] = []
        self.size = 0
        self.starts: list[np.ndarray] = []
        self.lens: list[np.ndarray] = []

    def _part(self, data: np.ndarray) -> int:
        base = self.size
        if len(data):
            self.parts.append(data)
            self.size += len(data)
        return base

    def const(self, data: bytes, present: np.ndarray | None = None) -> None:
        if not data:
            return
        base = self._part(np.frombuffer(data, np.uint8))
        self.starts.append(np.full(self.nb, base, np.int64))
        n = np.full(self.nb, len(data), np.int64)
        self.lens.append(n if present is None else n * present)

    def varint(self, values: np.ndarray, present: np.ndarray | None = None) -> None:
        v = np.asarray(values, dtype=np.int64)
        rows, mask = wire.varint_rows(v)
        lengths = np.count_nonzero(mask, axis=1).astype(np.int64)
        base = self._part(rows[mask])
        self.starts.append(base + np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64))
        self.lens.append(lengths if present is None else lengths * present)

    def data(self, buf: np.ndarray, starts: np.ndarray, lens: np.ndarray, present: np.ndarray | None = None) -> None:
        base = self._part(buf)
        self.starts.append(base + np.asarray(starts, dtype=np.int64))
        lens = np.asarray(lens, dtype=np.int64)
        self.lens.append(lens if present is None else lens * present)

    def len_field(self, number: int, buf: np.ndarray, starts: np.ndarray, lens: np.ndarray, present: Any) -> None:
        """tag, length, body where ``present`` and the body is not empty (proto3 leaves empty fields out)."""
        on = (np.asarray(lens) > 0) & present
        self.const(wire.tag(number, wire.WIRE_LEN), on)
        self.varint(lens, on)
        self.data(buf, starts, lens, on)

    def build(self) -> list[bytes]:
        from imulog.archive.wire_kernels import assemble

        if not self.starts:
            return [b""] * self.nb
        pool = np.concatenate(self.parts) if self.parts else np.zeros(0, np.uint8)
        starts = np.require(np.stack(self.starts, axis=1), np.int64, ["C", "W"])
        out, bounds = assemble(pool, starts, np.require(np.stack(self.lens, axis=1), np.int64, ["C", "W"]))
        del pool
        data = out.tobytes()  # one copy, then each message a slice of it (faster than a memoryview's per message)
        del out
        b = bounds.tolist()
        return [data[i:j] for i, j in zip(b[:-1], b[1:], strict=True)]


def _bytes_of(a: np.ndarray, dtype: np.dtype) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=dtype).reshape(-1).view(np.uint8)


def encode_blocks(t_ns: np.ndarray, layout: Layout) -> tuple[list[int], list[bytes]]:
    """The block messages of one stream: numpy plans for the whole stream, then one assembly for all blocks.

    Fields go out in number order without sorting: layout-1 fields (``t_ns``, float64 arrays, extras) come
    before the version-2 ones (compact times, then the ``_q`` arrays), as their numbers do.
    """
    first, end = block_edges(t_ns)
    nb = len(first)
    if not nb:
        return [], []
    n_rows = len(t_ns)
    counts = end - first
    bounds = list(zip(first.tolist(), end.tolist(), strict=True))
    tp = numbers.plan_times(t_ns, bounds)
    if not layout.compact:
        tp.compact[:] = False
    compact = tp.compact
    edges_rows = np.append(first, n_rows)
    arrays = []
    for f64_no, q_no, values, hint in layout.arrays:
        if values is None:
            continue
        v = np.asarray(values).reshape(n_rows, -1)
        plan = numbers.plan_numbers(v, hint, layout.precision) if layout.compact else None
        ok = np.zeros(nb, bool) if plan is None else np.logical_and.reduceat(plan.ok, first)
        arrays.append((f64_no, q_no, v, plan, ok))
    # which blocks carry version-2 fields
    t0z = (tp.t0 << 1) ^ (tp.t0 >> 63)
    spanz = (tp.span << 1) ^ (tp.span >> 63)
    high = compact & ((tp.t0 != 0) | (tp.span != 0) | tp.has_resid)
    for *_, ok in arrays:
        high = high | ok
    seg = _Segments(nb)
    seg.const(wire.uint_field(1, SCHEMA_VERSION) + layout.head, high)
    seg.const(wire.uint_field(1, SCHEMA_VERSION_V1) + layout.head, ~high)
    seg.const(wire.tag(layout.count, wire.WIRE_VARINT))
    seg.varint(counts)
    if not compact.all():
        row_bytes = 8 * first
        seg.len_field(layout.t_field, _bytes_of(t_ns, _I8), row_bytes, 8 * counts, ~compact)
    for f64_no, _, v, _, ok in arrays:
        if not ok.all():
            w = v.shape[1] * 8
            f64 = np.asarray(layout.f64_values.get(f64_no, v)).reshape(v.shape)
            seg.len_field(f64_no, _bytes_of(f64, _F8), w * first, w * counts, ~ok)
    for number, a, dtype in layout.extra:
        a = np.asarray(a).reshape(n_rows, -1)
        w = a.shape[1] * np.dtype(dtype).itemsize
        seg.len_field(number, _bytes_of(a, np.dtype(dtype)), w * first, w * counts, np.ones(nb, bool))
    t0_no, span_no, resid_no = layout.time_fields
    if compact.any():
        on = compact & (tp.t0 != 0)
        seg.const(wire.tag(t0_no, wire.WIRE_VARINT), on)
        seg.varint(t0z, on)
        on = compact & (tp.span != 0)
        seg.const(wire.tag(span_no, wire.WIRE_VARINT), on)
        seg.varint(spanz, on)
        if tp.has_resid.any():
            rs = tp.resid_starts[edges_rows]
            seg.len_field(resid_no, np.frombuffer(tp.resid, np.uint8), rs[:-1], np.diff(rs), compact & tp.has_resid)
    for _, q_no, _, plan, ok in arrays:
        if plan is None or not ok.any():
            continue
        cum = plan.cumulative()[edges_rows]
        body_len = np.diff(cum).astype(np.int64)
        has_body = body_len > 0
        inner_tag = b"\x0a" if plan.kind == "counts" else b"\x32"
        inner = np.where(has_body, len(inner_tag) + varint_lengths(body_len) + body_len + len(plan.head), 0)
        dec = None
        if plan.decimal_starts is not None:
            ds = plan.decimal_starts[edges_rows]
            dec = (ds[:-1], np.diff(ds).astype(np.int64))
            inner = inner + 1 + varint_lengths(dec[1]) + dec[1]
        seg.const(wire.tag(q_no, wire.WIRE_LEN), ok)
        seg.varint(inner, ok)
        on = ok & has_body
        seg.const(inner_tag, on)
        seg.varint(body_len, on)
        seg.data(np.frombuffer(plan.data, np.uint8), cum[:-1], body_len, on)
        seg.const(plan.head, on)
        if dec is not None:
            seg.const(b"\x3a", ok)
            seg.varint(dec[1], ok)
            seg.data(np.frombuffer(plan.decimals, np.uint8), dec[0], dec[1], ok)
    return first.tolist(), seg.build()


def strings_field(number: int, values: Sequence[str]) -> bytes:
    """A repeated string field (each value its own length-delimited entry, empty strings included)."""
    out = b""
    for value in values:
        data = str(value).encode("utf-8")
        out += wire.tag(number, wire.WIRE_LEN) + wire.varint(len(data)) + data
    return out
