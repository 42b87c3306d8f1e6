"""Archive speed: write, read into numpy and append, against one-protobuf-message-per-sample with `mcap`.

    python benchmarks/bench_archive.py                 # 1 h of 1 kHz 9-axis IMU = 3.6 M samples
    python benchmarks/bench_archive.py --samples 600000 --baseline-samples 100000

imulog stores ~1 s blocks of packed little-endian arrays (imulog.ImuBlock / SignalBlock). The baseline is
the naive layout measured in the same run with the same `mcap` library (zstd chunks): one protobuf message
per sample (t_ns + 9 doubles) written with ``mcap.writer.Writer`` and read back with
``mcap.reader.make_reader`` + protobuf parsing into numpy arrays. The baseline runs on a subset
(``--baseline-samples``) because it is slow; rates are samples per second, so the ratio is fair. The
append baseline is writing the derived channel (4 doubles per sample) as one message per sample with the
`mcap` writer, which cannot append: that is a lower bound of its real cost (it ignores copying the trial).
Targets (issue 2, 2-core machine): read >= 3 M samples/s, write >= 1 M/s, append >= 1 M/s, each >= 10x the
baseline.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from imulog.archive import TrialReader, append_derived, write_trial
from imulog.model import ImuStream, Recording, SignalStream

TARGETS = {"write": 1e6, "read": 3e6, "append": 1e6}


def make_imu(n: int, rate_hz: float = 1000.0, seed: int = 0) -> ImuStream:
    """A realistic 9-axis signal: slow movements + noise, quantised to the sensors' LSB like real data."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.int64) * int(round(1e9 / rate_hz)) + 1_000_000
    s = np.arange(n) / rate_hz
    move = np.sin(2 * np.pi * 0.3 * s)[:, None] * np.array([[2.0, 1.0, 0.5]])
    acc = np.round((move + [0, 0, 9.81] + rng.normal(0, 0.02, (n, 3))) / 0.000598) * 0.000598  # 16 g / 2^15
    gyr = np.round((move * 0.5 + rng.normal(0, 0.01, (n, 3))) / 0.00106) * 0.00106  # 2000 dps / 2^15
    mag = np.round((np.array([20.0, 5.0, -40.0]) + rng.normal(0, 0.3, (n, 3))) / 0.15) * 0.15
    return ImuStream("bench", t, acc=acc, gyr=gyr, mag=mag, meta={"rate_hz": rate_hz})


def _sample_class():
    """A per-sample message (t_ns + 9 doubles) built at run time, and its FileDescriptorSet."""
    fdp = descriptor_pb2.FileDescriptorProto(name="bench/ImuSample.proto", package="bench", syntax="proto3")
    msg = fdp.message_type.add(name="ImuSample")
    msg.field.add(name="t_ns", number=1, type=descriptor_pb2.FieldDescriptorProto.TYPE_INT64)
    for k, name in enumerate(["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"]):
        msg.field.add(name=name, number=k + 2, type=descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE)
    pool = descriptor_pool.DescriptorPool()
    pool.Add(fdp)
    fds = descriptor_pb2.FileDescriptorSet(file=[fdp]).SerializeToString()
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("bench.ImuSample")), fds


def baseline(imu: ImuStream, path: Path, width: int = 9) -> dict[str, float]:
    """One protobuf message per sample with the mcap library: write and read rates (samples/s)."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    cls, fds = _sample_class()
    names = ["ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz"][:width]
    values = np.hstack([imu.acc, imu.gyr, imu.mag])[:, :width].tolist()
    t0 = time.perf_counter()
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start()
        sid = w.register_schema("bench.ImuSample", "protobuf", fds)
        cid = w.register_channel("/imu/bench", "protobuf", sid)
        for t, row in zip(imu.t_ns.tolist(), values, strict=True):
            m = cls(t_ns=t, **dict(zip(names, row, strict=True)))
            w.add_message(cid, t, m.SerializeToString(), t)
        w.finish()
    write_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    ts, cols = [], []
    with open(path, "rb") as f:
        for _, _, message in make_reader(f).iter_messages():
            m = cls.FromString(message.data)
            ts.append(m.t_ns)
            cols.append([getattr(m, k) for k in names])
    t_arr, v_arr = np.array(ts, dtype=np.int64), np.array(cols)
    read_s = time.perf_counter() - t0
    assert np.array_equal(t_arr, imu.t_ns) and v_arr.shape == (len(imu), width)
    n = len(imu)
    return {"write": n / write_s, "read": n / read_s, "bytes_per_sample": path.stat().st_size / n}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=3_600_000, help="IMU samples (default: 1 h at 1 kHz)")
    ap.add_argument("--baseline-samples", type=int, default=200_000, help="samples for the per-sample baseline")
    ap.add_argument("--repeat", type=int, default=2, help="repetitions; the best time is reported")
    ap.add_argument("--dir", default=None, help="where to write the temporary files (default: system temp)")
    args = ap.parse_args(argv)

    imu = make_imu(args.samples)
    n = len(imu)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) + np.random.default_rng(1).normal(0, 1e-3, (n, 4))
    derived = SignalStream("/derived/orientation/bench", imu.t_ns, ["qw", "qx", "qy", "qz"], ["1"] * 4, q)
    with tempfile.TemporaryDirectory(dir=args.dir) as tmp:
        tmp = Path(tmp)
        best = {"write": np.inf, "read": np.inf, "append": np.inf}
        for _ in range(args.repeat):
            path = tmp / "trial.mcap"
            if path.exists():
                os.unlink(path)
            t0 = time.perf_counter()
            write_trial(path, Recording(imus=[imu]))
            best["write"] = min(best["write"], time.perf_counter() - t0)
            size_raw = path.stat().st_size
            t0 = time.perf_counter()
            with TrialReader(path) as trial:
                back = trial.read("/imu/bench")
            best["read"] = min(best["read"], time.perf_counter() - t0)
            assert np.array_equal(back.acc, imu.acc) and np.array_equal(back.t_ns, imu.t_ns)
            t0 = time.perf_counter()
            append_derived(path, [derived], run={"step": "bench", "algorithm": "none", "params": {}})
            best["append"] = min(best["append"], time.perf_counter() - t0)
        size = path.stat().st_size
        with TrialReader(path) as trial:
            assert np.array_equal(trial.read("/derived/orientation/bench").values, q)

        sub = make_imu(min(args.baseline_samples, n))
        base = baseline(sub, tmp / "baseline.mcap")
        base_q = baseline(sub, tmp / "baseline_q.mcap", width=4)
    rates = {k: n / v for k, v in best.items()}
    base_rates = {"write": base["write"], "read": base["read"], "append": base_q["write"]}
    print(f"imulog archive benchmark: {n:,} samples of 9-axis IMU at 1 kHz ({n / 3.6e6:.2f} h); best of {args.repeat}")
    print(
        f"file size: {size_raw / 1e6:.1f} MB raw trial ({size_raw / n:.1f} B per 9-axis sample, 80 B uncompressed), "
        f"{size / 1e6:.1f} MB with the 4-column derived channel"
    )
    print(
        f"baseline: one protobuf message per sample, mcap {_mcap_version()}, {len(sub):,} samples, "
        f"{base['bytes_per_sample']:.1f} B/sample"
    )
    print(f"{'':8s}{'seconds':>9s}{'samples/s':>13s}{'baseline/s':>13s}{'ratio':>8s}{'target':>10s}  verdict")
    ok_all = True
    for k in ("write", "read", "append"):
        ratio = rates[k] / base_rates[k]
        ok = rates[k] >= TARGETS[k] and ratio >= 10
        ok_all &= ok
        print(
            f"{k:8s}{best[k]:9.2f}{rates[k]:13,.0f}{base_rates[k]:13,.0f}{ratio:7.1f}x{TARGETS[k] / 1e6:8.1f} M"
            f"  {'meets target' if ok else 'BELOW TARGET'}"
        )
    return 0 if ok_all else 1


def _mcap_version() -> str:
    from importlib.metadata import version

    return version("mcap")


if __name__ == "__main__":
    raise SystemExit(main())
