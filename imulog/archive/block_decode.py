"""Decode all block messages of a channel at once: one compiled scan, then numpy over joined fields.

:func:`columns` scans every block's top-level fields in one call (:func:`imulog.archive.wire_kernels.scan_many`)
into (blocks, fields) tables of varint values and byte ranges; times and arrays are then gathered over all
blocks with one call per field. Only the common layouts take this path: anything unusual (a field twice,
an unexpected wire type, blocks whose Numbers parameters differ, a field missing in some blocks, sizes that do
not add up) returns None and the caller decodes block by block, which also gives the precise error.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from imulog.archive import numbers, wire

MIN_BLOCKS = 8  # fewer blocks: the per-block path (no numba import for a handful of messages)
_NUMBERS_FIELDS = 8


class Columns:
    """Top-level fields of N block messages: values (varints) and byte ranges (length-delimited) per block."""

    def __init__(self, pool: np.ndarray, value: np.ndarray, offset: np.ndarray, length: np.ndarray, wt: Any):
        self.pool, self.value, self.offset, self.length, self.wire = pool, value, offset, length, wt
        self.count = value[:, 0]  # replaced by the caller with the count field

    def gather(self, number: int, blocks: np.ndarray | None = None) -> np.ndarray:
        from imulog.archive.wire_kernels import gather

        off, ln = self.offset[:, number], self.length[:, number]
        if blocks is not None:
            off, ln = off[blocks], ln[blocks]
        return gather(self.pool, _i8(off), _i8(ln))


def _i8(a: np.ndarray) -> np.ndarray:
    """C-contiguous writable int64: the one signature the compiled kernels are built (and cached) for."""
    return np.require(a, np.int64, ["C", "W"])


def columns(payloads: Sequence[bytes | memoryview], spec: dict[int, tuple[str, str]]) -> Columns | None:
    """The fields of every block, or None when the per-block path must decide (see the module docstring)."""
    if len(payloads) < MIN_BLOCKS:
        return None
    from imulog.archive.wire_kernels import scan_many

    lengths = np.fromiter(map(len, payloads), np.int64, len(payloads))
    ends = np.cumsum(lengths)
    pool = np.frombuffer(b"".join(payloads), np.uint8)
    nfields = max(spec) + 1
    multi = np.zeros(nfields, np.bool_)
    expected = np.full(nfields, -1, np.int8)
    for number, (_, kind) in spec.items():
        multi[number] = kind == "rstring"
        expected[number] = 0 if kind in ("varint", "svarint") else 2
    status, value, offset, length, wt, hashes = scan_many(pool, _i8(ends - lengths), _i8(ends), nfields, multi)
    if status or bool((hashes != hashes[0]).any()):  # malformed, or strings that change between blocks
        return None
    seen = wt >= 0
    if bool((seen & (wt != expected[None, :])).any()):
        return None
    return Columns(pool, value, offset, length, wt)


def _zigzag(v: np.ndarray) -> np.ndarray:
    u = v.view(np.uint64)
    return (u >> np.uint64(1)).view(np.int64) ^ -(u & np.uint64(1)).view(np.int64)


def times(c: Columns, t_no: int, t0_no: int, span_no: int, resid_no: int, counts: np.ndarray, what: str):
    """int64 times of all blocks (explicit ``t_ns`` or start + span + residuals), None to use the per-block path."""
    total = int(counts.sum())
    explicit = c.length[:, t_no] > 0
    out = np.empty(total, dtype=np.int64)
    rows_explicit = np.repeat(explicit, counts) if explicit.any() else None
    if explicit.any():
        raw = c.gather(t_no, np.flatnonzero(explicit))
        if len(raw) != int(counts[explicit].sum()) * 8:
            return None
        if explicit.all():
            return raw.view("<i8").astype(np.int64)
        out[rows_explicit] = raw.view("<i8")
    comp = ~explicit
    n = counts[comp]
    t = numbers.spread(_zigzag(c.value[comp, t0_no]), _zigzag(c.value[comp, span_no]), n)
    has = c.length[comp, resid_no] > 0
    if has.any():
        raw = c.gather(resid_no, np.flatnonzero(comp)[has])
        try:
            res = wire.read_zigzag_varints(raw, int(n[has].sum()), f"{what} t_residual_ns")
        except ValueError:
            return None
        if has.all():
            t += res
        else:
            t[np.repeat(has, n)] += res
    if rows_explicit is None:
        return t
    out[~rows_explicit] = t
    return out


def _same_rows(c: Columns, number: int, blocks: np.ndarray) -> bytes | None:
    """The bytes of field ``number`` when they are the same in every one of ``blocks`` (b"" absent), else None."""
    ln = c.length[blocks, number]
    if not len(ln) or bool((ln != ln[0]).any()):
        return None if len(ln) else b""
    if ln[0] == 0:
        return b"" if bool((c.wire[blocks, number] == c.wire[blocks[0], number]).all()) else None
    raw = c.gather(number, blocks).reshape(len(blocks), int(ln[0]))
    return raw[0].tobytes() if bool((raw == raw[0]).all()) else None


def array(c: Columns, f64_no: int, q_no: int | None, counts: np.ndarray, width: int, required: bool):
    """(N, width) float64 of one array field over all blocks; (False, None) when absent; None: per-block path."""
    total = int(counts.sum())
    f64 = c.length[:, f64_no] > 0
    q = (c.wire[:, q_no] == 2) & ~f64 if q_no is not None else np.zeros(len(f64), bool)
    none = ~f64 & ~q
    if none.all() and not required:
        return False, None
    if (none & (counts > 0)).any():
        return None
    out = np.empty((total, width), dtype=np.float64)
    groups: list[tuple[np.ndarray, np.ndarray]] = []
    if f64.any():
        raw = c.gather(f64_no, np.flatnonzero(f64))
        if len(raw) != int(counts[f64].sum()) * width * 8:
            return None
        groups.append((f64, raw.view("<f8")))
    if q.any():
        from imulog.archive.wire_kernels import scan_many

        qb = np.flatnonzero(q)
        starts = c.offset[qb, q_no]
        multi = np.zeros(_NUMBERS_FIELDS, np.bool_)
        status, _, off, ln, wt, _ = scan_many(
            c.pool, _i8(starts), _i8(starts + c.length[qb, q_no]), _NUMBERS_FIELDS, multi
        )
        if status or bool(((wt >= 0) & (wt != 2)).any()):
            return None
        sub = Columns(c.pool, np.zeros_like(off), off, ln, wt)
        is_counts = (ln[:, 1] > 0) | ~(ln[:, 6] > 0)
        for kind_mask, is_c in ((is_counts, True), (~is_counts, False)):
            if not kind_mask.any():
                continue
            sel = np.flatnonzero(kind_mask)
            blocks = np.zeros(len(f64), bool)
            blocks[qb[sel]] = True
            n = int(counts[blocks].sum())
            if not is_c:
                raw = sub.gather(6, sel)
                if len(raw) != n * width * 4:
                    return None
                groups.append((blocks, raw.view("<f4")))
                continue
            raw = sub.gather(1, sel)
            if len(raw) != n * width * 4:
                return None
            cnt = raw.view("<i4").reshape(n, width)
            params = {}
            for k, p in enumerate(numbers.PARAMS):
                same = _same_rows(sub, k + 2, sel)
                if same is None or len(same) not in (0, 8 * width):
                    return None
                params[p] = np.frombuffer(same, "<f8").copy() if same else None
            dec_len = ln[sel, 7]
            if (dec_len > 0).any():
                if not (dec_len > 0).all() or params["shift"] is not None or params["divisor"] is not None:
                    return None
                try:
                    dec = wire.read_zigzag_varints(sub.gather(7, sel), n * width, "decimals")
                except ValueError:
                    return None
                if dec.min() < 0 or dec.max() > numbers.MAX_DECIMALS:
                    return None
                v = cnt / numbers.POW10[dec.reshape(n, width)]
                if params["scale"] is not None:
                    v = v * params["scale"]
                if params["offset"] is not None:
                    v = v + params["offset"]
            else:
                v = numbers.apply(cnt, params)
            groups.append((blocks, v))
    if len(groups) == 1:
        return True, groups[0][1].reshape(total, width).astype(np.float64, copy=False)
    row_block = np.repeat(np.arange(len(f64)), counts)
    for blocks, v in groups:
        out[blocks[row_block]] = v.reshape(-1, width)
    return True, out
