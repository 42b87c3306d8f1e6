"""APDM Opal exports (Mobility Lab / Motion Studio): two CSV layouts and the HDF5 file; one IMU stream per sensor.

CSV with labelled columns (what OpenSim's ``APDMDataReader`` reads)::

    Test Name:,Pendulum Test 01
    Sample Rate:,128,Hz
    Time,Static/Acceleration/X,...,Static/Orientation/Scalar,...,Static/Temperature/Scalar,Static/Pressure/Scalar,...
    s,m/s^2,...,rad/s,...,uT,...,(blank for the quaternion),deg C,kPa

Time in seconds from the start; units from the units row.

CSV ``Format=7`` (Mobility Lab)::

    Format=7,<case ID>,,,<Label>,...        14 columns per sensor
    Time,Accelerometer,,,Gyroscope,,,Magnetometer,,,Barometer,Orientation,,,
    ,X,Y,Z,X,Y,Z,X,Y,Z,,S,X,Y,Z

Time in microseconds since the Unix epoch (UTC) -> the trial's start time. No units row: APDM's SI units (m/s^2,
rad/s, uT, kPa). The Barometer column of these exports holds the IEEE-754 bit pattern of the double printed as an
integer (``4636858284341460992.000000`` is 101.72 kPa); it is reinterpreted.

HDF5 (``.h5``, the layouts scikit-digital-health and APDM's documentation read): format 5 ``/Sensors/<case ID>/``
``Accelerometer`` (N, 3) m/s^2, ``Gyroscope`` rad/s, ``Magnetometer`` uT, ``Temperature`` degC, ``Barometer`` kPa,
``Time`` (N,) microseconds since the Unix epoch (UTC), ``Configuration`` attributes ``Label 0``, ``Sample Rate`` and
``Timezone Offset`` (hours); ``/Processed/<case ID>/Orientation`` (N, 4) scalar first. Formats 3-4: root
attributes ``CaseIdList``/``MonitorLabelList``, ``/<case ID>/Time`` and ``/<case ID>/Calibrated/{Accelerometers,
Gyroscopes, Magnetometers, Temperature, Orientation}``, group attribute ``SampleRate``.

Streams are named from the sensor label (``Right Ankle`` -> ``/imu/right_ankle``), else ``opal_<case ID>``;
``--device-name 5718=pelvis`` renames by case ID (or by label). Orientation estimates go to
``/orientation/<name>``, other columns to ``/signals/<name>``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._common import (
    check_increasing,
    estimate_rate_hz,
    head_lines,
    sanitize_name,
    text_head_lines,
    unit_factor,
)
from imulog.converters._lab import ORIENTATION_TOPIC, orientation_stream, read_table, trial_start
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.bounds import check_epoch_array, read_h5
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording, SignalStream

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
READER_TIMEOUT_S = 60.0  # h5py runs in a guarded child: a hang, crash or runaway allocation ends in one line
READER_MEMORY_BYTES = 1 << 30
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
    """The ``Test Name:`` / ``Sample Rate:`` / ``Label/Quantity/Axis`` / units-row layout."""
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
    values = read_table(path, delimiter=",", skip_lines=n + 2, names=header, required=[0])
    tunit = units_row[0] or "s"
    factor = unit_factor("time", tunit)
    if factor is None:
        raise ConversionError(path, f"unknown time unit {tunit!r}", line=n + 2, column="Time")
    t = values[:, 0]
    t_ns = (np.round((t - t[0]) * factor) + round(t[0] * factor)).astype(np.int64)
    check_increasing(path, t_ns, n + 3, "Time")
    rate = None
    m = re.search(r"([0-9.]+)", info.get("Sample Rate", ""))
    if m:
        rate = float(m.group(1))
    common = {"format": "apdm-csv", "rate_hz": rate, "time": f"Time column ({tunit} from the start)"}
    if "Test Name" in info:
        common["test_name"] = info["Test Name"]
    return _build(path, list(sensors.values()), t_ns, values, names, n + 1, common)


# ------------------------------------------------------------------------------------------ Format=7 CSV
def read_format7(path: Path, lines: list[str], names: dict[str, str]) -> Recording:
    """Mobility Lab ``Format=7``: case-ID/label row, quantity row, axis row, time in us since the Unix epoch."""
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
    data = path.read_bytes()
    values = read_table(path, delimiter=",", skip_lines=3, names=header, data=data, required=[0])
    quirk = False
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
        raise ConversionError(path, f"time {us[i]:.0f} is not microseconds since 1970", line=4 + i, column="Time")
    t_ns = np.round(us).astype(np.int64) * 1000
    check_increasing(path, t_ns, 4, "Time")
    common: dict[str, Any] = {
        "format": "apdm-format7",
        "rate_hz": estimate_rate_hz(t_ns),
        "time": "Time column: microseconds since the Unix epoch (UTC), kept as the device clock",
        "units_note": "no units row: APDM's SI units m/s^2, rad/s, uT, kPa",
    }
    if quirk:
        common["barometer_quirk"] = "Barometer cells hold the int64 bit pattern of a double; reinterpreted (kPa)"
    rec = _build(path, sensors, t_ns, values, names, 2, common)
    start = datetime.fromtimestamp(int(round(us[0])) // 1_000_000, tz=UTC) + timedelta(
        microseconds=int(round(us[0])) % 1_000_000
    )
    rec.metadata["imulog.trial"] = trial_start(start, f"{path.name}: Time column (us since the Unix epoch, UTC)")
    return rec


# ------------------------------------------------------------------------------------------------ HDF5
def _text(value: Any) -> str:
    if isinstance(value, bytes | np.bytes_):
        return bytes(value).decode("utf-8", "replace").strip("\x00 ")
    return str(value).strip("\x00 ")


@dataclass
class H5Sensor:
    """Where one sensor's data sets are in an APDM HDF5 file (``paths``: quantity -> data set path)."""

    case_id: str
    label: str
    rate: Any
    tz_hours: Any
    paths: dict[str, str]


def h5_sensors(f: Any) -> tuple[str, list[H5Sensor]]:
    """The sensors of an APDM HDF5 file, in either layout: (layout name, sensors).

    * format 5 (Mobility Lab 2): ``/Sensors/<id>/{Time, Accelerometer, Gyroscope, Magnetometer, Temperature,
      Barometer}``, ``/Sensors/<id>/Configuration`` attributes ``Label 0``, ``Sample Rate``, ``Timezone Offset``,
      ``/Processed/<id>/Orientation``;
    * formats 3-4 (Motion Studio, Mobility Lab 1): root attributes ``CaseIdList``, ``MonitorLabelList``,
      ``/<id>/Time``, ``/<id>/Calibrated/{Accelerometers, Gyroscopes, Magnetometers, Temperature, Orientation}``,
      group attribute ``SampleRate``.
    """
    if "Sensors" in f:
        out = []
        for cid in sorted(f["Sensors"]):
            g = f["Sensors"][cid]
            cfg = dict(g["Configuration"].attrs) if "Configuration" in g else {}
            base = f"/Sensors/{cid}"
            paths = {
                q: f"{base}/{k}"
                for k, q in (
                    ("Time", "time"),
                    ("Accelerometer", "acc"),
                    ("Gyroscope", "gyr"),
                    ("Magnetometer", "mag"),
                    ("Temperature", "temperature"),
                    ("Barometer", "pressure"),
                )
            }
            paths["orientation"] = f"/Processed/{cid}/Orientation"
            label = _text(cfg.get("Label 0", b""))
            out.append(H5Sensor(str(cid), label, cfg.get("Sample Rate"), cfg.get("Timezone Offset"), paths))
        return "apdm-h5 (format 5: /Sensors)", out
    ids = [_text(x) for x in np.atleast_1d(f.attrs.get("CaseIdList", []))]
    labels = [_text(x) for x in np.atleast_1d(f.attrs.get("MonitorLabelList", []))]
    if not ids:
        ids = sorted(k for k in f if hasattr(f[k], "keys") and "Calibrated" in f[k])
    out = []
    for i, cid in enumerate(ids):
        base = f"/{cid}"
        paths = {"time": f"{base}/Time"}
        for k, q in (
            ("Accelerometers", "acc"),
            ("Gyroscopes", "gyr"),
            ("Magnetometers", "mag"),
            ("Temperature", "temperature"),
            ("Barometer", "pressure"),
            ("Orientation", "orientation"),
        ):
            paths[q] = f"{base}/Calibrated/{k}"
        rate = f[base].attrs.get("SampleRate") if base in f else None
        out.append(H5Sensor(cid, labels[i] if i < len(labels) else "", rate, None, paths))
    return "apdm-h5 (format 3-4: /<case ID>/Calibrated)", out


def read_apdm_h5(path: Path, names: dict[str, str]) -> Recording:
    """An APDM HDF5 file (see :func:`h5_sensors` for both layouts): one IMU per sensor, its orientation estimate.
    h5py reads it in a guarded child process (time and memory limit, :mod:`imulog.converters._guard`)."""
    from imulog.converters._guard import guarded_reader

    return guarded_reader(
        path, "h5py", _read_apdm_h5_checked, path, names, timeout_s=READER_TIMEOUT_S, memory_bytes=READER_MEMORY_BYTES
    )


def _read_apdm_h5_checked(path: Path, names: dict[str, str]) -> Recording:
    try:
        return _read_apdm_h5(path, names)
    except ConversionError:
        raise
    except (OSError, RuntimeError, KeyError, TypeError, ValueError) as e:  # h5py on a damaged file
        raise ConversionError(path, f"damaged HDF5 file: {e}") from None


def _read_apdm_h5(path: Path, names: dict[str, str]) -> Recording:
    try:
        import h5py
    except ImportError:  # pragma: no cover - h5py is in the hdf5 extra
        raise ConversionError(path, "reading APDM HDF5 needs h5py: pip install 'imulog[hdf5]'") from None

    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise ConversionError(path, f"not a readable HDF5 file (cut off or damaged?): {e}") from None
    widths = {"acc": 3, "gyr": 3, "mag": 3, "orientation": 4, "temperature": 1, "pressure": 1}
    with f:
        try:
            layout, sensors = h5_sensors(f)
        except (KeyError, OSError, RuntimeError, TypeError, ValueError) as e:
            raise ConversionError(path, f"cannot read the sensor list ({e})") from None
        if not sensors:
            raise ConversionError(path, "no sensors (/Sensors/<id> or CaseIdList): not an APDM HDF5 file")
        rec = Recording(sources=[str(path)])
        starts = []
        for sensor in sensors:
            where = sensor.paths["time"].rsplit("/", 1)[0]
            data: dict[str, np.ndarray] = {}
            try:
                if sensor.paths["time"] not in f:
                    raise ConversionError(path, f"{sensor.paths['time']} is missing")
                raw_us = read_h5(path, f[sensor.paths["time"]], sensor.paths["time"]).reshape(-1)
                n = len(raw_us)
                if n == 0:
                    raise ConversionError(path, f"{sensor.paths['time']} is empty")
                if raw_us.dtype.kind not in "iuf":
                    raise ConversionError(path, f"{sensor.paths['time']} holds {raw_us.dtype} values, not times")
                # checked before the conversion to int64 ns: uint64 values near 2^64 must not wrap to 1969
                check_epoch_array(path, sensor.paths["time"], raw_us.astype(np.float64) * 1000.0)
                us = raw_us.astype(np.int64)
                for q, width in widths.items():
                    p = sensor.paths.get(q)
                    if p is None or p not in f:
                        continue
                    a = read_h5(path, f[p], p, dtype=np.float64)
                    if width == 1:
                        a = a.reshape(-1)
                    if a.shape != ((n,) if width == 1 else (n, width)):
                        raise ConversionError(path, f"{p} has shape {a.shape}, Time has {n} samples")
                    data[q] = a
            except (KeyError, OSError, RuntimeError, TypeError, ValueError) as e:
                if isinstance(e, ConversionError):
                    raise
                raise ConversionError(path, f"{where}: cannot read ({e})") from None
            bad = np.nonzero(np.diff(us) <= 0)[0]
            if len(bad):
                raise ConversionError(path, f"{where}/Time does not increase at sample {int(bad[0]) + 1}")
            if "acc" not in data and "gyr" not in data:
                raise ConversionError(path, f"{where}: no accelerometer or gyroscope data set")
            t_ns = us * 1000
            name = _name(Sensor(label=sensor.label, case_id=sensor.case_id), names)
            if f"imulog.device.{name}" in rec.metadata:
                raise ConversionError(path, f"two sensors are both named {name!r} (give --device-name CASEID=NAME)")
            meta: dict[str, Any] = {
                "format": layout,
                "model": "APDM Opal",
                "serial": sensor.case_id,
                "label": sensor.label,
                "rate_hz": float(np.asarray(sensor.rate).reshape(-1)[0])
                if sensor.rate is not None
                else estimate_rate_hz(t_ns),
                "units": {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT", "temperature": "degC", "pressure": "kPa"},
                "time": "Time data set: microseconds since the Unix epoch (UTC), kept as the device clock",
                "source": path.name,
            }
            rec.imus.append(
                ImuStream(
                    name=name,
                    t_ns=t_ns,
                    acc=data.get("acc"),
                    gyr=data.get("gyr"),
                    mag=data.get("mag"),
                    temperature=data.get("temperature"),
                    meta=dict(meta),
                )
            )
            if "pressure" in data:
                rec.signals.append(
                    SignalStream(f"/signals/{name}", t_ns, ["pressure"], ["kPa"], data["pressure"][:, None])
                )
            if "orientation" in data:
                rec.signals.append(orientation_stream(name, t_ns, data["orientation"]))
                meta["orientation"] = {
                    "topic": ORIENTATION_TOPIC.format(name=name),
                    "from": sensor.paths["orientation"],
                }
            rec.metadata[f"imulog.device.{name}"] = meta
            starts.append((int(us[0]), sensor.tz_hours))
    us0, tz_hours = min(starts, key=lambda s: s[0])
    zone = UTC
    if tz_hours is not None:
        try:
            zone = timezone(timedelta(hours=float(np.asarray(tz_hours).reshape(-1)[0])))
        except (TypeError, ValueError):
            zone = UTC
    start = (datetime.fromtimestamp(us0 // 1_000_000, tz=UTC) + timedelta(microseconds=us0 % 1_000_000)).astimezone(
        zone
    )
    source = "Time (UTC) and Timezone Offset" if tz_hours is not None else "Time (UTC)"
    rec.metadata["imulog.trial"] = trial_start(start, f"{path.name}: {source}")
    return rec


def _is_apdm_h5(path: Path) -> bool:
    import h5py

    with h5py.File(path, "r") as f:
        if "Sensors" in f:
            return any("Time" in f["Sensors"][k] for k in f["Sensors"])
        return "CaseIdList" in f.attrs


class ApdmConverter(Converter):
    name = "apdm"
    description = "APDM Opal: labelled CSV (Label/Quantity/Axis + units row), Mobility Lab Format=7 CSV, HDF5 (.h5)"
    extensions = (".csv", ".h5")
    example = "imulog convert ../shared/data/devices/apdm_csv/imuData01.csv -o apdm.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        if head.startswith(HDF5_MAGIC):
            try:
                return 0.95 if _is_apdm_h5(path) else 0.0
            except Exception:  # noqa: BLE001 - cut-off HDF5: the HDF5 converters report it
                return 0.0
        lines = text_head_lines(head, 5)
        if not lines:
            return 0.0
        if lines[0].startswith("Format=") and len(lines) > 1 and lines[1].startswith("Time,"):
            return 0.95
        if lines[0].startswith("Test Name:") and any(re.search(r"/Acceleration/[XYZ]", x) for x in lines[1:4]):
            return 0.95
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        names = {k.upper(): v for k, v in (options.extra.get("names") or {}).items()}
        path = Path(path)
        with open(path, "rb") as fh:
            magic = fh.read(8)
        if magic == HDF5_MAGIC:
            return read_apdm_h5(path, names)
        lines = head_lines(path, max_lines=8)
        if lines[0].startswith("Format="):
            return read_format7(path, lines, names)
        return read_labelled_csv(path, lines, names)


CONVERTER = ApdmConverter()
