"""Converter speed against the bare parse: ``convert / pandas.read_csv`` of the same file, same process.

Files (generated in a temporary folder):
* a 1-hour 9-axis IMU text file at 100 Hz (360 000 rows, ``Time (s),Gyroscope X (deg/s),...``), ~60 MB;
* a 10-minute 40-marker Vicon Nexus CSV at 100 Hz (60 000 rows, Trajectories section, mm, some gaps).

Target: convert (parse + validate + units -> Recording) takes at most 2x the bare ``pandas.read_csv`` of the same
file (best of ``--repeat`` interleaved runs). The MCAP write (``write_trial``, the archive's part) is printed
after, for information.

    /work/venv/bin/python benchmarks/bench_convert.py [--repeat 5] [--minutes-imu 60] [--minutes-vicon 10]
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


def best_of_interleaved(bare, conv, repeat: int) -> tuple[float, float]:
    """Best time of each, runs alternating so that load changes on a shared machine hit both alike."""
    tb, tc = [], []
    for _ in range(repeat):
        for fn, out in ((bare, tb), (conv, tc)):
            t0 = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t0)
    return min(tb), min(tc)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--minutes-imu", type=float, default=60.0)
    ap.add_argument("--minutes-vicon", type=float, default=10.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        imu = Path(tmp) / "imu_1h.csv"
        nexus = Path(tmp) / "nexus_10min.csv"
        n_imu = write_imu(imu, args.minutes_imu)
        n_vic = write_nexus(nexus, args.minutes_vicon)
        cases = [
            (
                f"IMU text {args.minutes_imu:g} min 9-axis 100 Hz ({n_imu} rows, {imu.stat().st_size / 1e6:.0f} MB)",
                lambda: pd.read_csv(imu),
                lambda: DELIMITED.convert(imu),
            ),
            (
                f"Nexus CSV {args.minutes_vicon:g} min 40 markers ({n_vic} rows, {nexus.stat().st_size / 1e6:.0f} MB)",
                lambda: pd.read_csv(nexus, skiprows=5, header=None),
                lambda: VICON.convert(nexus),
            ),
        ]
        print(f"best of {args.repeat} runs; target: convert <= 2.0 x pandas.read_csv")
        worst = 0.0
        for label, bare, conv in cases:
            t_bare, t_conv = best_of_interleaved(bare, conv, args.repeat)
            ratio = t_conv / t_bare
            worst = max(worst, ratio)
            print(f"{label}\n    pandas.read_csv {t_bare:7.3f} s   convert {t_conv:7.3f} s   ratio {ratio:5.2f}")
        print(f"worst ratio {worst:.2f} ({'meets' if worst <= 2.0 else 'MISSES'} the 2x target)")
        # for information: the whole `imulog convert` path, i.e. also writing the MCAP trial (the archive's cost)
        from imulog.archive import write_trial

        for label, src, conv in (("IMU text", imu, DELIMITED), ("Nexus CSV", nexus, VICON)):
            out = Path(tmp) / f"{src.stem}.mcap"
            rec = conv.convert(src)
            t0 = time.perf_counter()
            write_trial(out, rec, attach_sources=True, overwrite=True)
            t_write = time.perf_counter() - t0
            print(f"(info) {label}: write_trial incl. attachment {t_write:.3f} s, {out.stat().st_size / 1e6:.0f} MB")


if __name__ == "__main__":
    main()
