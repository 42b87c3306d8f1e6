"""Block arrays at their source's resolution (``imulog.Numbers``) and block times as start plus span (issue 28).

Writing, for a whole stream at once (numpy, no per-sample Python):

- :func:`plan_numbers` picks how an (N, C) float64 array is stored: integer counts (sfixed32) with per-column
  ``shift``, ``divisor``, ``scale``, ``offset`` (from the converter's ``resolution`` hint, or decimal text found
  in the numbers: ``counts / 10**k``), float32 when every value is a float32 (or the stream asks for float32:
  derived channels whose accuracy is far coarser), counts on a grid the stream asks for (``precision:
  quantized`` with its ``quantum``: values rounded to a step far below their accuracy, :func:`quantum_hint`),
  else None (the float64 field, as before). Counts are kept
  only where they give every value back exactly (compared as numbers: ``-0.0`` reads as ``0.0``); a block with
  a row that does not (a NaN gap) keeps float64.
- :func:`plan_times` gives each block its start and span when the times are evenly spread, with residuals
  where they are not, and keeps explicit times when that is not smaller.

Reading joins the fields of all blocks and decodes them with one numpy pass each
(:mod:`imulog.archive.numbers_decode`; large int32 counts through :func:`apply`'s compiled pass). The formula a generic reader applies is in ``schemas/imulog/Numbers.proto`` and
docs/schemas.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imulog.archive import wire

PARAMS = ("shift", "divisor", "scale", "offset")
_SKIP = {"shift": 0.0, "divisor": 1.0, "scale": 1.0, "offset": 0.0}  # a parameter with these values is left out
_MAX_DECIMALS = 15  # %.7g of EMG in V near 1e-7 has 13 decimals; 10**15 is an exact double
_EXACT_INT = 2.0**53
_MAX_COUNT = 2.0**31  # counts are sfixed32
_RESID_BYTES = 4  # residual varints longer than this make a block's times explicit (|r| >= 2**27 ns)
_COMPILED_SIZE = 65536  # values from which apply and _counted use the compiled loops (wire_kernels)


def apply(counts: np.ndarray, params: dict[str, np.ndarray | None]) -> np.ndarray:
    """float64 values of (N, C) counts: ``((counts + shift) / divisor) * scale + offset``, absent steps skipped.

    Large int32 arrays (the decoder's) take one compiled pass (:func:`imulog.archive.wire_kernels.apply_counts`,
    bit-identical) instead of a numpy pass per parameter, when every parameter is one value per column; per-row
    parameters ((N, C): blocks planned apart, e.g. a file converted in pieces) take the numpy passes."""
    per_column = all(p is None or np.ndim(p) <= 1 for p in params.values())
    if counts.dtype == np.int32 and counts.ndim == 2 and counts.size >= 4096 and per_column:
        from imulog.archive.wire_kernels import apply_counts

        return apply_counts(np.ascontiguousarray(counts), *_param_arrays(params, counts.shape[1]))
    v = counts.astype(np.float64)
    if params.get("shift") is not None:
        v += params["shift"]
    if params.get("divisor") is not None:
        v /= params["divisor"]
    if params.get("scale") is not None:
        v *= params["scale"]
    if params.get("offset") is not None:
        v += params["offset"]
    return v


def _params(hint: dict[str, Any], width: int) -> dict[str, np.ndarray | None]:
    out: dict[str, np.ndarray | None] = {}
    for p in PARAMS:
        value = hint.get(p)
        if value is None:
            out[p] = None
            continue
        a = np.broadcast_to(np.asarray(value, dtype=np.float64).reshape(-1), (width,)).copy()
        out[p] = None if bool(np.all(a == _SKIP[p])) else a
    return out


def _params_head(params: dict[str, np.ndarray | None]) -> bytes:
    """The parameter fields (shift, divisor, scale, offset: packed doubles) that every block of a plan repeats."""
    return b"".join(
        wire.packed(k + 2, params[p], np.dtype("<f8")) for k, p in enumerate(PARAMS) if params.get(p) is not None
    )


@dataclass
class NumbersPlan:
    """How one (N, C) array is stored: ``kind`` "counts" or "f32"; ``ok`` rows that the encoding gives back."""

    kind: str
    width: int
    ok: np.ndarray
    data: bytes = b""  # counts: the varints of every row (rows not ok as 0); f32: the float32 bytes
    row_bytes: np.ndarray | None = None  # bytes of each row in ``data``
    params: dict[str, np.ndarray | None] = field(default_factory=dict)
    head: bytes = b""  # the parameter fields, the same in every block
    decimals: bytes = b""  # per-value decimals (varints), when the text's numbers have varying decimals
    decimal_starts: np.ndarray | None = None  # byte offset of each row's decimals, N + 1

    def cumulative(self) -> np.ndarray:
        """Byte offset of each row's start in ``data`` (N + 1 entries)."""
        assert self.row_bytes is not None
        return np.concatenate([[0], np.cumsum(self.row_bytes)])


def _counted(values: np.ndarray, params: dict[str, np.ndarray | None]) -> NumbersPlan:
    """:func:`_from_counts` of :func:`_counts_of`: compiled in one pass for large arrays (same values)."""
    if values.size < _COMPILED_SIZE:
        return _from_counts(values, _counts_of(values, params), params)
    from imulog.archive.wire_kernels import counts_check

    width = values.shape[1]
    counts, ok = counts_check(np.require(values, np.float64, ["C", "W"]), *_param_arrays(params, width))
    head = _params_head(params)
    return NumbersPlan(
        "counts", width, ok, counts.astype("<i4").tobytes(), np.full(len(values), 4 * width), params, head
    )


def _from_counts(values: np.ndarray, counts: np.ndarray, params: dict[str, np.ndarray | None]) -> NumbersPlan:
    """The plan for ``counts`` (float64, whole numbers or not): each value kept where the formula gives it back."""
    eq = apply(counts, params) == values  # NaN never equals: a gap row keeps float64
    ok = eq.all(axis=1)
    counts[~eq] = 0
    data = counts.astype("<i4").tobytes()  # |counts| < 2**31 (checked by _counts_of): one pass, no varints
    head = _params_head(params)
    width = values.shape[1]
    return NumbersPlan("counts", width, ok, data, np.full(len(values), 4 * width), params, head)


def _counts_of(values: np.ndarray, params: dict[str, np.ndarray | None], clip: bool = True) -> np.ndarray:
    """Whole numbers (float64) that the parameters map to ``values``: the inverse formula, rounded; values
    out of the exact integer range become 0 (and then fail the check; ``clip=False``: left as they are)."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        c = values - params["offset"] if params.get("offset") is not None else values.copy()
        if params.get("scale") is not None:
            c /= params["scale"]
        if params.get("divisor") is not None:
            c *= params["divisor"]
        if params.get("shift") is not None:
            c -= params["shift"]
        np.rint(c, out=c)
        if clip:
            c[~(np.abs(c) < _MAX_COUNT)] = 0  # NaN, inf and beyond sfixed32
    return c


def _param_arrays(params: dict[str, np.ndarray | None], width: int) -> list[np.ndarray]:
    """The compiled kernels' arguments: the 4 parameters as (width,) float64 (zeros when absent), then ``use``."""
    arrays = [
        np.require(params[p] if params.get(p) is not None else np.zeros(width), np.float64, ["C", "W"]) for p in PARAMS
    ]
    return [*arrays, np.array([params.get(p) is not None for p in PARAMS])]


def _decimals(values: np.ndarray) -> np.ndarray | None:
    """Per column the fewest decimals k <= 15 with ``rint(v * 10**k) / 10**k == v`` on a sample, or None."""
    sample = values[: min(len(values), 4096)]
    ks = []
    for col in sample.T:
        col = col[np.isfinite(col)]
        if not len(col):
            ks.append(0)
            continue
        for k in range(_MAX_DECIMALS + 1):
            d = 10.0**k
            if np.max(np.abs(col)) * d >= _MAX_COUNT:
                return None
            if np.array_equal(np.rint(col * d) / d, col):
                ks.append(k)
                break
        else:
            return None
    return np.asarray(ks)


_POW10 = 10.0 ** np.arange(_MAX_DECIMALS + 1)
POW10, MAX_DECIMALS = _POW10, _MAX_DECIMALS  # for imulog.archive.block_decode


def _value_decimals(v: np.ndarray, scale: np.ndarray | None = None) -> NumbersPlan | None:
    """Counts with each value's own decimals (``counts / 10**k``, k <= 15, then ``* scale`` per column when the
    converter multiplied the text by a unit factor): text such as ``%.6g``."""
    k = np.full(v.shape, -1, dtype=np.int8)
    counts = np.zeros(v.shape)
    text = v if scale is None else v / scale
    with np.errstate(invalid="ignore", over="ignore"):
        for d in range(_MAX_DECIMALS + 1):
            todo = k < 0
            if not todo.any():
                break
            c = np.rint(text[todo] * _POW10[d])
            back = c / _POW10[d]
            if scale is not None:
                back *= np.broadcast_to(scale, v.shape)[todo]
            hit = (np.abs(c) < _MAX_COUNT) & (back == v[todo])
            idx = np.flatnonzero(todo.reshape(-1))[hit]
            k.reshape(-1)[idx] = d
            counts.reshape(-1)[idx] = c[hit]
    eq = k >= 0
    ok = eq.all(axis=1)
    if ok.mean() <= 0.5:
        return None
    k[~eq] = 0
    width = v.shape[1]
    dec, lengths = wire.zigzag_varints(k.astype(np.int64))
    plan = NumbersPlan("counts", width, ok, counts.astype("<i4").tobytes(), np.full(len(v), 4 * width))
    if scale is not None:
        plan.params = {"scale": scale}
        plan.head = wire.packed(4, scale, np.dtype("<f8"))
    plan.decimals = dec
    plan.decimal_starts = np.concatenate([[0], np.cumsum(lengths.reshape(-1, width).sum(axis=1))])
    return plan


def plan_numbers(values: np.ndarray | None, hint: dict[str, Any] | None, precision: str = "") -> NumbersPlan | None:
    """How to store ``values`` (N, C) or (N,) float64; None: as float64 (the field of schema_version 1)."""
    if values is None or len(values) == 0:
        return None
    v = np.asarray(values, dtype=np.float64)
    v = v.reshape(len(v), -1)
    width = v.shape[1]
    if precision == "float32":
        f = v.astype("<f4")
        return NumbersPlan("f32", width, np.ones(len(v), dtype=bool), f.tobytes(), np.full(len(v), 4 * width))
    if precision == "quantized" and hint:  # counts on the requested grid: rounded, by request (see quantum_hint)
        params = _params(hint, width)
        if v.size >= _COMPILED_SIZE:  # one compiled pass, the same counts (wire_kernels.quantize_counts)
            from imulog.archive.wire_kernels import quantize_counts

            counts, ok = quantize_counts(np.require(v, np.float64, ["C"]), *_param_arrays(params, width))
        else:
            counts = _counts_of(v, params, clip=False)
            with np.errstate(invalid="ignore"):
                ok = (np.abs(counts) < _MAX_COUNT).all(axis=1)
            counts[~ok] = 0  # a NaN gap row (or one beyond the counts' range) keeps float64
        head = _params_head(params)
        return NumbersPlan(
            "counts", width, ok, counts.astype("<i4").tobytes(), np.full(len(v), 4 * width), params, head
        )
    candidates: list[dict[str, np.ndarray | None]] = []
    if hint:
        candidates.append(_params(hint, width))
        plan = _counted(v, candidates[0])
        if plan.ok.mean() > 0.5:
            return plan
    ks = _decimals(v)  # only when the converter's hint does not fit: the text's decimals
    if ks is not None:
        params = _params({"divisor": 10.0 ** ks.astype(np.float64)}, width)
        plan = _counted(v, params)
        if plan.ok.mean() > 0.5:
            return plan
    f = v.astype("<f4")
    ok = np.all(f.astype(np.float64) == v, axis=1)
    if ok.mean() > 0.5:
        return NumbersPlan("f32", width, ok, f.tobytes(), np.full(len(v), 4 * width))
    scale = candidates[0].get("scale") if hint and len(candidates) else None
    only_scale = scale is not None and all(candidates[0].get(p) is None for p in ("shift", "divisor", "offset"))
    if only_scale:  # text times a unit factor: the text's decimals, then the factor
        text = v / scale
        ks = _decimals(text)
        if ks is not None:
            params = _params({"divisor": 10.0 ** ks.astype(np.float64), "scale": scale}, width)
            plan = _counted(v, params)
            if plan.ok.mean() > 0.5:
                return plan
    return _value_decimals(v, scale if only_scale else None)


def numbers_field(number: int, plan: NumbersPlan, starts: np.ndarray, i: int, j: int) -> bytes:
    """The ``Numbers`` sub-message field of rows [i, j) (``starts``: :meth:`NumbersPlan.cumulative`)."""
    body = plan.data[int(starts[i]) : int(starts[j])]
    # fields in number order, as protobuf writes them: counts 1, parameters 2-5; or f32 6
    inner = wire.len_field(1, body) + plan.head if plan.kind == "counts" else wire.len_field(6, body)
    return wire.tag(number, wire.WIRE_LEN) + wire.varint(len(inner)) + inner


# --------------------------------------------------------------------------------------------- times


@dataclass
class TimesPlan:
    """Per block: compact (start, span, residual bytes) or explicit ``t_ns``."""

    compact: np.ndarray  # (blocks,) bool
    t0: np.ndarray
    span: np.ndarray
    resid: bytes
    resid_starts: np.ndarray  # byte offset of each sample's residual, N + 1
    has_resid: np.ndarray  # (blocks,) bool


def predicted(t0: np.ndarray, span: np.ndarray, k: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Times spread evenly: ``t0 + (2 k span + n - 1) // (2 (n - 1))`` (``t0`` for one-sample blocks)."""
    den = np.maximum(n - 1, 1)
    return t0 + (2 * k * span + den) // (2 * den)


def spread(t0: np.ndarray, span: np.ndarray, n: np.ndarray) -> np.ndarray:
    """:func:`predicted` times of whole blocks, concatenated: a padded (blocks, max n) grid, no per-sample repeat."""
    if not len(n):
        return np.zeros(0, dtype=np.int64)
    k = np.arange(int(n.max()), dtype=np.int64)[None, :]
    grid = predicted(t0[:, None], span[:, None], k, n[:, None])
    return grid[k < n[:, None]] if bool((n != n.max()).any()) else grid.reshape(-1)


def plan_times(t_ns: np.ndarray, bounds: list[tuple[int, int]]) -> TimesPlan:
    """Which blocks store start + span instead of explicit sfixed64 times.

    A block is compact when its times are the span spread evenly, or differ from that by less than 2**27 ns
    (about 134 ms) each: residuals of at most 4 bytes, half the 8 of an explicit time, and the smooth
    residuals of a device clock compress far better than explicit times (an Axivity block clock's 1/65536 s
    steps give residuals up to about 12 us; skdh's .cwa time rule steps 9.75 / 10 / 10.25 ms, up to 6 ms off
    a 1-s block's line: explicit, a converted .cwa was 1.5x larger). Larger jitter or a longer gap inside a
    block keeps explicit times.
    """
    i = np.asarray([b[0] for b in bounds], dtype=np.int64)
    j = np.asarray([b[1] for b in bounds], dtype=np.int64)
    n = j - i
    t = np.asarray(t_ns, dtype=np.int64)
    t0, span = t[i], t[j - 1] - t[i]
    resid = t - spread(t0, span, n)
    data, lengths = wire.zigzag_varints(resid)
    nonzero = np.add.reduceat(resid != 0, i) > 0
    small = np.add.reduceat(lengths > _RESID_BYTES, i) == 0  # |r| < 2**27 ns: a device clock's jitter
    compact = (~nonzero) | small
    return TimesPlan(compact, t0, span, data, np.concatenate([[0], np.cumsum(lengths)]), nonzero)


def signal_hint(attrs: dict[str, Any]) -> dict[str, Any] | None:
    """The ``values`` hint of a SignalStream: its grid (:func:`quantum_hint`), else a converter's ``resolution``
    attribute (JSON ``{"values": {"scale": [...], ...}}``, e.g. GENEActiv light ``counts * lux / volts``), else None."""
    grid = quantum_hint(attrs)
    if grid is not None:
        return grid
    res = attrs.get("resolution")
    if not res:
        return None
    hint = json.loads(res) if isinstance(res, str) else res
    values = hint.get("values") if isinstance(hint, dict) else None
    return values if isinstance(values, dict) else None


def quantum_hint(attrs: dict[str, Any]) -> dict[str, float] | None:
    """The ``values`` hint of a derived stream that asks for ``precision: quantized``: ``{"scale": quantum}`` (its
    ``quantum`` attribute, the grid step in the channel's units); None when it asks for no grid."""
    if attrs.get("precision") != "quantized":
        return None
    quantum = float(attrs.get("quantum", "nan"))
    if not (np.isfinite(quantum) and quantum > 0):
        raise ValueError(f"precision quantized needs a positive quantum, got {attrs.get('quantum')!r}")
    return {"scale": quantum}
