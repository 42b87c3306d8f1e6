"""APDM Opal CSV exports (labelled columns, Mobility Lab Format=7) to one IMU stream per sensor (see imulog.converters.apdm).

Both layouts are read in pieces of about 16 MiB of text by :func:`imulog.converters._pieces.iter_table` (the whole
file is the one-piece case): the time checks carry across pieces and the rate estimate (when the file gives none)
is the median step of all times so far, so the last piece's is the whole file's."""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._binary import concat_chunks
from imulog.converters._common import (
    check_increasing,
    estimate_rate_hz,
    sanitize_name,
    unit_factor,
)
from imulog.converters._lab import ORIENTATION_TOPIC, orientation_stream, trial_start
from imulog.converters._pieces import hand_over, iter_table
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording, SignalStream
from imulog.numeric import add_counts, median_of_counts

QUANTITY = {  # APDM quantity name -> (model quantity, SI unit when the file gives none)
    "acceleration": ("acc", "m/s^2"),
    "accelerometer": ("acc", "m/s^2"),
    "angular velocity": ("gyr", "rad/s"),
    "gyroscope": ("gyr", "rad/s"),
    "magnetic field": ("mag", "uT"),
    "magnetometer": ("mag", "uT"),
    "orientation": ("orientation", "1"),
    "temperature": ("temperature", "degC"),
    "pressure": ("pressure", "kPa"),
    "barometer": ("pressure", "kPa"),
}


_AXIS = {"x": 0, "y": 1, "z": 2, "scalar": 0, "s": 0, "w": 0}


_ORIENT_AXIS = {"scalar": 0, "s": 0, "w": 0, "x": 1, "y": 2, "z": 3}


@dataclass
class Sensor:
    """Where one sensor's columns are: quantity -> [column index per axis], with the unit found per quantity."""

    label: str
    case_id: str = ""
    columns: dict[str, list[int | None]] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    extra: list[tuple[str, int, str]] = field(default_factory=list)  # (name, column, unit)


def _name(sensor: Sensor, names: dict[str, str]) -> str:
    for key in (sensor.case_id.upper(), sensor.label.upper()):
        if key and key in names:
            return sanitize_name(names[key])
    return sanitize_name(sensor.label) if sensor.label else f"opal_{sanitize_name(sensor.case_id)}"


def _place(sensor: Sensor, quantity: str, axis: str, col: int) -> bool:
    width = 4 if quantity == "orientation" else 3 if quantity in ("acc", "gyr", "mag") else 1
    idx = (_ORIENT_AXIS if quantity == "orientation" else _AXIS).get(axis.lower())
    if width == 1:
        idx = 0
    if idx is None or idx >= width:
        return False
    slots = sensor.columns.setdefault(quantity, [None] * width)
    slots[idx] = col
    return True


def _build(
    path: Path,
    sensors: list[Sensor],
    t_ns: np.ndarray,
    values: np.ndarray,
    names: dict[str, str],
    header_line: int,
    meta_common: dict[str, Any],
) -> Recording:
    rec = Recording(sources=[str(path)])
    seen_names: set[str] = set()
    for s in sensors:
        name = _name(s, names)
        if name in seen_names:
            raise ConversionError(path, f"two sensors are both named {name!r} (give --device-name CASEID=NAME)")
        seen_names.add(name)
        data: dict[str, np.ndarray] = {}
        units: dict[str, str] = {}
        for quantity, cols in s.columns.items():
            if any(c is None for c in cols):
                missing = "XYZ" if quantity != "orientation" else "SXYZ"
                raise ConversionError(
                    path, f"sensor {s.label or s.case_id}: {quantity} lacks an axis of {missing}", line=header_line
                )
            block = values[:, cols]
            unit = s.units.get(quantity, "")
            if quantity in ("acc", "gyr", "mag", "temperature"):
                factor = unit_factor(quantity, unit) if unit else 1.0
                if factor is None:
                    raise ConversionError(
                        path, f"sensor {s.label}: unknown {quantity} unit {unit!r}", line=header_line + 1
                    )
                block = block * factor
                units[quantity] = unit or QUANTITY_SI[quantity]
            data[quantity] = block
        if not any(q in data for q in ("acc", "gyr")):
            raise ConversionError(path, f"sensor {s.label or s.case_id}: no acceleration or angular velocity columns")
        meta: dict[str, Any] = {
            **meta_common,
            "model": "APDM Opal",
            "serial": s.case_id,
            "label": s.label,
            "rate_hz": meta_common.get("rate_hz") or estimate_rate_hz(t_ns),
            "units": units,
            "source": path.name,
        }
        imu = ImuStream(
            name=name,
            t_ns=t_ns,
            acc=data.get("acc"),
            gyr=data.get("gyr"),
            mag=data.get("mag"),
            temperature=data["temperature"][:, 0] if "temperature" in data else None,
            meta=dict(meta),
        )
        rec.imus.append(imu)
        extra_cols = []
        extra_vals = []
        extra_units = []
        if "pressure" in data:
            extra_cols.append("pressure")
            extra_vals.append(data["pressure"][:, 0])
            extra_units.append(s.units.get("pressure") or "kPa")
        for col_name, col, unit in s.extra:
            extra_cols.append(col_name)
            extra_vals.append(values[:, col])
            extra_units.append(unit)
        if extra_cols:
            rec.signals.append(
                SignalStream(
                    topic=f"/signals/{name}",
                    t_ns=t_ns,
                    columns=extra_cols,
                    units=extra_units,
                    values=np.stack(extra_vals, axis=1),
                )
            )
        if "orientation" in data:
            rec.signals.append(orientation_stream(name, t_ns, data["orientation"]))
            meta["orientation"] = {"topic": ORIENTATION_TOPIC.format(name=name), "from": "APDM Orientation (w,x,y,z)"}
        rec.metadata[f"imulog.device.{name}"] = meta
    return rec


QUANTITY_SI = {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT", "temperature": "degC"}


# ------------------------------------------------------------------------------------------ labelled CSV
def read_labelled_csv(path: Path, lines: list[str], names: dict[str, str]) -> Recording:
    """The ``Test Name:`` / ``Sample Rate:`` / ``Label/Quantity/Axis`` / units-row layout, in one piece."""
    return concat_chunks(iter_labelled_csv(path, lines, names, None))


def iter_labelled_csv(
    path: Path, lines: list[str], names: dict[str, str], piece_bytes: int | None
) -> Iterator[Recording]:
    """:func:`read_labelled_csv` in pieces of about ``piece_bytes`` of text (None: one piece)."""
    info: dict[str, str] = {}
    n = 0
    while n < len(lines) and re.match(r"^[A-Za-z ]+:,", lines[n]):
        cells = lines[n].split(",")
        info[cells[0].rstrip(":").strip()] = ",".join(c for c in cells[1:] if c.strip())
        n += 1
    if n + 1 >= len(lines):
        raise ConversionError(path, "file ends inside the header (names and units rows expected)", line=n + 1)
    header = [c.strip() for c in lines[n].split(",")]
    units_row = [c.strip() for c in lines[n + 1].split(",")]
    units_row += [""] * (len(header) - len(units_row))
    while header and header[-1] == "":
        header.pop()
    if not header or header[0].lower() != "time":
        raise ConversionError(path, "the first column of the names row must be 'Time'", line=n + 1)
    sensors: dict[str, Sensor] = {}
    for j, name in enumerate(header[1:], start=1):
        parts = name.split("/")
        if len(parts) != 3:
            raise ConversionError(path, f"column {j + 1} {name!r} is not <Label>/<Quantity>/<Axis>", line=n + 1)
        label, quantity, axis = (p.strip() for p in parts)
        s = sensors.setdefault(label, Sensor(label=label))
        q = QUANTITY.get(quantity.lower())
        if q is None or not _place(s, q[0], axis, j):
            s.extra.append((f"{quantity}/{axis}", j, units_row[j]))
            continue
        if units_row[j]:
            s.units[q[0]] = units_row[j]
    tunit = units_row[0] or "s"
    factor = unit_factor("time", tunit)
    rate = None
    m = re.search(r"([0-9.]+)", info.get("Sample Rate", ""))
    if m:
        rate = float(m.group(1))
    common = {"format": "apdm-csv", "rate_hz": rate, "time": f"Time column ({tunit} from the start)"}
    if "Test Name" in info:
        common["test_name"] = info["Test Name"]
    t0: float | None = None
    clock = _Clock()
    notes: list[str] = []
    for values, first_line in iter_table(
        path, delimiter=",", skip_lines=n + 2, names=header, required=[0], piece_bytes=piece_bytes, warnings=notes
    ):
        if factor is None:
            raise ConversionError(path, f"unknown time unit {tunit!r}", line=n + 2, column="Time")
        t = values[:, 0]
        if t0 is None and len(t):
            t0 = float(t[0])
        t_ns = (np.round((t - t0) * factor) + round(t0 * factor)).astype(np.int64) if len(t) else t.astype(np.int64)
        estimate = clock.add(path, t_ns, first_line)
        rec = _build(path, list(sensors.values()), t_ns, values, names, n + 1, {**common, "rate_hz": rate or estimate})
        yield hand_over(notes, rec)


class _Clock:
    """The time checks and rate estimate of the whole file, piece by piece: every time after the one before (the
    previous piece's last included), the median step of all times so far (the last piece's: the whole file's)."""

    def __init__(self) -> None:
        self.before: int | None = None
        self.steps: dict[int, int] = {}

    def add(self, path: Path, t_ns: np.ndarray, first_line: int) -> float | None:
        check_increasing(path, t_ns, first_line, "Time", before=self.before)
        if len(t_ns):
            add_counts(self.steps, np.diff(t_ns if self.before is None else np.concatenate([[self.before], t_ns])))
            self.before = int(t_ns[-1])
        step = median_of_counts(self.steps)
        return 1e9 / step if step is not None and step > 0 else None  # as estimate_rate_hz of every time


# ------------------------------------------------------------------------------------------ Format=7 CSV
def read_format7(path: Path, lines: list[str], names: dict[str, str]) -> Recording:
    """Mobility Lab ``Format=7``: case-ID/label row, quantity row, axis row, time in us since the Unix epoch; one
    piece."""
    return concat_chunks(iter_format7(path, lines, names, None))


def iter_format7(path: Path, lines: list[str], names: dict[str, str], piece_bytes: int | None) -> Iterator[Recording]:
    """:func:`read_format7` in pieces of about ``piece_bytes`` of text (None: one piece)."""
    if len(lines) < 4:
        raise ConversionError(path, "file ends inside the 3 header rows", line=len(lines))
    rows = [[c.strip() for c in lines[i].split(",")] for i in range(3)]
    width = max(len(r) for r in rows)
    for r in rows:
        r += [""] * (width - len(r))
    if rows[1][0].lower() != "time":
        raise ConversionError(path, "the quantity row must start with 'Time'", line=2)
    sensors: list[Sensor] = []
    current: Sensor | None = None
    quantity = ""
    baro: dict[int, Sensor] = {}
    for j in range(1, width):
        top = rows[0][j]
        if re.fullmatch(r"\d+|[A-Z]{2}-\d+", top):
            current = Sensor(label="", case_id=top)
            sensors.append(current)
        elif top and current is not None and not current.label:
            current.label = top
        if rows[1][j]:
            quantity = rows[1][j]
        if current is None:
            raise ConversionError(path, f"column {j + 1} belongs to no sensor (no case ID before it)", line=1)
        q = QUANTITY.get(quantity.lower())
        axis = rows[2][j] or "scalar"
        if q is None or not _place(current, q[0], axis, j):
            current.extra.append((f"{quantity}/{axis}" if rows[2][j] else quantity, j, ""))
        elif q[0] == "pressure":
            baro[j] = current
    if not sensors:
        raise ConversionError(path, "no case IDs in the first row", line=1)
    header = ["Time"] + [f"{rows[1][j] or '?'}/{rows[2][j]}" for j in range(1, width)]
    clock = _Clock()
    quirk = False
    start = None
    notes: list[str] = []
    for values, first_line in iter_table(
        path, delimiter=",", skip_lines=3, names=header, required=[0], piece_bytes=piece_bytes, warnings=notes
    ):
        for j in baro:
            col = values[:, j]
            big = np.isfinite(col) & (np.abs(col) > 1e15)
            if big.any():  # the bit pattern of a double printed as an integer: reinterpret it
                bits = np.zeros(len(col), dtype=np.int64)
                bits[big] = np.round(col[big]).astype(np.int64)
                col = np.where(big, bits.view(np.float64), col)
                values[:, j] = col
                quirk = True
        us = values[:, 0]
        if np.any(us < 0) or np.any(us > 2**62 / 1000):
            i = int(np.argmax((us < 0) | (us > 2**62 / 1000)))
            raise ConversionError(
                path, f"time {us[i]:.0f} is not microseconds since 1970", line=first_line + i, column="Time"
            )
        t_ns = np.round(us).astype(np.int64) * 1000
        common: dict[str, Any] = {
            "format": "apdm-format7",
            "rate_hz": clock.add(path, t_ns, first_line),
            "time": "Time column: microseconds since the Unix epoch (UTC), kept as the device clock",
            "units_note": "no units row: APDM's SI units m/s^2, rad/s, uT, kPa",
        }
        if quirk:
            common["barometer_quirk"] = "Barometer cells hold the int64 bit pattern of a double; reinterpreted (kPa)"
        rec = _build(path, sensors, t_ns, values, names, 2, common)
        if start is None and len(us):
            us0 = int(round(us[0]))
            start = datetime.fromtimestamp(us0 // 1_000_000, tz=UTC) + timedelta(microseconds=us0 % 1_000_000)
        if start is not None:
            rec.metadata["imulog.trial"] = trial_start(
                start, f"{path.name}: Time column (us since the Unix epoch, UTC)"
            )
        yield hand_over(notes, rec)
