"""The block codec's all-blocks-at-once encoder and decoder against the per-block ones they replaced.

The encoder must give the same bytes as the per-block encoder of commit 3ae3c3f (copied below as
``_old_encode_blocks``), and the column decoder the same arrays as the per-block decoder (still the path for
unusual layouts and few blocks), on every stream kind and storage: counts with scale, decimal text, per-value
decimals, float32, float64 with NaN gaps, explicit and compact times.
"""

from __future__ import annotations

import numpy as np
import pytest

from imulog.archive import block_decode, block_encode, codec, codec_decode, numbers, wire
from imulog.archive.block_encode import SCHEMA_VERSION, SCHEMA_VERSION_V1, block_bounds
from imulog.model import AnalogStream, ImuStream, MarkerStream, PoseStream, SignalStream

_I8 = np.dtype("<i8")
_F8 = np.dtype("<f8")


def _old_encode_blocks(t_ns: np.ndarray, layout: block_encode.Layout) -> tuple[list[int], list[bytes]]:
    """The block messages of one stream: numpy plans for the whole stream, then byte slices per block.

    Fields go out in number order without sorting: layout-1 fields (``t_ns``, float64 arrays, extras) come
    before the version-2 ones (compact times, then the ``_q`` arrays), as their numbers do.
    """
    bounds = block_bounds(t_ns)
    if not bounds:
        return [], []
    first = np.asarray([b[0] for b in bounds], dtype=np.int64)
    tp = numbers.plan_times(t_ns, bounds)
    if not layout.compact:
        tp.compact[:] = False
    plans = []
    for f64_no, q_no, values, hint in layout.arrays:
        if values is None:
            continue
        v = np.asarray(values).reshape(len(t_ns), -1)
        plan = numbers.plan_numbers(v, hint, layout.precision) if layout.compact else None
        if plan is None:
            plans.append((f64_no, v, None, None, None, None))
        else:
            ok = np.logical_and.reduceat(plan.ok, first).tolist()
            q_tag = wire.tag(q_no, wire.WIRE_LEN)
            inner_tag = b"\x0a" if plan.kind == "counts" else b"\x32"
            cum = plan.cumulative()
            edges = cum[np.append(first, len(t_ns))].tolist()  # byte offsets of the blocks in plan.data
            dec = None
            if plan.decimal_starts is not None:
                dec = plan.decimal_starts[np.append(first, len(t_ns))].tolist()
            plans.append((f64_no, v, plan, edges, ok, (q_tag, inner_tag, plan.head, dec)))
    heads = {v: wire.uint_field(1, v) + layout.head for v in (SCHEMA_VERSION_V1, SCHEMA_VERSION)}
    t0_no, span_no, resid_no = layout.time_fields
    t0_tag, span_tag = wire.tag(t0_no, wire.WIRE_VARINT), wire.tag(span_no, wire.WIRE_VARINT)
    resid_tag = wire.tag(resid_no, wire.WIRE_LEN)
    count_tag = wire.tag(layout.count, wire.WIRE_VARINT)
    varint, packed = wire.varint, wire.packed
    compact, has_resid = tp.compact.tolist(), tp.has_resid.tolist()
    t0s, spans = tp.t0.tolist(), tp.span.tolist()
    rstarts = tp.resid_starts[np.append(first, len(t_ns))].tolist()  # residual bytes of each block
    payloads = []
    for b, (i, j) in enumerate(bounds):
        low: list[bytes] = [count_tag + varint(j - i)]
        high: list[bytes] = []
        if compact[b]:
            t0, span = t0s[b], spans[b]
            if t0:
                high.append(t0_tag + varint((t0 << 1) ^ (t0 >> 63)))
            if span:
                high.append(span_tag + varint((span << 1) ^ (span >> 63)))
            if has_resid[b]:
                body = tp.resid[rstarts[b] : rstarts[b + 1]]
                high.append(resid_tag + varint(len(body)) + body)
        else:
            low.append(packed(layout.t_field, t_ns[i:j], _I8))
        for f64_no, v, plan, cum, ok, tags in plans:
            if plan is not None and ok[b]:
                body = plan.data[cum[b] : cum[b + 1]]
                inner = tags[1] + varint(len(body)) + body + tags[2] if body else b""
                if tags[3] is not None:  # per-value decimals, field 7
                    d = plan.decimals[tags[3][b] : tags[3][b + 1]]
                    inner += b"\x3a" + varint(len(d)) + d
                high.append(tags[0] + varint(len(inner)) + inner)
            else:
                low.append(packed(f64_no, v[i:j], _F8))
        for number, a, dtype in layout.extra:
            low.append(packed(number, a[i:j], dtype))
        head = heads[SCHEMA_VERSION if high else SCHEMA_VERSION_V1]
        payloads.append(b"".join([head, *low, *high]))
    return first.tolist(), payloads


def _streams() -> list:
    rng = np.random.default_rng(3)
    n = 2500
    t = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 10_000_000
    jitter = t + rng.integers(-20_000, 20_000, n)  # a device clock's rounding: compact with residuals
    gappy = t.copy()
    gappy[1200:] += 3_000_000_000  # a gap
    counts = rng.integers(-2000, 2000, (n, 3)).astype(np.float64) / 256.0 * 9.81
    acc_hint = {"resolution": {"acc": {"scale": 9.81 / 256.0}}}
    dec = np.round(rng.normal(0, 1, (n, 3)), 4)
    g6 = np.array([float(f"{x:.6g}") for x in rng.normal(0, 50, n * 3)]).reshape(n, 3)
    f64 = rng.normal(0, 1, (n, 3))
    f64[300:320] = np.nan
    f64[1700] = np.nan
    pos = np.round(rng.normal(0, 1, (n, 4, 3)), 5)
    pos[500:900, 1] = np.nan
    valid = np.isfinite(pos).all(axis=2)
    q = rng.normal(0, 1, (n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return [
        ImuStream(
            "a", jitter, acc=counts, gyr=dec, mag=g6, temperature=np.round(rng.normal(25, 1, n), 2), meta=acc_hint
        ),
        ImuStream("b", t, acc=f64, gyr=f64.astype(np.float32).astype(np.float64), meta={"precision": "float32"}),
        ImuStream("c", gappy, acc=f64),
        MarkerStream("m", t, ["A", "B", "", "D"], pos, valid),
        AnalogStream("an", jitter, ["x", "y", "z"], ["V", "V", "V"], g6, {}),
        SignalStream("/derived/s", gappy, ["u", "v", "w"], ["1", "1", "1"], dec, "world", {"precision": "float32"}),
        PoseStream("/derived/p", t, dec, q, "world"),
    ]


@pytest.mark.parametrize("compact", [True, False])
@pytest.mark.parametrize("k", range(7))
def test_encoder_bytes_equal_the_per_block_encoder(monkeypatch, k: int, compact: bool):
    stream = _streams()[k]
    new = codec.encode(stream, compact=compact)
    monkeypatch.setattr(codec, "encode_blocks", _old_encode_blocks)
    old = codec.encode(stream, compact=compact)
    assert new[2] == old[2]
    assert len(new[3]) == len(old[3]) > 8
    assert new[3] == old[3]
    cls = codec.MESSAGE_CLASSES[new[0]]
    for payload in new[3][:3] + new[3][-3:]:  # and what protobuf's own serializer writes for the message
        assert cls.FromString(payload).SerializeToString(deterministic=True) == payload


def _same(a, b) -> None:
    assert type(a) is type(b)
    for f, v in vars(a).items():
        w = getattr(b, f)
        if isinstance(v, np.ndarray):
            assert v.dtype == w.dtype and v.shape == w.shape and v.tobytes() == w.tobytes(), f
        else:
            assert v == w, f


@pytest.mark.parametrize("compact", [True, False])
@pytest.mark.parametrize("k", range(7))
def test_column_decoder_equals_the_per_block_decoder(monkeypatch, k: int, compact: bool):
    stream = _streams()[k]
    schema, meta, _, payloads = codec.encode(stream, compact=compact)
    calls = []
    columns = block_decode.columns
    monkeypatch.setattr(block_decode, "columns", lambda *a: calls.append(1) or columns(*a))
    fast = codec.decode(schema, stream.topic, meta, payloads)
    assert calls
    monkeypatch.setattr(block_decode, "MIN_BLOCKS", 10**9)
    slow = codec.decode(schema, stream.topic, meta, payloads)
    _same(fast, slow)
    assert np.array_equal(fast.t_ns, stream.t_ns)


def test_column_decoder_leaves_unusual_blocks_to_the_per_block_path():
    """Labels that change between blocks: the column scan declines, the per-block path names the problem."""
    stream = _streams()[3]
    schema, meta, _, payloads = codec.encode(stream)
    other = codec.encode(MarkerStream("m", stream.t_ns, ["A", "B", "C", "D"], stream.pos, stream.valid))[3]
    spec = codec_decode._BLOCK_SPECS[schema][0]
    assert block_decode.columns(payloads, spec) is not None
    mixed = payloads[:10] + other[10:]
    assert block_decode.columns(mixed, spec) is None
    with pytest.raises(codec.DecodeError, match="labels change"):
        codec.decode(schema, "/m", meta, mixed)


def test_scan_many_rejects_truncated_messages():
    from imulog.archive.wire_kernels import BAD_WIRE, scan_many

    payload = codec.encode(_streams()[0])[3][0]
    pool = np.frombuffer(payload[:-1], np.uint8)
    status = scan_many(pool, np.array([0]), np.array([len(pool)]), 20, np.zeros(20, np.bool_))[0]
    assert status == BAD_WIRE


def test_compiled_counts_and_varints_equal_the_numpy_passes():
    """Large arrays take the compiled exactness check and zigzag encoder: the same counts, rows and bytes."""
    rng = np.random.default_rng(5)
    counts = rng.integers(-40000, 40000, (70000, 3)).astype(np.float64)
    params = numbers._params({"shift": [0.5, 0, 2], "divisor": 4096.0, "scale": 9.80665, "offset": [0, 0.1, 0]}, 3)
    v = numbers.apply(counts, params)
    v[10] = np.nan
    v[20, 1] += 1e-9  # not a count
    v[30, 2] = 3e10  # beyond sfixed32
    fast = numbers._counted(v, params)
    slow = numbers._from_counts(v, numbers._counts_of(v, params), params)
    assert fast.data == slow.data and np.array_equal(fast.ok, slow.ok) and fast.head == slow.head
    assert not fast.ok[[10, 20, 30]].any() and fast.ok.sum() == len(v) - 3
    r = rng.integers(-(2**40), 2**40, 70000) >> rng.integers(0, 40, 70000)
    data, lengths = wire.zigzag_varints(r)
    assert np.array_equal(wire.read_zigzag_varints(data, len(r), "r"), r)
    small = [wire.zigzag_varints(r[k : k + 1000]) for k in range(0, len(r), 1000)]
    assert data == b"".join(d for d, _ in small)
    assert np.array_equal(lengths, np.concatenate([ln for _, ln in small]))
    # derived channels on a requested grid (precision "quantized"): the compiled rounding gives the numpy one's
    # counts and rows, piece by piece below the threshold; a NaN row and a row beyond sfixed32 stay float64
    q = rng.normal(0.0, 1.0, (70000, 4))
    q[10, 2], q[30, 0] = np.nan, 2.0**14  # 2**32 quanta of 2**-18
    hint = numbers.quantum_hint({"precision": "quantized", "quantum": repr(2.0**-18)})
    whole = numbers.plan_numbers(q, hint, "quantized")
    parts = [numbers.plan_numbers(q[k : k + 1000], hint, "quantized") for k in range(0, len(q), 1000)]
    assert whole.data == b"".join(p.data for p in parts) and whole.head == parts[0].head
    assert np.array_equal(whole.ok, np.concatenate([p.ok for p in parts]))
    assert not whole.ok[[10, 30]].any() and whole.ok.sum() == len(q) - 2
    back = numbers.apply(np.frombuffer(whole.data, "<i4").reshape(-1, 4), whole.params)
    assert np.abs(back - q)[whole.ok].max() <= 2.0**-19
    # decoding: int32 counts take the compiled formula, the same float64 bits as the numpy passes (float counts)
    c32 = counts.astype(np.int32)
    for some in (params, {"divisor": params["divisor"], "scale": params["scale"]}, {}):
        assert np.array_equal(numbers.apply(c32, some), numbers.apply(counts, some))
        assert np.array_equal(numbers.apply(c32[:5], some), numbers.apply(counts[:5], some))  # short: numpy


def test_large_stream_bytes_equal_the_per_block_encoder(monkeypatch):
    """70,000 samples: the compiled counts check and residual varints, through both encoders."""
    rng = np.random.default_rng(8)
    n = 70_000
    t = 1_000_000_000 + np.arange(n, dtype=np.int64) * 10_000_000 + rng.integers(-20_000, 20_000, n)
    acc = rng.integers(-2000, 2000, (n, 3)).astype(np.float64) / 256.0 * 9.81
    acc[5000:5100] = np.nan
    imu = ImuStream(
        "big",
        t,
        acc=acc,
        gyr=np.round(rng.normal(0, 1, (n, 3)), 4),
        meta={"resolution": {"acc": {"scale": 9.81 / 256}}},
    )
    new = codec.encode(imu)
    monkeypatch.setattr(codec, "encode_blocks", _old_encode_blocks)
    assert new[3] == codec.encode(imu)[3]
    assert np.array_equal(codec.decode(new[0], "/imu/big", new[1], new[3]).acc, acc, equal_nan=True)


@pytest.mark.parametrize("column_decoder", [True, False])
def test_blocks_with_and_without_per_value_decimals_decode_together(monkeypatch, column_decoder: bool):
    """A channel appended in pieces (a live recording's flushes) is planned piece by piece: a piece of
    values as text with varying decimals (``%.7g``: 123456.5 beside 0.0012345) needs per-value decimals, a piece of whole numbers
    does not; together they decode exactly."""
    if not column_decoder:
        monkeypatch.setattr(block_decode, "MIN_BLOCKS", 10**9)
    pieces = [np.array([[123456.5, 1.0], [1.234567, 2.0], [0.0012345, 3.0]]), np.array([[3.0, -1.0], [4.0, -1.0]])]
    t0, payloads, schema, meta = 0, [], None, None
    for values in pieces:
        t_ns = t0 + np.arange(len(values), dtype=np.int64) * 5_000_000
        t0 = int(t_ns[-1]) + 5_000_000
        schema, meta, _, blocks = codec.encode(SignalStream("/s", t_ns, ["a", "b"], ["mV", "mV"], values))
        payloads += blocks
    assert numbers.plan_numbers(pieces[0], None).decimals and not numbers.plan_numbers(pieces[1], None).decimals
    assert all(codec.MESSAGE_CLASSES[schema].FromString(p).HasField("values_q") for p in payloads)
    got = codec.decode(schema, "/s", meta, payloads)
    np.testing.assert_array_equal(got.values, np.concatenate(pieces))


@pytest.mark.parametrize("column_decoder", [True, False])
def test_blocks_with_different_scales_decode_together(monkeypatch, column_decoder: bool):
    """A channel converted in pieces is planned piece by piece: pieces whose counts have different scales give
    per-row parameters; with more than 4096 counts (the compiled formula's threshold) they decode exactly, as the
    numpy formula does (they failed in numba's typing: a per-row scale is 2-D)."""
    if not column_decoder:
        monkeypatch.setattr(block_decode, "MIN_BLOCKS", 10**9)
    rng = np.random.default_rng(11)
    scales = (9.81 / 256, 9.81 / 4096, 0.01)
    pieces = [rng.integers(-3000, 3000, (3000, 3)) * s for s in scales]
    t0, payloads, schema, meta = 0, [], None, None
    for k, values in enumerate(pieces):
        t_ns = t0 + np.arange(len(values), dtype=np.int64) * 10_000_000
        t0 = int(t_ns[-1]) + 10_000_000
        imu = ImuStream("big", t_ns, acc=values, meta={"resolution": {"acc": {"scale": scales[k]}}})
        schema, meta, _, blocks = codec.encode(imu)
        payloads += blocks
    got = codec.decode(schema, "/imu/big", meta, payloads)
    np.testing.assert_array_equal(got.acc, np.concatenate(pieces))
    counts = rng.integers(-3000, 3000, (5000, 3))
    per_row = {"scale": np.repeat(np.array([[0.5, 0.25, 2.0], [0.1, 0.2, 0.3]]), [2500, 2500], axis=0), "offset": None}
    assert np.array_equal(numbers.apply(counts.astype(np.int32), per_row), numbers.apply(counts.astype(float), per_row))
