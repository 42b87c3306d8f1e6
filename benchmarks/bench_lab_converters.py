"""Lab-system converters (issue 14) against the bare parse: an Xsens MT Manager export and a Motive CSV.

Files (generated in a temporary folder, in the layouts of the real samples in ../shared/data/devices):
* an Xsens MT Manager export (old header, tab, empty SampleTimeFine/UTC columns, acc, gyr, mag, rotation
  matrix) at 100 Hz, ``--minutes-xsens`` long (30 min: 180 000 rows, ~34 MB);
* an OptiTrack Motive CSV 1.21 (1 rigid body + 40 markers with 1 % occlusions) at 120 Hz, ``--minutes-motive``.

imulog's side is ``convert_file`` (field counts checked per line, gaps kept, orientation from the matrix, the
``Recording`` built); the floor is ``pandas.read_csv`` of the same numeric block. Best of ``--repeat``; the load
average and peak RSS are printed.

    python benchmarks/bench_lab_converters.py [--repeat 2] [--minutes-xsens 30] [--minutes-motive 10]
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from imulog.converters import convert_file

XSENS_HEADER = [
    "// Start Time: Unknown",
    "// Update Rate: 100.0Hz",
    "// Filter Profile: human (46.1)",
    "// Option Flags: AHS Disabled ICC Disabled ",
    "// Firmware Version: 4.0.2",
]
XSENS_COLUMNS = (
    "PacketCounter\tSampleTimeFine\tYear\tMonth\tDay\tSecond\tUTC_Nano\tUTC_Year\tUTC_Month\tUTC_Day\tUTC_Hour\t"
    "UTC_Minute\tUTC_Second\tUTC_Valid\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y\tGyr_Z\tMag_X\tMag_Y\tMag_Z\t"
    + "\t".join(f"Mat[{r}][{c}]" for c in (1, 2, 3) for r in (1, 2, 3))
)


def write_xsens(path: Path, minutes: float, seed: int = 0) -> int:
    rng = np.random.default_rng(seed)
    n = int(minutes * 60 * 100)
    data = np.round(rng.normal(0, 1, (n, 18)), 6)
    counter = np.arange(n) % 65536
    body = pd.DataFrame(data).astype(str)
    body.insert(0, "pc", [f"{c:05d}" for c in counter])
    for k in range(13):
        body.insert(1 + k, f"e{k}", "")
    with open(path, "w") as f:
        f.write("\n".join([*XSENS_HEADER, XSENS_COLUMNS]) + "\n")
        body.to_csv(f, sep="\t", header=False, index=False, lineterminator="\n")
    return n


def motive_header(n: int, markers: int) -> list[str]:
    """The header lines of a Motive 1.21 take of ``n`` frames at 120 Hz: rigid body ``RB``, markers ``M0``..."""
    return [
        "Format Version,1.21,Take Name,bench,Capture Frame Rate,120.000000,Export Frame Rate,120.000000,"
        f"Capture Start Time,2016-01-05 03.49.50.755 PM,Total Frames in Take,{n},Total Exported Frames,{n},"
        "Rotation Type,Quaternion,Length Units,Meters,Coordinate Space,Global",
        "",
        ",," + ",".join(["Rigid Body"] * 7 + ["Marker"] * 3 * markers),
        ",," + ",".join(["RB"] * 7 + [f"M{m}" for m in range(markers) for _ in range(3)]),
        ",," + ",".join(["1"] * 7 + [str(100 + m) for m in range(markers) for _ in range(3)]),
        ",," + ",".join(["Rotation"] * 4 + ["Position"] * 3 + ["Position"] * 3 * markers),
        "Frame,Time," + ",".join(["X", "Y", "Z", "W", "X", "Y", "Z"] + ["X", "Y", "Z"] * markers),
    ]


def write_motive(path: Path, minutes: float, markers: int = 40, seed: int = 1) -> int:
    rng = np.random.default_rng(seed)
    n = int(minutes * 60 * 120)
    q = rng.normal(0, 1, (n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    cols = np.column_stack(
        [np.arange(n), np.arange(n) / 120.0, q, rng.normal(0, 1, (n, 3)), rng.normal(0, 1, (n, 3 * markers))]
    )
    text = pd.DataFrame(np.round(cols, 6)).astype(str)
    text.iloc[:, 0] = np.arange(n).astype(str)
    occluded = np.repeat(rng.random((n, markers)) < 0.01, 3, axis=1)
    marker_part = text.iloc[:, 9:].to_numpy()
    marker_part[occluded] = ""
    text.iloc[:, 9:] = marker_part
    with open(path, "w") as f:
        f.write("\n".join(motive_header(n, markers)) + "\n")
        text.to_csv(f, header=False, index=False, lineterminator="\n")
    return n


def best(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--minutes-xsens", type=float, default=30.0)
    ap.add_argument("--minutes-motive", type=float, default=10.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        xs = Path(tmp) / "MT_012005D6_099-000_00B421AF.txt"
        mo = Path(tmp) / "take.csv"
        n_x = write_xsens(xs, args.minutes_xsens)
        n_m = write_motive(mo, args.minutes_motive)
        for name, path, n, bare in (
            ("xsens", xs, n_x, lambda p=xs: pd.read_csv(p, sep="\t", skiprows=6, header=None)),
            ("motive", mo, n_m, lambda p=mo: pd.read_csv(p, skiprows=7, header=None)),
        ):
            floor = best(bare, args.repeat)
            conv = best(lambda p=path: convert_file(p), args.repeat)
            print(
                f"{name:7s} {n:8d} rows, {path.stat().st_size / 1e6:6.1f} MB: convert {conv:6.2f} s "
                f"({n / conv / 1e3:5.0f} k rows/s), bare read_csv {floor:6.2f} s, ratio {conv / floor:4.2f}x"
            )
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS {rss:.0f} MB; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
