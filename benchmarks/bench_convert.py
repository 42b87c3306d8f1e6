"""`imulog convert` speed against its floor: the bare parse plus the `mcap` library writing the same blocks.

Files (generated in a temporary folder):
* a 1-hour 9-axis IMU text file at 100 Hz (360 000 rows, ``Time (s),Gyroscope X (deg/s),...``), ~60 MB;
* a 10-minute 40-marker Vicon Nexus CSV at 100 Hz (60 000 rows, Trajectories section, mm, some gaps).

imulog's side is the whole conversion a user runs: parse + validate + units -> Recording, then ``write_trial``
(MCAP with metadata and the raw-data hash), with and without attaching the source file. The floor (issue 17) is
the bare ``pandas.read_csv`` of the same file plus the `mcap` library writing the same block messages
(``bench_archive.peer_write``: zstd, same chunk target). Runs alternate in one process; best of ``--repeat``;
the load average is printed.

Target (issue 17): convert (without attachment, like the floor) at most 1.5x the floor.

    python benchmarks/bench_convert.py [--repeat 5] [--minutes-imu 60] [--minutes-vicon 10]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from converters.delimited import CONVERTER as DELIMITED
from converters.vicon_csv import CONVERTER as VICON


def write_imu(path: Path, minutes: float, rate_hz: float = 100.0, seed: int = 0) -> int:
    rng = np.random.default_rng(seed)
    n = int(minutes * 60 * rate_hz)
    t = np.arange(n) / rate_hz
    data = np.column_stack([t, rng.normal(0, 20, (n, 3)), rng.normal(0, 0.3, (n, 3)), rng.normal(20, 5, (n, 3))])
    header = "Time (s)," + ",".join(
        [f"Gyroscope {a} (deg/s)" for a in "XYZ"]
        + [f"Accelerometer {a} (g)" for a in "XYZ"]
        + [f"Magnetometer {a} (uT)" for a in "XYZ"]
    )
    np.savetxt(path, data, delimiter=",", header=header, comments="", fmt=["%.4f"] + ["%.6g"] * 9)
    return n


def write_nexus(path: Path, minutes: float, markers: int = 40, rate_hz: float = 100.0, seed: int = 1) -> int:
    rng = np.random.default_rng(seed)
    n = int(minutes * 60 * rate_hz)
    pos = rng.normal(500, 300, (n, markers * 3))
    text = pos.round(3).astype(str).astype(object)
    gaps = rng.random((n, markers)) < 0.01
    text[np.repeat(gaps, 3, axis=1)] = ""
    width = 2 + 3 * markers
    lines = [
        "Trajectories" + "," * (width - 1),
        f"{rate_hz:g}" + "," * (width - 1),
        ",," + ",".join(f"Subject:M{m:02d},," for m in range(markers))[:-1],
        "Frame,Sub Frame," + ",".join(["X,Y,Z"] * markers),
        ",," + ",".join(["mm"] * 3 * markers),
    ]
    frames = np.arange(1, n + 1).astype(str)
    body = [f"{frames[i]},0," + ",".join(text[i]) for i in range(n)]
    path.write_text("\r\n".join(lines + body) + "\r\n")
    return n


def best_of_interleaved(fns, repeat: int) -> list[float]:
    """Best time of each function, runs alternating so that load changes on a shared machine hit all alike."""
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(repeat):
        for fn, out in zip(fns, times, strict=True):
            t0 = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t0)
    return [min(t) for t in times]


def main() -> int:
    from bench_archive import load_average, peer_write

    from imulog.archive import write_trial

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--minutes-imu", type=float, default=60.0)
    ap.add_argument("--minutes-vicon", type=float, default=10.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        imu = tmp / "imu_1h.csv"
        nexus = tmp / "nexus_10min.csv"
        n_imu = write_imu(imu, args.minutes_imu)
        n_vic = write_nexus(nexus, args.minutes_vicon)
        cases = [
            (
                f"IMU text {args.minutes_imu:g} min 9-axis 100 Hz ({n_imu} rows, {imu.stat().st_size / 1e6:.0f} MB)",
                imu,
                lambda: pd.read_csv(imu),
                DELIMITED,
            ),
            (
                f"Nexus CSV {args.minutes_vicon:g} min 40 markers ({n_vic} rows, {nexus.stat().st_size / 1e6:.0f} MB)",
                nexus,
                lambda: pd.read_csv(nexus, skiprows=5, header=None),
                VICON,
            ),
        ]
        print(f"best of {args.repeat} interleaved runs; load average {load_average()}")
        print("target: convert + write (no attachment) <= 1.5 x (pandas.read_csv + mcap library writing the blocks)")
        worst = 0.0
        for label, src, bare, conv in cases:
            streams = conv.convert(src).streams()

            def floor(bare=bare, streams=streams, src=src):
                bare()
                for k, stream in enumerate(streams):
                    peer_write(stream, tmp / f"{src.stem}_peer{k}.mcap")

            def ours(conv=conv, src=src, attach=False):
                write_trial(tmp / f"{src.stem}.mcap", conv.convert(src), attach_sources=attach, overwrite=True)

            t_floor, t_ours, t_attach = best_of_interleaved(
                [floor, ours, lambda conv=conv, src=src: ours(conv, src, True)], args.repeat
            )
            ratio = t_ours / t_floor
            worst = max(worst, ratio)
            print(
                f"{label}\n    floor {t_floor:7.3f} s   imulog convert {t_ours:7.3f} s (ratio {ratio:4.2f})"
                f"   with the source attached {t_attach:7.3f} s ({t_attach / t_floor:4.2f}x)"
            )
        print(f"worst ratio {worst:.2f} ({'meets' if worst <= 1.5 else 'MISSES'} the 1.5x target)")
    return 0 if worst <= 1.5 else 1


if __name__ == "__main__":
    raise SystemExit(main())
