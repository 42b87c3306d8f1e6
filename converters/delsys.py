"""Delsys Trigno CSV exports (EMGworks / Delsys File Utility): a time column per channel, one IMU per sensor.

Layout::

    Label: Mini sensor 10: EMG 10 Sampling frequency: 1.259259e+003 Number of points: 81141 start: 0.000000e+000
        Unit: V Domain Unit: s                                            (one line per channel)
    ...
    Start Trigger Method: None
    Stop Trigger Method: None
    <blank>
    X[s],Mini sensor 10: EMG 10,X[s],Mini sensor 10: ACC.X 10,...
    0.000000,0,0.000000,0,...

Every channel has its own ``X[s]`` time column (seconds); slower channels end early and the rest of their column is
empty. Per sensor (``<label>: <channel> <number>``): ``EMG`` -> ``/analog/<sensor>`` in V; ``ACC.X/Y/Z`` (g) and
``GYRO.X/Y/Z`` (deg/s) -> ``/imu/<sensor>`` in m/s^2 and rad/s (``MAG.*`` uT); any other channel ->
``/signals/<sensor>`` with the unit as found. Units come from the ``Label:`` lines. Sensors are named from their
label (``Mini sensor 10`` -> ``mini_sensor_10``); ``--device-name 10=wrist`` renames by sensor number or label.

Memory: in pieces of about 16 MB of text (:func:`iter_delsys`), the whole-file ``convert`` being the one-piece case:
the ``Label:`` lines say every channel, rate and unit up front; each channel's time column is checked across pieces
(set on a prefix of the rows); a stream whose channel has ended is left out of later pieces.
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import head_lines, sanitize_name, text_head_lines, unit_factor
from imulog.converters._pieces import PIECE_BYTES, hand_over, iter_table
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import AnalogStream, ImuStream, Recording, SignalStream

_LABEL = re.compile(
    r"^Label:\s*(?P<name>.+?)\s+Sampling frequency:\s*(?P<fs>\S+)\s+Number of points:\s*(?P<n>\d+)\s+"
    r"start:\s*(?P<start>\S+)\s+Unit:\s*(?P<unit>.*?)\s+Domain Unit:\s*(?P<dunit>\S+)"
)
_CHANNEL = re.compile(r"^(?P<sensor>.+):\s*(?P<kind>[A-Za-z]+)(?:\.(?P<axis>[XYZ]))?\s*(?P<number>\d+)?\s*$")
EMG_UNITS = {"v": 1.0, "mv": 1e-3, "uv": 1e-6, "µv": 1e-6}


@dataclass
class Channel:
    name: str
    time_col: int
    value_col: int
    rate_hz: float | None = None
    unit: str = ""
    points: int | None = None


@dataclass
class Sensor:
    label: str
    number: str
    channels: dict[str, Channel] = field(default_factory=dict)  # "EMG", "ACC.X", ...


def _labels(lines: list[str]) -> tuple[dict[str, dict[str, str]], int]:
    """Label-line fields by channel name, and the index of the names row (``X[s],...``)."""
    out: dict[str, dict[str, str]] = {}
    for i, line in enumerate(lines):
        text = line.rstrip().rstrip(",").strip()
        if text.startswith("X[s]") or text.startswith('"X[s]"'):
            return out, i
        m = _LABEL.match(text)
        if m:
            out[m.group("name").strip()] = m.groupdict()
    return out, -1


def read_delsys(path: Path, *, names: dict[str, str] | None = None) -> Recording:
    """The whole export: :func:`iter_delsys` as one piece."""
    (rec,) = iter_delsys(path, names=names, piece_bytes=None)
    return rec


@dataclass
class _Plan:
    """One sensor's streams: its topic name, device record, IMU trios (quantity, axes, factor), EMG, others."""

    name: str
    meta: dict[str, Any]
    imu_meta: dict[str, Any]
    trios: list[tuple[str, str, list[Channel], float]]
    emg: tuple[Channel, float] | None
    others: list[tuple[str, Channel]]


@dataclass
class _Carry:
    """A channel across pieces: the line of its first empty time cell (its end), its last time (ns)."""

    end_line: int | None = None
    last: int | None = None


def iter_delsys(
    path: Path, *, names: dict[str, str] | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """The export in pieces of about ``piece_bytes`` of text (None: one piece), rows read by
    :func:`~imulog.converters._pieces.iter_table`. The header says every channel, rate and unit; each channel's
    column is a prefix of the rows (slower channels end early), checked across pieces: a time set after the
    channel's first empty time cell is an error naming that cell's line. A stream that has ended is left out of
    later pieces (the first piece has every stream)."""
    path = Path(path)
    header, hi, plans = _layout(path, names)
    carry: dict[str, _Carry] = {}
    notes: list[str] = []
    rows = iter_table(path, delimiter=",", skip_lines=hi + 1, names=header, piece_bytes=piece_bytes, warnings=notes)
    for k, (values, first_line) in enumerate(rows):
        column = partial(_column, path, values, first_line, carry)
        rec = Recording(sources=[str(path)])
        for plan in plans:
            _sensor_piece(path, plan, column, rec)
            if k == 0:
                rec.metadata[f"imulog.device.{plan.name}"] = plan.meta
        if k:
            for kind in (rec.imus, rec.analogs, rec.signals):
                kind[:] = [st for st in kind if len(st.t_ns)]
        yield hand_over(notes, rec)


def _column(
    path: Path, values: np.ndarray, first_line: int, carries: dict[str, _Carry], ch: Channel
) -> tuple[np.ndarray, np.ndarray]:
    """(t_ns, values) of one channel in one piece: the rows where its time is set; empty only after its end
    (``carries``: each channel's state from the pieces before)."""
    carry = carries.setdefault(ch.name, _Carry())
    t = values[:, ch.time_col]
    v = values[:, ch.value_col]
    have = np.isfinite(t)
    n = int(have.sum())
    if carry.end_line is not None and n:
        line = carry.end_line  # the channel had ended in an earlier piece
    elif not have[:n].all():
        line = first_line + int(np.argmin(have[:n]))
    else:
        line = None
    if line is not None:
        raise ConversionError(
            path, "empty time cell before the channel's last sample", line=line, column=f"X[s] of {ch.name}"
        )
    if n < len(t) and carry.end_line is None:
        carry.end_line = first_line + n
    bad = ~np.isfinite(v[:n])
    if bad.any():
        i = int(np.argmax(bad))
        raise ConversionError(path, "missing value where the time is set", line=first_line + i, column=ch.name)
    t_ns = np.round(t[:n] * 1e9).astype(np.int64)
    d = np.diff(t_ns if carry.last is None else np.concatenate([[carry.last], t_ns]))
    if np.any(d <= 0):
        i = int(np.argmax(d <= 0)) + (1 if carry.last is None else 0)
        raise ConversionError(path, "time does not increase", line=first_line + i, column=f"X[s] of {ch.name}")
    if n:
        carry.last = int(t_ns[-1])
    return t_ns, v[:n]


def _layout(path: Path, names: dict[str, str] | None) -> tuple[list[str], int, list[_Plan]]:
    """The names row, its index and every sensor's streams, from the ``Label:`` lines (errors name the line)."""
    names = {k.upper(): v for k, v in (names or {}).items()}
    lines = head_lines(path, max_lines=400)
    labels, hi = _labels(lines)
    if hi < 0:
        raise ConversionError(path, "no 'X[s],<channel>,...' names row (header cut off?)", line=len(lines))
    header = next(csv.reader([lines[hi]]))
    header = [c.strip() for c in header]
    while header and header[-1] == "":
        header.pop()
    if len(header) % 2:
        raise ConversionError(path, f"{len(header)} columns: expected pairs of X[s] and a channel", line=hi + 1)
    sensors: dict[str, Sensor] = {}
    for j in range(0, len(header), 2):
        if header[j] != "X[s]":
            raise ConversionError(path, f"column {j + 1} is {header[j]!r}, expected 'X[s]'", line=hi + 1)
        name = header[j + 1]
        lab = labels.get(name, {})
        ch = Channel(name=name, time_col=j, value_col=j + 1, unit=lab.get("unit", "").strip())
        if lab:
            try:
                ch.rate_hz = float(lab["fs"])
            except ValueError:
                raise ConversionError(path, f"{name}: sampling frequency {lab['fs']!r} is not a number") from None
            ch.points = int(lab["n"])
        m = _CHANNEL.match(name)
        if not m:
            key, label, number, kind = name, name, "", "VALUE"
        else:
            label, number = m.group("sensor").strip(), m.group("number") or ""
            kind = m.group("kind").upper() + (f".{m.group('axis')}" if m.group("axis") else "")
            key = label
        sensor = sensors.setdefault(key, Sensor(label=label, number=number))
        if kind in sensor.channels:
            raise ConversionError(path, f"channel {name!r} appears twice", line=hi + 1)
        sensor.channels[kind] = ch
    plans: list[_Plan] = []
    used: set[str] = set()
    for sensor in sensors.values():
        name = sanitize_name(names.get(sensor.number) or names.get(sensor.label.upper()) or sensor.label)
        if name in used:
            raise ConversionError(path, f"two sensors are both named {name!r}", line=hi + 1)
        used.add(name)
        meta: dict[str, Any] = {
            "format": "delsys-trigno-csv",
            "model": f"Delsys Trigno ({sensor.label})",
            "serial": sensor.number,
            "label": sensor.label,
            "source": path.name,
            "channels": {
                k: {"unit": c.unit, "rate_hz": c.rate_hz, "points_in_label": c.points}
                for k, c in sensor.channels.items()
            },
            "time": "per-channel X[s] columns (s)",
        }
        trios: list[tuple[str, str, list[Channel], float]] = []
        for quantity, prefix in (("acc", "ACC"), ("gyr", "GYRO"), ("mag", "MAG")):
            axes = [sensor.channels.get(f"{prefix}.{a}") for a in "XYZ"]
            if not any(axes):
                continue
            if not all(axes):
                raise ConversionError(path, f"sensor {sensor.label}: {prefix} lacks an axis", line=hi + 1)
            unit = axes[0].unit  # type: ignore[union-attr]
            factor = unit_factor(quantity, unit)
            if factor is None:
                raise ConversionError(path, f"{axes[0].name}: unknown unit {unit!r}")  # type: ignore[union-attr]
            trios.append((quantity, prefix, axes, factor))  # type: ignore[arg-type]
            meta.setdefault("units_in_file", {})[quantity] = unit
            meta.setdefault("resolution", {})[quantity] = {"scale": factor}  # the text's decimals x the unit factor
        imu_rate = sensor.channels[f"{trios[0][1]}.X"].rate_hz if trios else None
        emg = None
        if "EMG" in sensor.channels:
            ch = sensor.channels["EMG"]
            f = EMG_UNITS.get(ch.unit.lower())
            if f is None:
                raise ConversionError(path, f"{ch.name}: unknown EMG unit {ch.unit!r}")
            emg = (ch, f)
        others = [
            (k, c) for k, c in sensor.channels.items() if k != "EMG" and not k.startswith(("ACC.", "GYRO.", "MAG."))
        ]
        imu_meta = {**meta, "rate_hz": imu_rate}
        meta["rate_hz"] = max((c.rate_hz or 0.0) for c in sensor.channels.values()) or None
        plans.append(_Plan(name, meta, imu_meta, trios, emg, others))
    if not plans or not any(p.trios or p.emg or p.others for p in plans):
        raise ConversionError(path, "no channels", line=hi + 1)
    return header, hi, plans


def _sensor_piece(path: Path, plan: _Plan, column: Any, rec: Recording) -> None:
    """Append one sensor's streams of one piece to ``rec`` (``column``: a channel's times and values)."""
    imu: dict[str, np.ndarray] = {}
    imu_t: np.ndarray | None = None
    imu_from = ""
    for quantity, prefix, axes, factor in plan.trios:
        cols = [column(c) for c in axes]
        n = min(len(t) for t, _ in cols)
        t0 = cols[0][0][:n]
        for (t, _), c in zip(cols[1:], axes[1:], strict=True):
            if np.max(np.abs(t[:n] - t0), initial=0) > 1000:  # > 1 us apart
                raise ConversionError(path, f"{c.name}: time column differs from {axes[0].name}")
        if imu_t is None:
            imu_t, imu_from = t0, prefix
        elif len(t0) != len(imu_t) or np.max(np.abs(t0[: len(imu_t)] - imu_t), initial=0) > 1000:
            n2 = min(len(t0), len(imu_t))
            if np.max(np.abs(t0[:n2] - imu_t[:n2]), initial=0) > 1000:
                raise ConversionError(path, f"sensor {plan.meta['label']}: {prefix} is not sampled with {imu_from}")
            imu_t = imu_t[:n2]
            for key in imu:
                imu[key] = imu[key][:n2]
            t0 = t0[:n2]
        imu[quantity] = np.stack([v[: len(imu_t)] for _, v in cols], axis=1) * factor
    if imu and imu_t is not None:
        rec.imus.append(ImuStream(name=plan.name, t_ns=imu_t, meta=dict(plan.imu_meta), **imu))
    if plan.emg is not None:
        ch, f = plan.emg
        t_ns, v = column(ch)
        rec.analogs.append(
            AnalogStream(
                name=plan.name,
                t_ns=t_ns,
                channel_names=["EMG"],
                units=["V"],
                values=v[:, None] * f,
                meta={"rate_hz": ch.rate_hz, "unit_in_file": ch.unit, "resolution": {"values": {"scale": f}}},
            )
        )
    for k, c in plan.others:
        t_ns, v = column(c)
        rec.signals.append(SignalStream(f"/signals/{plan.name}_{sanitize_name(k)}", t_ns, [k], [c.unit], v[:, None]))


class DelsysConverter(Converter):
    name = "delsys"
    description = "Delsys Trigno CSV (Label: lines, X[s] time column per channel): EMG -> /analog (V), ACC/GYRO -> /imu"
    extensions = (".csv",)
    example = "imulog convert ../shared/data/devices/delsys_trigno/truncated_trigno_sample.csv -o trigno.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 5)
        if not lines:
            return 0.0
        return 0.95 if lines[0].startswith("Label:") and "Sampling frequency:" in lines[0] else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        return read_delsys(Path(path), names=options.extra.get("names"))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """The export in pieces of about 16 MB of text (see :func:`iter_delsys`)."""
        options = options or ConvertOptions()
        return iter_delsys(Path(path), names=options.extra.get("names"), piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = DelsysConverter()
