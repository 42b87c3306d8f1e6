"""Block codec throughput: encode and decode of a simulated home recording, against the previous codec and a peer.

    python benchmarks/bench_codec.py                  # 0.1 day of simulated AX6 data (864,000 samples)
    python benchmarks/bench_codec.py --days 1         # a whole day (8.64 M samples)

Data: ``imulog simulate home --days D`` (100 Hz Axivity AX6 ``.cwa``) converted with ``imulog convert``; the
benchmark reads the IMU channel back (integer counts with their scale, compact times) and makes a derived
float32 channel of the same length (a quaternion, as ``process orientation`` writes). Sides, in one process,
interleaved, best of ``--repeat``:

* new: :func:`imulog.archive.codec.encode` / :func:`~imulog.archive.codec.decode` (all blocks of the stream at
  once, numba scan / gather / assemble);
* previous: the per-block encoder of commit 3ae3c3f (loaded from ``git show``; same bytes, checked) and the
  per-block decoder (still in the code as the fallback path);
* float64: the codec before issue 28 (schema_version 1: float64 arrays, explicit times), per-block encoder;
* peer: the same arrays as 1-s blocks built and serialized with protobuf's own C++ (upb) message classes
  (``ImuBlock(t_ns=..., acc=...)``, ``SerializeToString``) and parsed back (``FromString`` + numpy), plus the
  ``mcap`` library writing and reading those messages in memory.

Throughput is samples per second (the derived channel's samples count too). The machine's load average is
printed with the figures.
"""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_archive import load_average

from imulog.archive import TrialReader, block_decode, codec
from imulog.model import SignalStream

OLD_COMMIT = "3ae3c3f"


def old_encode_blocks():
    """The per-block ``_encode_blocks`` of commit 3ae3c3f, executed from ``git show`` (the previous encoder)."""
    from imulog.archive import block_encode, numbers, wire

    root = Path(__file__).resolve().parent.parent
    src = subprocess.run(
        ["git", "show", f"{OLD_COMMIT}:imulog/archive/codec.py"], cwd=root, capture_output=True, text=True, check=True
    ).stdout
    body = src[src.index("def _encode_blocks(") : src.index("def _strings(")]
    ns = {
        "np": np,
        "numbers": numbers,
        "wire": wire,
        "block_bounds": block_encode.block_bounds,
        "SCHEMA_VERSION": codec.SCHEMA_VERSION,
        "SCHEMA_VERSION_V1": codec.SCHEMA_VERSION_V1,
        "_I8": np.dtype("<i8"),
        "_F8": np.dtype("<f8"),
        "_U1": np.dtype("u1"),
        "_Layout": block_encode.Layout,
        "Any": object,
    }
    exec(compile("from __future__ import annotations\n" + body, f"{OLD_COMMIT}:codec.py", "exec"), ns)
    return ns["_encode_blocks"]


def encode_with(encoder, streams, compact=True):
    saved = codec.encode_blocks
    codec.encode_blocks = encoder
    try:
        return [codec.encode(s, compact=compact) for s in streams]
    finally:
        codec.encode_blocks = saved


def decode_all(encoded, topics, per_block=False):
    saved = block_decode.MIN_BLOCKS
    if per_block:
        block_decode.MIN_BLOCKS = 10**12
    try:
        return [codec.decode(e[0], t, e[1], e[3]) for e, t in zip(encoded, topics, strict=True)]
    finally:
        block_decode.MIN_BLOCKS = saved


def _blocks(t_ns):
    return codec.block_bounds(t_ns)


def peer_encode(imu, sig):
    """1-s blocks as upb messages (float64 arrays, explicit times), serialized, then written with `mcap`."""
    from mcap.writer import Writer

    imu_cls, sig_cls = codec.MESSAGE_CLASSES["imulog.ImuBlock"], codec.MESSAGE_CLASSES["imulog.SignalBlock"]
    out = []
    for i, j in _blocks(imu.t_ns):
        m = imu_cls(schema_version=1, sensor=imu.name, count=j - i, t_ns=imu.t_ns[i:j], acc=imu.acc[i:j].ravel())
        for f in ("gyr", "mag", "temperature"):
            if getattr(imu, f) is not None:
                getattr(m, f).extend(getattr(imu, f)[i:j].ravel())
        out.append(m.SerializeToString())
    for i, j in _blocks(sig.t_ns):
        m = sig_cls(schema_version=1, count=j - i, t_ns=sig.t_ns[i:j], values=sig.values[i:j].ravel())
        out.append(m.SerializeToString())
    buf = io.BytesIO()
    w = Writer(buf)
    w.start()
    sid = w.register_schema("imulog.ImuBlock", "protobuf", codec.file_descriptor_set("imulog.ImuBlock"))
    cid = w.register_channel("/peer", "protobuf", sid)
    for k, payload in enumerate(out):
        w.add_message(cid, log_time=k, data=payload, publish_time=k)
    w.finish()
    return out, buf.getvalue()


def peer_decode(payloads, n_imu_blocks, file_bytes):
    """`mcap` reads the messages back, upb parses them, numpy joins the repeated fields."""
    from mcap.reader import make_reader

    list(make_reader(io.BytesIO(file_bytes)).iter_messages())
    imu_cls, sig_cls = codec.MESSAGE_CLASSES["imulog.ImuBlock"], codec.MESSAGE_CLASSES["imulog.SignalBlock"]
    t, acc, gyr, vals = [], [], [], []
    for k, p in enumerate(payloads):
        if k < n_imu_blocks:
            m = imu_cls.FromString(p)
            t.append(np.asarray(m.t_ns, dtype=np.int64))
            acc.append(np.asarray(m.acc, dtype=np.float64))
            gyr.append(np.asarray(m.gyr, dtype=np.float64))
        else:
            m = sig_cls.FromString(p)
            vals.append(np.asarray(m.values, dtype=np.float64))
    return np.concatenate(t), np.concatenate(acc).reshape(-1, 3), np.concatenate(vals).reshape(-1, 4)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--days", type=float, default=0.1, help="days of simulated 100 Hz AX6 data (default 0.1)")
    ap.add_argument("--repeat", type=int, default=3, help="repetitions; the best time of each side is reported")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp_p = Path(tmp)
        run = [sys.executable, "-m", "imulog"]
        subprocess.run([*run, "simulate", "home", "--days", str(args.days), "-o", tmp], check=True, capture_output=True)
        cwa = next(tmp_p.glob("*.cwa"))
        subprocess.run([*run, "convert", str(cwa), "-o", str(tmp_p / "t.mcap")], check=True, capture_output=True)
        with TrialReader(tmp_p / "t.mcap") as tr:
            topic = next(c.topic for c in tr.channels if c.topic.startswith("/imu/"))
            imu = tr.read(topic)
    n = len(imu.t_ns)
    rng = np.random.default_rng(0)
    q = rng.normal(0, 1, (n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    sig = SignalStream("/derived/orientation/x", imu.t_ns, ["qw", "qx", "qy", "qz"], ["1"] * 4, q)
    sig.attrs["precision"] = "float32"
    streams, topics = [imu, sig], [topic, sig.topic]
    samples = 2 * n
    old = old_encode_blocks()
    new_enc = encode_with(codec.encode_blocks, streams)
    assert all(a[3] == b[3] for a, b in zip(new_enc, encode_with(old, streams), strict=True)), "bytes differ"
    f64_enc = encode_with(old, streams, compact=False)
    decode_all(new_enc, topics)  # compile / load the numba kernels outside the timings
    best: dict[str, float] = {}

    def clock(name, fn):
        t0 = time.perf_counter()
        out = fn()
        best[name] = min(best.get(name, np.inf), time.perf_counter() - t0)
        return out

    load_before = load_average()
    for _ in range(args.repeat):
        clock("encode new", lambda: encode_with(codec.encode_blocks, streams))
        clock("encode previous", lambda: encode_with(old, streams))
        clock("encode float64", lambda: encode_with(old, streams, compact=False))
        payloads, file_bytes = clock("encode peer", lambda: peer_encode(imu, sig))
        a = clock("decode new", lambda: decode_all(new_enc, topics))
        b = clock("decode previous", lambda: decode_all(new_enc, topics, per_block=True))
        clock("decode float64", lambda: decode_all(f64_enc, topics, per_block=True))
        p = clock("decode peer", lambda pl=payloads, fb=file_bytes: peer_decode(pl, len(_blocks(imu.t_ns)), fb))
        assert np.array_equal(a[0].acc, b[0].acc) and np.array_equal(a[1].values, b[1].values)
        assert np.array_equal(p[1], imu.acc) and np.array_equal(a[0].acc, imu.acc)
    print(f"block codec on {args.days:g} day of simulated AX6 (imu {n:,} samples + float32 quaternion {n:,})")
    print(f"best of {args.repeat}; load average {load_before} before, {load_average()} after")
    print(f"{'':18s}{'seconds':>9s}{'M samples/s':>13s}{'new is x faster':>17s}")
    for op in ("encode", "decode"):
        for side in ("new", "previous", "float64", "peer"):
            s = best[f"{op} {side}"]
            ratio = s / best[f"{op} new"]
            print(f"{op + ' ' + side:18s}{s:9.3f}{samples / s / 1e6:13.2f}{ratio:16.2f}x")
    print("previous = per-block codec of 3ae3c3f (counts, compact times); float64 = schema_version 1 blocks;")
    print("peer = the same arrays as 1-s float64 blocks with protobuf's upb classes and the mcap library")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
