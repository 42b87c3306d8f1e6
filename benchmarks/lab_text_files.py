"""Long files of the lab and device text exports for ``bench_convert_pieces.py --formats`` (issue 24, point 4).

Each writer puts a file of ``n`` rows into a folder, block by block (the bench's own memory stays small), in the
layout of the shared samples (``../shared/data/devices``): OptiTrack Motive CSV 1.21 (120 Hz, a rigid body and 4
markers with occlusions as empty cells), Qualisys QTM TSV (100 Hz, 8 markers, Frame/Time, zeros and ``NULL`` for
missing data), OpenSim TRC (100 Hz, 8 markers, mm), OpenSense ``.sto`` (100 Hz, 3 IMU quaternions), Delsys Trigno CSV
(a sensor's ACC and GYRO at 148 Hz beside another's EMG at 296 Hz: the IMU columns end halfway, as slower channels
do; EMG is slower than Trigno's 1259 Hz to keep the files small), an Empatica E4 ``ACC.csv`` (32 Hz) and an ActiLife
epoch CSV (1 s epochs, Date and Time columns). ``FORMATS``: name -> (rows per hour, writer).
"""

from __future__ import annotations

import io
from collections.abc import Callable
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
from bench_lab_converters import motive_header

BLOCK = 100_000  # rows generated and written at a time


def _write_rows(
    f, n: int, make: Callable[[int, int, np.random.Generator], np.ndarray], fmt: list[str], delimiter: str
) -> None:
    """``make(lo, hi, rng)`` rows in blocks, NaN written as empty cells."""
    rng = np.random.default_rng(0)
    for lo in range(0, n, BLOCK):
        buf = io.StringIO()
        np.savetxt(buf, make(lo, min(n, lo + BLOCK), rng), delimiter=delimiter, fmt=fmt)
        f.write(buf.getvalue().replace(f"{delimiter}nan", delimiter))


def _write_file(
    path: Path, header: list[str], n: int, make: Callable[[int, int, np.random.Generator], np.ndarray], fmt, delim: str
) -> Path:
    """``header`` lines, then ``n`` rows of ``make`` (:func:`_write_rows`); returns ``path``."""
    with open(path, "w") as f:
        f.write("\n".join(header) + "\n")
        _write_rows(f, n, make, fmt, delim)
    return path


def _marker_rows(
    lo: int, hi: int, rng: np.random.Generator, markers: int, missing: tuple[int, float], rate_hz: float = 100.0
) -> np.ndarray:
    """Frame (from 1), time (s) and x, y, z (mm) of ``markers`` markers; ``missing``: (every k-th row, the value
    the first marker then has: 0 as QTM writes it, or NaN, an empty cell)."""
    mm = rng.normal(0, 400, (hi - lo, 3 * markers))
    every, value = missing
    mm[::every, :3] = value
    return np.column_stack([np.arange(lo, hi) + 1, np.arange(lo, hi) / rate_hz, mm])


def motive_csv(folder: Path, n: int, markers: int = 4) -> Path:
    path = folder / "take.csv"
    header = motive_header(n, markers)

    def make(lo: int, hi: int, rng: np.random.Generator) -> np.ndarray:
        q = rng.normal(0, 1, (hi - lo, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        pos = rng.normal(0, 1, (hi - lo, 3 * markers))
        pos[np.repeat(rng.random((hi - lo, markers)) < 0.01, 3, axis=1)] = np.nan  # occluded
        frames = np.arange(lo, hi)
        return np.column_stack([frames, frames / 120.0, q, rng.normal(0, 1, (hi - lo, 3)), pos])

    return _write_file(path, header, n, make, ["%d", "%.6f"] + ["%.6f"] * (7 + 3 * markers), ",")


def qualisys_tsv(folder: Path, n: int, markers: int = 8) -> Path:
    path = folder / "walk_3d.tsv"
    names = [f"M{m}" for m in range(markers)]
    header = [
        f"NO_OF_FRAMES\t{n}",
        "NO_OF_CAMERAS\t8",
        f"NO_OF_MARKERS\t{markers}",
        "FREQUENCY\t100",
        "NO_OF_ANALOG\t0",
        "ANALOG_FREQUENCY\t0",
        "DESCRIPTION\t--",
        "TIME_STAMP\t2021-06-30, 10:12:59.345\t81234.56",
        "DATA_INCLUDED\t3D",
        "MARKER_NAMES\t" + "\t".join(names),
        "Frame\tTime\t" + "\t".join(f"{m} {a}" for m in names for a in "XYZ"),
    ]

    def make(lo: int, hi: int, rng: np.random.Generator) -> np.ndarray:
        return _marker_rows(lo, hi, rng, markers, (997, 0.0))  # QTM's missing marker: 0.000 0.000 0.000

    return _write_file(path, header, n, make, ["%d", "%.5f"] + ["%.3f"] * (3 * markers), "\t")


def trc(folder: Path, n: int, markers: int = 8) -> Path:
    path = folder / "markers.trc"
    names = [f"M{m}" for m in range(markers)]
    header = [
        "PathFileType\t4\t(X/Y/Z)\tmarkers.trc",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"100\t100\t{n}\t{markers}\tmm\t100\t1\t{n}",
        "Frame#\tTime\t" + "\t".join(f"{m}\t\t" for m in names),
        "\t\t" + "\t".join(f"X{i + 1}\tY{i + 1}\tZ{i + 1}" for i in range(markers)),
        "",
    ]

    def make(lo: int, hi: int, rng: np.random.Generator) -> np.ndarray:
        return _marker_rows(lo, hi, rng, markers, (1009, np.nan))  # a marker missing now and then

    return _write_file(path, header, n, make, ["%d", "%.3f"] + ["%.4f"] * (3 * markers), "\t")


def sto(folder: Path, n: int, imus: int = 3) -> Path:
    path = folder / "orientations.sto"
    names = ["pelvis_imu", "femur_r_imu", "tibia_r_imu"][:imus]
    header = ["DataRate=100.000000", "DataType=Quaternion", "version=3", "OpenSimVersion=4.2", "endheader"]
    header.append("time\t" + "\t".join(names))
    rng = np.random.default_rng(0)
    with open(path, "w") as f:
        f.write("\n".join(header) + "\n")
        for lo in range(0, n, BLOCK):
            m = min(n, lo + BLOCK) - lo
            q = rng.normal(0, 1, (m, imus, 4))
            q /= np.linalg.norm(q, axis=2, keepdims=True)
            buf = io.StringIO()
            fmt = "%.2f" + "".join("\t%.12f,%.12f,%.12f,%.12f" for _ in range(imus))
            np.savetxt(buf, np.column_stack([(lo + np.arange(m)) / 100.0, q.reshape(m, -1)]), fmt=fmt)
            f.write(buf.getvalue())
    return path


def delsys_csv(folder: Path, n: int) -> Path:
    """``n`` rows: the EMG (296.296 Hz) on every row, the IMU (148.148 Hz) on the first half."""
    path = folder / "trigno.csv"
    emg_fs, imu_fs = 296.296296, 148.148148
    n_imu = n // 2
    imu = [f"Avanti sensor 1: {q}.{a} 1" for q in ("ACC", "GYRO") for a in "XYZ"]
    labels = [
        f"Label: Avanti sensor 2: EMG 2 Sampling frequency: {emg_fs:.6e} Number of points: {n} start: 0.000000e+000 "
        "Unit: V Domain Unit: s"
    ] + [
        f"Label: {c} Sampling frequency: {imu_fs:.6e} Number of points: {n_imu} start: 0.000000e+000 "
        f"Unit: {'g' if 'ACC' in c else 'deg/s'} Domain Unit: s"
        for c in imu
    ]
    header = [*labels, "Start Trigger Method: None", "Stop Trigger Method: None", ""]
    header.append(",".join(f'X[s],"{c}"' for c in ["Avanti sensor 2: EMG 2", *imu]))

    def make(lo: int, hi: int, rng: np.random.Generator) -> np.ndarray:
        rows = np.arange(lo, hi)
        out = np.full((hi - lo, 14), np.nan)
        out[:, 0], out[:, 1] = rows / emg_fs, rng.normal(0, 1e-4, hi - lo)
        has = rows < n_imu
        for j in range(6):
            out[has, 2 + 2 * j] = rows[has] / imu_fs
            out[has, 3 + 2 * j] = rng.normal(0, 1 if j < 3 else 20, int(has.sum()))
        return out

    return _write_file(path, header, n, make, ["%.6f", "%.7e"] * 7, ",")


def e4_acc(folder: Path, n: int) -> Path:
    path = folder / "ACC.csv"
    with open(path, "w") as f:
        f.write("1680686620.000000, 1680686620.000000, 1680686620.000000\n32.000000, 32.000000, 32.000000\n")
        _write_rows(f, n, lambda lo, hi, rng: rng.integers(-64, 64, (hi - lo, 3)), ["%d"] * 3, ",")
    return path


def actilife_epochs(folder: Path, n: int) -> Path:
    """``n`` epochs of 1 s with Date and Time columns."""
    path = folder / "epochs1s.csv"
    banner = (
        "------------ Data File Created By ActiGraph GT3X+ ActiLife v6.13.3 Firmware v3.2.1 date format M/d/yyyy "
        "at 30 Hz  Filter Normal -----------\nSerial Number: NEO1F12345678\nStart Time 10:00:00\nStart Date 3/4/2021\n"
        "Epoch Period (hh:mm:ss) 00:00:01\nDownload Time 10:00:00\nDownload Date 3/11/2021\n"
        "Current Memory Address: 0\nCurrent Battery Voltage: 4.10     Mode = 61\n"
        "--------------------------------------------------\nDate,Time,Axis1,Axis2,Axis3,Steps,Lux,Vector Magnitude\n"
    )
    t0 = datetime(2021, 3, 4, 10, 0, 0)
    rng = np.random.default_rng(0)
    with open(path, "w") as f:
        f.write(banner)
        for lo in range(0, n, BLOCK):
            hi = min(n, lo + BLOCK)
            counts = rng.integers(0, 900, (hi - lo, 5))
            lines = []
            for i in range(lo, hi):
                t = t0 + timedelta(seconds=i)
                c = counts[i - lo]
                vm = float(np.sqrt(c[0] ** 2 + c[1] ** 2 + c[2] ** 2))
                lines.append(f"{t.month}/{t.day}/{t.year},{t:%H:%M:%S},{c[0]},{c[1]},{c[2]},{c[3]},{c[4]},{vm:.2f}")
            f.write("\n".join(lines) + "\n")
    return path


#: format -> (rows per hour, writer of a file of n rows into a folder, returning the path to convert)
FORMATS: dict[str, tuple[int, Callable[[Path, int], Path]]] = {
    "motive": (432_000, motive_csv),
    "qualisys": (360_000, qualisys_tsv),
    "trc": (360_000, trc),
    "sto": (360_000, sto),
    "delsys": (1_066_667, delsys_csv),
    "e4": (115_200, e4_acc),
    "actilife-epoch": (3_600, actilife_epochs),
}
