"""Viewer speed: `imulog view trial.mcap --save` against reading the same channels and ``rr.send_columns``.

    python benchmarks/bench_view.py                  # a 1-hour trial
    python benchmarks/bench_view.py --duration 600   # quicker

The trial (IMU at 115 Hz with acc, gyr and mag; 4 markers at 100 Hz; 3 trajectories at 100 Hz; phases) is
written once as an MCAP archive. imulog's side is its viewer saving an ``.rrd``: open the trial, map every channel
to the reference clock, log it with the default layout (norms, cursors, paths, errors, states, blueprint). It runs
two ways: ``open_trial`` (each channel read when the viewer reaches it, so Rerun encodes one channel while the
next is read; what ``imulog view`` does, and the target is measured on it) and ``read_trial`` (every channel read
before anything is logged, for comparison).
The peer (issue 17) is what a user of Rerun who already has the arrays would write: read the same
channels with ``TrialReader.read`` and send each as one ``rr.send_columns`` batch (scalars, marker points,
state changes) to an ``.rrd`` file — the read is included on both sides. One process, interleaved, best of
``--repeat``; the machine's load average is printed before and after, and the CPU time of each side (all threads
of the process, rerun's encoder threads included), which a loaded machine distorts less than wall time.

Target (issue 17): imulog's time at most 1.5x the peer's.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np
import rerun as rr

from imulog.archive import TrialReader, write_trial
from imulog.model import ImuStream, Intervals, MarkerStream, Recording, SignalStream
from imulog.view import layout as L
from imulog.view.sample import SampleTrialParams, sample_recording
from imulog.view.session import show
from imulog.view.source import open_trial, read_trial


def bench_trial(duration_s: float) -> Recording:
    """IMU + 4 markers + 3 trajectories + phases, from the analytic sample trial."""
    full = sample_recording(SampleTrialParams(duration_s=duration_s))
    trajectories = [s for s in full.signals if s.topic.startswith(L.TRAJECTORY_PREFIX)]
    return Recording(
        imus=full.imus,
        markers=full.markers,
        signals=trajectories,
        events=full.events,
        metadata={"imulog.alignment": full.metadata["imulog.alignment"]},
    )


def imulog_view(path: Path, out: Path, *, read_first: bool = False) -> tuple[float, float]:
    """(wall s, CPU s of the whole process, rerun's encoder threads included) of imulog's viewer saving ``out``.

    Channels are read while they are logged (``open_trial``), or all read before logging (``read_trial``:
    ``read_first``)."""
    t0, c0 = time.perf_counter(), time.process_time()
    show([read_trial(path) if read_first else open_trial(path)], sink="save", save_paths=[out])
    return time.perf_counter() - t0, time.process_time() - c0


def _time(t_ns: np.ndarray) -> rr.TimeColumn:
    return rr.TimeColumn(L.TIMELINE, duration=np.asarray(t_ns, dtype=np.int64).astype("timedelta64[ns]"))


def peer_view(path: Path, out: Path) -> tuple[float, float]:
    """Read every channel and send it columnarly, nothing else (no clock mapping, layout or derived views).

    Returns (wall s, process CPU s)."""
    t0, c0 = time.perf_counter(), time.process_time()
    rec = rr.RecordingStream("peer", recording_id=uuid.uuid4())
    rec.save(out)
    with TrialReader(path) as trial:
        for topic in trial.topics():
            s = trial.read(topic)
            if isinstance(s, ImuStream):
                for name in ("acc", "gyr", "mag"):
                    values = getattr(s, name)
                    if values is not None:
                        rec.send_columns(
                            f"{topic}/{name}", indexes=[_time(s.t_ns)], columns=rr.Scalars.columns(scalars=values)
                        )
            elif isinstance(s, MarkerStream):
                counts = s.valid.sum(axis=1).astype(np.int64)
                cols = rr.Points3D.columns(positions=np.ascontiguousarray(s.pos[s.valid], dtype=np.float32))
                rec.send_columns(topic, indexes=[_time(s.t_ns)], columns=cols.partition(counts))
            elif isinstance(s, SignalStream):
                rec.send_columns(topic, indexes=[_time(s.t_ns)], columns=rr.Scalars.columns(scalars=s.values))
            elif isinstance(s, Intervals):
                t = np.concatenate([s.start_ns, s.end_ns])
                states = [str(x) for x in s.labels] + [""] * len(s)
                order = np.argsort(t, kind="stable")
                rec.send_columns(
                    topic,
                    indexes=[_time(t[order])],
                    columns=rr.StateChange.columns(state=[states[i] for i in order]),
                )
    rec.flush()
    rec.disconnect()
    return time.perf_counter() - t0, time.process_time() - c0


SIDES = {
    "streamed": "imulog view, open_trial (read while logged)",
    "read_first": "imulog view, read_trial (all read first)",
    "peer": "read + send_columns (peer)",
}


def run_side(side: str, trial: Path, out: Path) -> tuple[float, float]:
    """(wall s, CPU s) of one run of ``side`` (a key of :data:`SIDES`) writing ``out``."""
    if side == "peer":
        return peer_view(trial, out)
    return imulog_view(trial, out, read_first=side == "read_first")


def main(argv: list[str] | None = None) -> int:
    from bench_archive import load_average  # benchmarks/ is on sys.path when this script runs

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3600.0, help="trial length, s (default 3600)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each side; the best is reported")
    args = ap.parse_args(argv)

    rec = bench_trial(args.duration)
    load_before = load_average()
    runs: dict[str, list[tuple[float, float]]] = {side: [] for side in SIDES}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        trial = write_trial(tmp / "trial.mcap", rec)
        for i in range(args.repeat):
            for side in SIDES:
                runs[side].append(run_side(side, trial, tmp / f"{side}{i}.rrd"))
        size = {side: (tmp / f"{side}0.rrd").stat().st_size / 1e6 for side in SIDES}
    wall = {side: min(w for w, _ in r) for side, r in runs.items()}
    cpu = {side: min(c for _, c in r) for side, r in runs.items()}
    print(
        f"view benchmark: {args.duration:.0f} s trial, IMU {len(rec.imus[0]):,} samples, markers "
        f"{len(rec.markers[0]):,} x 4, {len(rec.signals)} trajectories, {len(rec.events[0])} phases"
    )
    print(
        f"best of {args.repeat}; load average {load_before} before, {load_average()} after; rerun-sdk {rr.__version__}"
    )
    for side, label in SIDES.items():
        listed = ", ".join(f"{w:.2f}" for w, _ in runs[side])
        print(f"{label:44s}: {wall[side]:5.2f} s wall (runs {listed}), {cpu[side]:.2f} s CPU, {size[side]:.0f} MB")
    for side in ("streamed", "read_first"):
        print(
            f"{SIDES[side]} / peer = {wall[side] / wall['peer']:.2f}x wall, {cpu[side] / cpu['peer']:.2f}x CPU "
            "(CPU: all threads of the process, less sensitive to load)"
        )
    ratio = wall["streamed"] / wall["peer"]
    ok = ratio <= 1.5
    print(f"imulog / peer = {ratio:.2f}x wall (target <= 1.5x): {'meets target' if ok else 'ABOVE TARGET'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
