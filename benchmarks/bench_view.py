"""Benchmark: a 1-hour trial to .rrd with imulog's columnar viewer vs per-sample ``rr.log`` of the same data.

Trial: IMU at 115 Hz (acc, gyr, mag), 4 markers at 100 Hz, 3 derived trajectories at 100 Hz, phases
(720 repetitions x 4). Run::

    /work/venv/bin/python benchmarks/bench_view.py            # 3600 s trial, baseline time-boxed
    /work/venv/bin/python benchmarks/bench_view.py --duration 600 --baseline-seconds 60

The per-sample baseline logs the same rows (one ``rr.log`` per entity per sample, ``set_time`` per sample)
on the first ``--baseline-seconds`` of the trial and is extrapolated linearly to the full row count (its
cost per row is constant); the printout says so. Both write to an .rrd file in a temporary directory.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np
import rerun as rr

from imulog.model import Intervals, Recording, SignalStream
from imulog.view import layout as L
from imulog.view.clock import device_to_reference
from imulog.view.sample import SampleTrialParams, sample_recording
from imulog.view.streams import log_streams


def bench_trial(duration_s: float) -> Recording:
    """IMU + 4 markers + 3 trajectories + phases (the benchmark's trial), from the analytic sample."""
    full = sample_recording(SampleTrialParams(duration_s=duration_s))
    trajectories = [s for s in full.signals if s.topic.startswith(L.TRAJECTORY_PREFIX)]
    return Recording(
        imus=full.imus,
        markers=full.markers,
        signals=trajectories,
        events=full.events,
        metadata={"imulog.alignment": full.metadata["imulog.alignment"]},
    )


def rows_of(rec: Recording) -> int:
    """Rows the viewer sends (one per sample per entity; phases: start + reset rows)."""
    imu = rec.imus[0]
    n = 4 * len(imu) + len(rec.markers[0])  # acc, gyr, mag, |gyr|
    n += sum(2 * len(s) for s in rec.signals)  # scalars + cursor
    return n + sum(2 * len(e) for e in rec.events)


def columnar(rec: Recording, out: Path) -> float:
    """Seconds to log ``rec`` with :func:`log_streams` into ``out`` (including flushing the file)."""
    start = time.perf_counter()
    stream = rr.RecordingStream("imulog-bench", recording_id=uuid.uuid4())
    stream.save(out)
    log_streams(rec.streams(), rec.metadata, recording=stream, label="bench")
    stream.flush()
    stream.disconnect()
    return time.perf_counter() - start


def per_sample(rec: Recording, out: Path, until_s: float) -> tuple[float, int]:
    """Per-sample ``rr.log`` of the same entities for samples before ``until_s`` (reference clock)."""
    start = time.perf_counter()
    stream = rr.RecordingStream("imulog-bench-baseline", recording_id=uuid.uuid4())
    stream.save(out)
    rows = 0
    alignment = rec.metadata["imulog.alignment"]
    imu = rec.imus[0]
    t_imu = device_to_reference(imu.t_ns, alignment)
    gyr_norm = np.linalg.norm(imu.gyr, axis=1)
    for i in np.nonzero(t_imu < until_s * 1e9)[0]:
        stream.set_time(L.TIMELINE, duration=np.timedelta64(int(t_imu[i]), "ns"))
        stream.log("/imu/wrist/acc", rr.Scalars(imu.acc[i]))
        stream.log("/imu/wrist/gyr", rr.Scalars(imu.gyr[i]))
        stream.log("/imu/wrist/mag", rr.Scalars(imu.mag[i]))
        stream.log("/imu/wrist/gyr_norm", rr.Scalars(gyr_norm[i]))
        rows += 4
    markers = rec.markers[0]
    for i in np.nonzero(markers.t_ns < until_s * 1e9)[0]:
        stream.set_time(L.TIMELINE, duration=np.timedelta64(int(markers.t_ns[i]), "ns"))
        ok = markers.valid[i]
        stream.log("/world/markers/vicon", rr.Points3D(markers.pos[i][ok], class_ids=np.nonzero(ok)[0]))
        rows += 1
    for s in rec.signals:
        assert isinstance(s, SignalStream)
        cursor = L.cursor_entity(s.topic)
        for i in np.nonzero(s.t_ns < until_s * 1e9)[0]:
            stream.set_time(L.TIMELINE, duration=np.timedelta64(int(s.t_ns[i]), "ns"))
            stream.log(s.topic, rr.Scalars(s.values[i]))
            stream.log(cursor, rr.Points3D([s.values[i]]))
            rows += 2
    for e in rec.events:
        assert isinstance(e, Intervals)
        t0 = device_to_reference(e.start_ns, alignment)
        t1 = device_to_reference(e.end_ns, alignment)
        for i in np.nonzero(t0 < until_s * 1e9)[0]:
            stream.set_time(L.TIMELINE, duration=np.timedelta64(int(t0[i]), "ns"))
            stream.log(e.topic, rr.StateChange(state=[e.labels[i], f"rep {e.task_index[i]}"]))
            stream.set_time(L.TIMELINE, duration=np.timedelta64(int(t1[i]), "ns"))
            stream.log(e.topic, rr.StateChange(state=["", ""]))
            rows += 2
    stream.flush()
    stream.disconnect()
    return time.perf_counter() - start, rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration", type=float, default=3600.0, help="trial length, s (default 3600)")
    parser.add_argument("--baseline-seconds", type=float, default=60.0, help="data span the baseline logs, s")
    parser.add_argument("--repeat", type=int, default=3, help="columnar runs (best is reported)")
    args = parser.parse_args()

    rec = bench_trial(args.duration)
    total_rows = rows_of(rec)
    print(
        f"trial: {args.duration:.0f} s, IMU {len(rec.imus[0])} samples @115 Hz, markers {len(rec.markers[0])} x 4 "
        f"@100 Hz, {len(rec.signals)} trajectories, {len(rec.events[0])} phases; {total_rows} rows"
    )
    with tempfile.TemporaryDirectory() as tmp:
        times = [columnar(rec, Path(tmp) / f"columnar{i}.rrd") for i in range(args.repeat)]
        best = min(times)
        size_mb = (Path(tmp) / "columnar0.rrd").stat().st_size / 1e6
        print(f"columnar send_columns: {best:.2f} s (runs: {', '.join(f'{t:.2f}' for t in times)}), {size_mb:.0f} MB")
        verdict = "OK" if max(times) <= 3.0 else "OK (best run only)" if best <= 3.0 else "MISSED"
        print(f"  -> {total_rows / best / 1e6:.2f} M rows/s; target <= 3 s: {verdict}")

        base_s, base_rows = per_sample(rec, Path(tmp) / "baseline.rrd", args.baseline_seconds)
        per_row = base_s / base_rows
        extrapolated = per_row * total_rows
        label = "measured" if args.baseline_seconds >= args.duration else "extrapolated"
        print(
            f"per-sample rr.log: {base_s:.2f} s for {base_rows} rows (first {args.baseline_seconds:.0f} s of data), "
            f"{per_row * 1e6:.1f} us/row -> {extrapolated:.1f} s for the whole trial ({label})"
        )
        ratio = extrapolated / best
        worst = extrapolated / max(times)
        print(
            f"speed-up columnar vs per-sample: {ratio:.0f}x (best run), {worst:.0f}x (slowest run); "
            f"target >= 50x: {'OK' if worst >= 50 else 'MISSED'}"
        )


if __name__ == "__main__":
    main()
