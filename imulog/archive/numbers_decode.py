"""Reading ``imulog.Numbers`` arrays and compact block times block by block (the per-block decoder's path; the
column decoder, :mod:`imulog.archive.block_decode`, takes the common layouts at once). Writing, and the formula
both sides share (:func:`~imulog.archive.numbers.apply`, :func:`~imulog.archive.numbers.spread`), are in
:mod:`imulog.archive.numbers`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from imulog.archive import wire
from imulog.archive.numbers import _MAX_DECIMALS, _POW10, _SKIP, PARAMS, apply, spread


def decode_times(blocks: list[Any], counts: np.ndarray, what: str) -> np.ndarray:
    """int64 times of all blocks: explicit ``t_ns`` joined, compact blocks expanded (one numpy pass)."""
    total = int(counts.sum())
    explicit = np.array([len(b.t_ns) > 0 for b in blocks], dtype=bool)
    if explicit.all() or total == 0:
        buf = bytearray().join([b.t_ns for b in blocks])
        if len(buf) != total * 8:
            raise ValueError(f"{what} t_ns: {len(buf)} bytes for {total} samples")
        return np.frombuffer(buf, dtype="<i8").astype(np.int64)
    if not explicit.any():
        rows_explicit = np.zeros(total, dtype=bool)
        out = np.empty(0, dtype=np.int64)
    else:
        rows_explicit = np.repeat(explicit, counts)
        out = np.empty(total, dtype=np.int64)
    if explicit.any():
        buf = bytearray().join([b.t_ns for b, e in zip(blocks, explicit, strict=True) if e])
        if len(buf) != int(rows_explicit.sum()) * 8:
            raise ValueError(f"{what} t_ns: {len(buf)} bytes for {int(rows_explicit.sum())} samples")
        out[rows_explicit] = np.frombuffer(buf, dtype="<i8")
    comp = ~explicit
    n = counts[comp]
    t0 = np.array([b.t0_ns for b, c in zip(blocks, comp, strict=True) if c], dtype=np.int64)
    span = np.array([b.t_span_ns for b, c in zip(blocks, comp, strict=True) if c], dtype=np.int64)
    t = spread(t0, span, n)
    has = np.array([len(b.t_residual_ns) > 0 for b, c in zip(blocks, comp, strict=True) if c], dtype=bool)
    if has.any():
        parts = [b.t_residual_ns for b, c in zip(blocks, comp, strict=True) if c and len(b.t_residual_ns)]
        res = wire.read_zigzag_varints(bytearray().join(parts), int(has.astype(np.int64) @ n), f"{what} t_residual_ns")
        if has.all():
            t += res
        else:
            t[np.repeat(has, n)] += res
    if not explicit.any():
        return t
    out[~rows_explicit] = t
    return out


# ------------------------------------------------------------------------------------------- reading


def split_counts(payload: memoryview | bytes) -> tuple[memoryview, bytes] | None:
    """(counts bytes, the rest) of a Numbers message that starts with its counts field, else None (cheap: the
    rest is the same parameters in every block of a channel, compared as bytes by :func:`numbers_sources`)."""
    mv = memoryview(payload)
    if len(mv) < 2 or mv[0] != 0x0A:
        return None
    length, pos, shift = 0, 1, 0
    while True:
        if pos >= len(mv) or shift > 63:
            return None
        b = mv[pos]
        pos += 1
        length |= (b & 0x7F) << shift
        if b < 0x80:
            break
        shift += 7
    end = pos + length
    if end > len(mv):
        return None
    return mv[pos:end], bytes(mv[end:])


def numbers_sources(payloads: list[Any]) -> list[dict[str, Any]] | None:
    """Scanned Numbers of blocks that all hold counts with the same parameters (the common case), or None."""
    first = split_counts(payloads[0]) if payloads else None
    if first is None:
        return None
    try:
        common = scan_numbers(first[1])
    except wire.Fallback:
        return None
    if len(common["counts"]) or len(common["f32"]):
        return None
    out = []
    for p in payloads:
        part = split_counts(p)
        if part is None or part[1] != first[1]:
            return None
        out.append({**common, "counts": part[0]})
    return out


def scan_numbers(payload: memoryview | bytes) -> dict[str, Any]:
    """The fields of one ``imulog.Numbers`` message (views); raises wire.Fallback on anything unexpected."""
    out: dict[str, Any] = {"counts": b"", "f32": b"", "decimals": b"", **{p: None for p in PARAMS}}
    names = {1: "counts", 2: "shift", 3: "divisor", 4: "scale", 5: "offset", 6: "f32", 7: "decimals"}
    for number, wire_type, value in wire.scan(payload):
        name = names.get(number)
        if name is None:
            continue
        if wire_type != wire.WIRE_LEN:
            raise wire.Fallback
        out[name] = value
    return out


def decode_numbers(sources: list[tuple[str, Any]], counts: np.ndarray, width: int, what: str) -> np.ndarray:
    """(N, width) float64 from each block's source: ("f64", bytes), ("q", scanned Numbers) or ("none", None)."""
    total = int(counts.sum())
    kinds = [k for k, _ in sources]
    out = np.empty((total, width), dtype=np.float64)
    # counts with per-value decimals and counts with per-column parameters are decoded apart: a channel written
    # in several appends (a live recording's flushes) can hold both, e.g. a block whose values are all integers
    groups: dict[str, list[int]] = {"f64": [], "counts": [], "decimals": [], "f32": []}
    for b, (kind, src) in enumerate(sources):
        if kind == "q":
            kind = "counts" if len(src["counts"]) or not len(src["f32"]) else "f32"
            if kind == "counts" and len(src.get("decimals") or b""):
                kind = "decimals"
        if kind in groups:
            groups[kind].append(b)
    row_block = np.repeat(np.arange(len(sources)), counts)
    if sum(len(g) for g in groups.values()) != sum(1 for k in kinds if k != "none"):
        raise ValueError(f"{what}: unknown block layout")
    covered = 0
    for kind, blocks in groups.items():
        if not blocks:
            continue
        n = int(counts[blocks].sum())
        covered += n
        if len(blocks) == len(sources):
            rows: slice | np.ndarray = slice(None)
        else:
            mask = np.zeros(len(sources), dtype=bool)
            mask[blocks] = True
            rows = mask[row_block]
        if kind == "f64":
            buf = bytearray().join([sources[b][1] for b in blocks])
            if len(buf) != n * width * 8:
                raise ValueError(f"{what}: {len(buf)} bytes for {n} samples x {width} values")
            out[rows] = np.frombuffer(buf, dtype="<f8").reshape(n, width)
        elif kind == "f32":
            buf = bytearray().join([sources[b][1]["f32"] for b in blocks])
            if len(buf) != n * width * 4:
                raise ValueError(f"{what}: {len(buf)} float32 bytes for {n} samples x {width} values")
            out[rows] = np.frombuffer(buf, dtype="<f4").reshape(n, width)
        else:
            srcs = [sources[b][1] for b in blocks]
            buf = bytearray().join([s["counts"] for s in srcs])
            if len(buf) != n * width * 4:
                raise ValueError(f"{what}: {len(buf)} count bytes for {n} samples x {width} values")
            c = np.frombuffer(buf, dtype="<i4").reshape(n, width)
            if kind == "decimals":
                dec = wire.read_zigzag_varints(
                    bytearray().join([s["decimals"] for s in srcs]), n * width, f"{what} decimals"
                )
                if dec.min() < 0 or dec.max() > _MAX_DECIMALS:
                    raise ValueError(f"{what}: decimals outside 0..{_MAX_DECIMALS}")
                v = c / _POW10[dec.reshape(n, width)]
                for p, srcs_p in (("scale", [s["scale"] for s in srcs]), ("offset", [s["offset"] for s in srcs])):
                    raw = {bytes(x) if x is not None else b"" for x in srcs_p}
                    if len(raw) != 1:
                        raise ValueError(f"{what}: {p} changes between blocks with decimals")
                    value = raw.pop()
                    if value:
                        v = v * np.frombuffer(value, "<f8") if p == "scale" else v + np.frombuffer(value, "<f8")
                out[rows] = v
                continue
            params = {}
            for p in PARAMS:
                raw = [bytes(s[p]) if s[p] is not None else b"" for s in srcs]
                if not any(raw):
                    params[p] = None
                    continue
                if any(len(r) not in (0, 8 * width) for r in raw):
                    raise ValueError(f"{what}: {p} does not have {width} values")
                if len(set(raw)) == 1:
                    params[p] = np.frombuffer(raw[0], dtype="<f8").astype(np.float64)
                    continue
                default = np.full(width, _SKIP[p]).tobytes()
                per = np.frombuffer(b"".join(r or default for r in raw), dtype="<f8").reshape(len(srcs), width)
                params[p] = np.repeat(per, counts[blocks], axis=0)
            out[rows] = apply(c, params)
    if covered != total:
        raise ValueError(f"{what}: present in some blocks only")
    return out
