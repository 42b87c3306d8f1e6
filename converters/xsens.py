"""Xsens MT Manager text exports (one file per sensor; several files of one recording = one trial, one stream each).

Layout (new headers; old ones have ``// Start Time``, ``// Update Rate``, ... and no ``DeviceId``)::

    // General information:
    //  MT Manager version: 2022.2.0
    // Device information:
    //  DeviceId: 00B42D4B
    //  ProductCode: MTW2-3A7G6
    // Device settings:
    //  Filter Profile: human(46.1)
    // Coordinate system: ENU
    PacketCounter<TAB>SampleTimeFine<TAB>...<TAB>Acc_X<TAB>...<TAB>Gyr_X<TAB>...<TAB>Mag_X<TAB>...<TAB>Quat_q0...

Delimiters: tab, semicolon, comma or single spaces (a space export marks an empty field by one more space, so runs
are never collapsed). ``NaN`` and empty cells are gaps (NaN). Units: ``Acc_*`` m/s^2, ``Gyr_*`` rad/s,
``Mag_*`` arbitrary units normalised to the calibration field (kept as a signal, not uT), ``Temperature`` degC.
The device's orientation (``Quat_q0..3`` with q0 = w, else ``Mat[r][c]`` read by name, else Roll/Pitch/Yaw) goes
to ``/orientation/<name>``; ``UTC_*`` columns date the trial.

Time: ``SampleTimeFine`` (10 kHz ticks, unsigned 32 bit, unwrapped) when every row has it; otherwise the
``PacketCounter`` (16 bit, wraps from 65535 to 0, unwrapped; lost packets leave gaps) divided by the update rate
(100 Hz, said out loud, when the file gives none and ``--rate`` is not set). The serial is the header's
``DeviceId``, else the last 8 hex digits of ``MT_<master>_<trial>-000_<DeviceId>.txt``; the stream is named
``mt_<serial>`` unless ``options.extra["names"]`` maps the serial to a name.

Memory: read whole, not yet in pieces (issue 24): MT Manager exports of one session per sensor file.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._common import (
    check_increasing,
    estimate_rate_hz,
    head_lines,
    is_number,
    sanitize_name,
    split_row,
    text_head_lines,
)
from imulog.converters._lab import ORIENTATION_TOPIC, orientation_stream, read_table, trial_start
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording, SignalStream
from imulog.process import quaternion

TICKS_PER_S = 10_000  # SampleTimeFine resolution
DEFAULT_RATE_HZ = 100.0  # used (and recorded as assumed) when neither the header nor SampleTimeFine times a file
SIGNAL_UNITS = {
    "quat": "1",
    "roll": "deg",
    "pitch": "deg",
    "yaw": "deg",
    "freeacc": "m/s^2",
    "mag": "a.u.",
    "pressure": "Pa",
}


def unwrap_counter(values: np.ndarray, modulus: int) -> tuple[np.ndarray, int | None, str]:
    """Unwrap a wrapping counter; returns (unwrapped int64, index of first bad step or None, problem)."""
    c = values.astype(np.int64)
    d = np.diff(c)
    d = np.where(d < 0, d + modulus, d)
    bad = np.nonzero((d <= 0) | (d > modulus // 2))[0]
    if len(bad):
        i = int(bad[0])
        problem = "duplicated" if c[i + 1] == c[i] else "goes backwards or jumps more than half its range"
        return c, i + 1, problem
    return np.concatenate([[c[0]], c[0] + np.cumsum(d)]), None, ""


def _check_counter(path: Path, values: np.ndarray, modulus: int, first_line: int, column: str) -> None:
    bad = ~((values >= 0) & (values < modulus) & (values == np.round(values)))
    if bad.any():
        i = int(np.argmax(bad))
        raise ConversionError(
            path, f"{values[i]:g} is not a counter value in 0..{modulus - 1}", line=first_line + i, column=column
        )


def _header_info(lines: list[str]) -> tuple[dict[str, str], int]:
    info: dict[str, str] = {}
    n = 0
    for line in lines:
        if not line.lstrip().startswith("//"):
            break
        n += 1
        m = re.match(r"^\s*//\s*([^:]+?)\s*:\s*(.*?)\s*$", line)
        if m and m.group(2):
            info[m.group(1).strip()] = m.group(2)
    return info, n


def _delimiter(header_line: str) -> str:
    """Tab, semicolon, comma or (literal, never collapsed) space: the first one the column header uses."""
    for d in ("\t", ";", ","):
        if d in header_line:
            return d
    return " "


_FILE_SERIAL = re.compile(r"[_-]([0-9A-Fa-f]{8})$")
_FILE_KEY = re.compile(r"^(.*?)(?:-\d{3})?[_-][0-9A-Fa-f]{8}$")


def serial_from_name(path: Path) -> str:
    """DeviceId from an MT Manager file name ``MT_<master>_<trial>-000_<DeviceId>.txt`` (the last 8 hex digits)."""
    m = _FILE_SERIAL.search(Path(path).stem)
    return m.group(1).upper() if m else ""


def orientation_wxyz(values: np.ndarray, seen: dict[str, int]) -> tuple[np.ndarray | None, str]:
    """The sensor's orientation (sensor to global, w first) from Quat_q0..q3 (q0 = w), else the rotation matrix
    ``Mat[r][c]`` (exported column-major, read by name), else Roll/Pitch/Yaw (deg, Rz(yaw) Ry(pitch) Rx(roll))."""
    quat = [f"Quat_q{i}" for i in range(4)]
    if all(c in seen for c in quat):
        q = values[:, [seen[c] for c in quat]]
        return q, "Quat_q0..q3 (q0 = w)"
    mat = [f"Mat[{r}][{c}]" for r in (1, 2, 3) for c in (1, 2, 3)]
    if all(c in seen for c in mat):
        r = values[:, [seen[c] for c in mat]].reshape(-1, 3, 3)
        q = np.full((len(r), 4), np.nan)
        ok = np.isfinite(r).all(axis=(1, 2))
        if ok.any():
            q[ok] = quaternion.from_rotation_matrix(r[ok])
        return q, "Mat[r][c] (rotation matrix sensor to global, by element name)"
    euler = ["Roll", "Pitch", "Yaw"]
    if all(c in seen for c in euler):
        rad = np.radians(values[:, [seen[c] for c in euler]])
        half = rad / 2
        cr, cp, cy = np.cos(half).T
        sr, sp, sy = np.sin(half).T
        q = np.stack(
            [
                cy * cp * cr + sy * sp * sr,
                cy * cp * sr - sy * sp * cr,
                cy * sp * cr + sy * cp * sr,
                sy * cp * cr - cy * sp * sr,
            ],
            axis=1,
        )
        return q, "Roll/Pitch/Yaw (deg, Rz(yaw) Ry(pitch) Rx(roll))"
    return None, ""


_UTC = ["UTC_Year", "UTC_Month", "UTC_Day", "UTC_Hour", "UTC_Minute", "UTC_Second"]


def utc_start(values: np.ndarray, seen: dict[str, int], t_ns: np.ndarray) -> datetime | None:
    """The UTC time of the first sample from the UTC_* columns (first row with a valid, fully resolved UTC time,
    minus its offset on the device clock); None when the columns are absent or empty."""
    if not all(c in seen for c in _UTC):
        return None
    cols = values[:, [seen[c] for c in _UTC]]
    ok = np.isfinite(cols).all(axis=1)
    if "UTC_Valid" in seen:
        flags = values[:, seen["UTC_Valid"]]
        ok &= np.isfinite(flags) & ((np.nan_to_num(flags).astype(np.int64) & 0x04) != 0)
    rows = np.flatnonzero(ok)
    for i in rows[:10]:
        y, mo, d, h, mi, sec = (int(v) for v in cols[i])
        nano = values[i, seen["UTC_Nano"]] if "UTC_Nano" in seen and np.isfinite(values[i, seen["UTC_Nano"]]) else 0
        try:
            when = datetime(y, mo, d, h, mi, sec, tzinfo=UTC) + timedelta(microseconds=float(nano) / 1000)
        except ValueError:
            continue
        return when - timedelta(microseconds=int(t_ns[i] - t_ns[0]) / 1000)
    return None


def read_xsens(path: Path, *, names: dict[str, str] | None = None, rate_hz: float | None = None) -> Recording:
    path = Path(path)
    lines = head_lines(path)
    info, n_comment = _header_info(lines)
    if n_comment >= len(lines):
        raise ConversionError(path, "no column header after the // lines", line=n_comment)
    header_line = lines[n_comment]
    delimiter = _delimiter(header_line)
    cols = header_line.split(delimiter) if delimiter != " " else header_line.strip().split(" ")
    cols = [c.strip().strip('"').strip() for c in cols]
    while cols and cols[-1] == "":
        cols.pop()
    if "PacketCounter" not in cols and "SampleTimeFine" not in cols:
        raise ConversionError(path, "no PacketCounter or SampleTimeFine column", line=n_comment + 1)
    seen: dict[str, int] = {}
    for i, c in enumerate(cols):
        if c == "":
            raise ConversionError(path, f"empty column name (column {i + 1})", line=n_comment + 1)
        if c in seen:
            raise ConversionError(path, f"duplicated column {c!r}", line=n_comment + 1)
        seen[c] = i
    first = split_row(lines[n_comment + 1], delimiter) if n_comment + 1 < len(lines) and delimiter != " " else []
    imu_cols = {f"{q}_{a}" for q in ("Acc", "Gyr") for a in "XYZ"}
    text_cols = [
        i for i, c in enumerate(cols) if c not in imu_cols and i < len(first) and first[i] and not is_number(first[i])
    ]
    time_col = "PacketCounter" if "PacketCounter" in seen else "SampleTimeFine"
    notes: list[str] = []  # a cut final row dropped
    values = read_table(
        path,
        delimiter=delimiter,
        skip_lines=n_comment + 1,
        names=cols,
        required=[seen[time_col]],
        skip_columns=text_cols,
        warnings=notes,
    )
    first_line = n_comment + 2
    if not len(values):
        raise ConversionError(path, "no data rows after the header", line=first_line)

    rate = rate_hz
    assumed: list[str] = []
    m = re.search(r"([0-9]+(?:\.[0-9]+)?)", info.get("Update Rate", info.get("Sample rate", "")))
    if rate is None and m:
        rate = float(m.group(1))
    time_source = ""
    t_ns: np.ndarray | None = None
    if "SampleTimeFine" in seen:
        stf = values[:, seen["SampleTimeFine"]]
        if np.isfinite(stf).all():
            _check_counter(path, stf, 2**32, first_line, "SampleTimeFine")
            ticks, bad, problem = unwrap_counter(stf, 2**32)
            if bad is not None:
                raise ConversionError(path, f"SampleTimeFine {problem}", line=first_line + bad, column="SampleTimeFine")
            t_ns = ticks * (1_000_000_000 // TICKS_PER_S)
            time_source = "SampleTimeFine (10 kHz ticks, unwrapped at 2^32)"
    if t_ns is None:
        if "PacketCounter" not in seen:
            raise ConversionError(
                path, "SampleTimeFine has empty cells and there is no PacketCounter", column="SampleTimeFine"
            )
        if not rate:
            rate = DEFAULT_RATE_HZ
            assumed.append(
                f"{path.name}: no '// Update Rate' line and no SampleTimeFine: assumed {DEFAULT_RATE_HZ:g} Hz "
                "for the PacketCounter; pass --rate HZ if the recording used another rate"
            )
        pc = values[:, seen["PacketCounter"]]
        _check_counter(path, pc, 65536, first_line, "PacketCounter")
        counts, bad, problem = unwrap_counter(pc, 65536)
        if bad is not None:
            raise ConversionError(path, f"PacketCounter {problem}", line=first_line + bad, column="PacketCounter")
        t_ns = np.round(counts * (1e9 / rate)).astype(np.int64)
        time_source = f"PacketCounter / {rate:g} Hz (unwrapped at 65535)"
    check_increasing(path, t_ns, first_line)

    serial = info.get("DeviceId") or info.get("Device ID") or serial_from_name(path)
    serial = serial.split()[0].upper() if serial else ""
    names = {k.upper(): v for k, v in (names or {}).items()}
    name = sanitize_name(names.get(serial, f"mt_{serial}" if serial else "xsens"))
    streams: dict[str, np.ndarray] = {}
    for q, key in (("Acc", "acc"), ("Gyr", "gyr")):
        present = [f"{q}_{a}" in seen for a in "XYZ"]
        if any(present) and not all(present):
            missing = [f"{q}_{a}" for a in "XYZ" if f"{q}_{a}" not in seen]
            raise ConversionError(path, f"missing column(s) {', '.join(missing)}", line=n_comment + 1)
        if all(present):
            streams[key] = values[:, [seen[f"{q}_{a}"] for a in "XYZ"]]
    if "Temperature" in seen:
        temp = values[:, seen["Temperature"]]
        if np.isfinite(temp).any():
            streams["temperature"] = temp
    if not streams:
        raise ConversionError(path, "no Acc_X/Y/Z or Gyr_X/Y/Z columns", line=n_comment + 1)
    meta: dict[str, Any] = {
        "format": "xsens",
        "model": info.get("ProductCode", info.get("Product Code", "Xsens MT")),
        "serial": serial,
        "rate_hz": float(rate) if rate else estimate_rate_hz(t_ns),
        "units": {"acc": "m/s^2", "gyr": "rad/s", "mag": "a.u. (normalised to the calibration field)"},
        "time": time_source,
        "source": path.name,
        "header": info,
        "delimiter": {"\t": "tab", ";": "semicolon", ",": "comma", " ": "space"}[delimiter],
    }
    if assumed:
        meta["assumed"] = assumed
    for key in ("Filter Profile", "Firmware Version", "Firmware revision", "Start Time", "Option Flags"):
        if key in info:
            meta[key.lower().replace(" ", "_")] = info[key]
    if "Coordinate system" in info:
        meta["coordinate_system"] = info["Coordinate system"]
    master = re.match(r"^MT_([0-9A-Fa-f]{8})_", path.name)
    if master and master.group(1).upper() != serial:
        meta["master"] = master.group(1).upper()  # the Awinda station / master of this sensor (file name)
    n_gaps = int((~np.isfinite(np.hstack([streams[k] for k in ("acc", "gyr") if k in streams]))).any(axis=1).sum())
    if n_gaps:
        meta["samples_with_gaps"] = n_gaps
    rec = Recording(sources=[str(path)], warnings=[*notes, *assumed])
    rec.imus.append(ImuStream(name=name, t_ns=t_ns, meta=dict(meta), **streams))
    q, q_source = orientation_wxyz(values, seen)
    if q is not None:
        rec.signals.append(orientation_stream(name, t_ns, q))
        meta["orientation"] = {"topic": ORIENTATION_TOPIC.format(name=name), "from": q_source}
    rec.metadata[f"imulog.device.{name}"] = meta
    start = utc_start(values, seen, t_ns)
    if start is not None:
        rec.metadata["imulog.trial"] = trial_start(start, f"{path.name}: UTC_* columns")
    skip = imu_cols | {"PacketCounter", "SampleTimeFine"} | ({"Temperature"} if "temperature" in streams else set())
    extra = [
        (c, i) for c, i in seen.items() if c not in skip and i not in text_cols and np.isfinite(values[:, i]).any()
    ]
    if extra:
        units = [SIGNAL_UNITS.get(c.split("_")[0].lower(), "") for c, _ in extra]
        rec.signals.insert(
            0,
            SignalStream(
                topic=f"/signals/{name}",
                t_ns=t_ns,
                columns=[c for c, _ in extra],
                units=units,
                values=values[:, [i for _, i in extra]],
            ),
        )
    return rec


class XsensConverter(Converter):
    name = "xsens"
    description = "Xsens MT Manager text export (// header; tab, comma, semicolon or space; one file per sensor)"
    extensions = (".txt", ".csv")
    example = "imulog convert ../shared/data/devices/xsens_mtmanager/ -o xsens/"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 60)
        if not lines:
            return 0.0
        if lines[0].startswith(("PacketCounter\t", "PacketCounter,", "PacketCounter;", "PacketCounter ")):
            return 0.8  # exported without the // header lines
        if not lines[0].lstrip().startswith("//"):
            return 0.0
        for line in lines:
            if not line.lstrip().startswith("//"):
                return 0.9 if ("PacketCounter" in line or "SampleTimeFine" in line) else 0.0
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        return read_xsens(Path(path), names=options.extra.get("names"), rate_hz=options.rate_hz)

    def recording_key(self, path: Path) -> str | None:
        """``MT_012005D6_031-000_00B421AF.txt`` -> ``MT_012005D6_031``: the per-sensor files of one recording."""
        m = _FILE_KEY.match(Path(path).stem)
        return m.group(1) if m and m.group(1) else None


CONVERTER = XsensConverter()
