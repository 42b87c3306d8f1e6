"""APDM Opal HDF5 files (formats 3-5) in pieces of about 16 MiB of samples (see imulog.converters.apdm).

h5py runs in guarded child processes (:mod:`imulog.converters._h5pieces`): one scans the file (every check, the
rate from all the times when the file gives none), one reads each piece's rows; the whole file is the one-piece
case (:func:`read_apdm_h5`)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _h5pieces
from imulog.converters._binary import concat_chunks
from imulog.converters._h5pieces import (
    PIECE_BYTES,
    H5Messages,
    declared_spans,
    guarded_h5,
    row_ranges,
    scan_slices,
)
from imulog.converters._lab import ORIENTATION_TOPIC, orientation_stream, trial_start
from imulog.converters.apdm_csv import Sensor, _name
from imulog.converters.bounds import check_epoch_array, check_h5_size, read_h5
from imulog.converters.errors import ConversionError

from imulog.model import PIECES_RECORD, ImuStream, Recording, SignalStream
from imulog.numeric import add_counts, median_of_counts

HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"


READER_TIMEOUT_S = 60.0  # h5py runs in a guarded child: a hang, crash or runaway allocation ends in one line


READER_MEMORY_BYTES = 1 << 30


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


WIDTHS = {"acc": 3, "gyr": 3, "mag": 3, "orientation": 4, "temperature": 1, "pressure": 1}


@dataclass
class SensorLayout:
    """One sensor as the scan found it: where its data sets are, its samples, its stream name, the quantities
    present, its rate (the ``Sample Rate`` attribute, else the median step of all its times) and first time (us)."""

    sensor: H5Sensor
    n: int
    name: str
    quantities: list[str]
    rate_hz: float | None
    us0: int
    us_last: int


def read_apdm_h5(path: Path, names: dict[str, str]) -> Recording:
    """An APDM HDF5 file (see :func:`h5_sensors` for both layouts): one IMU per sensor, its orientation estimate;
    the pieces of :func:`iter_apdm_h5` joined (each piece's rows read in a guarded child of its own, so a long file
    is not refused by the child's memory cap)."""
    return concat_chunks(iter_apdm_h5(path, names, piece_bytes=_h5pieces.PIECE_BYTES))


def iter_apdm_h5(path: Path, names: dict[str, str], piece_bytes: int | None = PIECE_BYTES) -> Iterator[Recording]:
    """An APDM HDF5 file in pieces of about ``piece_bytes`` of samples (None: the whole file). h5py runs in guarded
    child processes (time and memory limit, :mod:`imulog.converters._guard`): one scans the file (:func:`_scan`:
    every check the whole file's reading makes, times read in slices), one reads each piece's rows."""
    path = Path(path)
    layout, sensors = _guarded(path, _scan, names)
    starts = [(s.us0, s.sensor.tz_hours) for s in sensors]
    trial = _trial(path, starts)
    metas = {s.name: _meta(path, layout, s) for s in sensors}
    row_bytes = 8 * sum(1 + sum(WIDTHS[q] for q in s.quantities) for s in sensors)
    for a, b in row_ranges(max(s.n for s in sensors), row_bytes, piece_bytes):
        rows = _guarded(path, _rows, sensors, a, b)
        rec = Recording(sources=[str(path)])
        for s in sensors:
            if s.name not in rows:
                continue
            us, data = rows[s.name]
            t_ns = us * 1000
            meta = dict(metas[s.name])
            stream_meta = {k: v for k, v in meta.items() if k != "orientation"}
            rec.imus.append(
                ImuStream(
                    name=s.name,
                    t_ns=t_ns,
                    acc=data.get("acc"),
                    gyr=data.get("gyr"),
                    mag=data.get("mag"),
                    temperature=data.get("temperature"),
                    meta=stream_meta,
                )
            )
            if "pressure" in data:
                rec.signals.append(
                    SignalStream(f"/signals/{s.name}", t_ns, ["pressure"], ["kPa"], data["pressure"][:, None])
                )
            if "orientation" in data:
                rec.signals.append(orientation_stream(s.name, t_ns, data["orientation"]))
            rec.metadata[f"imulog.device.{s.name}"] = meta
        rec.metadata["imulog.trial"] = dict(trial)
        if a == 0:  # every stream's span, known from the scan (the time axis and the recording's length)
            last = {s.name: s.us_last * 1000 for s in sensors}
            rec.metadata[PIECES_RECORD] = declared_spans(rec, lambda topic, last=last: last[topic.rsplit("/", 1)[1]])
        yield rec


def _meta(path: Path, layout: str, s: SensorLayout) -> dict[str, Any]:
    """The device record of one sensor (its IMU stream's meta is the same without ``orientation``)."""
    meta: dict[str, Any] = {
        "format": layout,
        "model": "APDM Opal",
        "serial": s.sensor.case_id,
        "label": s.sensor.label,
        "rate_hz": s.rate_hz,
        "units": {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT", "temperature": "degC", "pressure": "kPa"},
        "time": "Time data set: microseconds since the Unix epoch (UTC), kept as the device clock",
        "source": path.name,
    }
    if "orientation" in s.quantities:
        meta["orientation"] = {"topic": ORIENTATION_TOPIC.format(name=s.name), "from": s.sensor.paths["orientation"]}
    return meta


def _trial(path: Path, starts: list[tuple[int, Any]]) -> dict[str, Any]:
    """The ``imulog.trial`` record: the earliest sensor's first time, in the zone of its ``Timezone Offset``."""
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
    return trial_start(start, f"{path.name}: {source}")


#: how h5py's failures on an APDM file are worded
WORDS = H5Messages(
    opened="not a readable HDF5 file (cut off or damaged?): {e}",
    damaged="damaged HDF5 file: {e}",
    open_errors=(OSError,),
    errors=(OSError, RuntimeError, KeyError, TypeError, ValueError),
)


def _guarded(path: Path, fn, *args):
    """``fn(open file, path, *args)`` in the guarded child (the module's time and memory limits)."""
    return guarded_h5(path, fn, *args, words=WORDS, timeout_s=READER_TIMEOUT_S, memory_bytes=READER_MEMORY_BYTES)


def _scan(f: Any, path: Path, names: dict[str, str]) -> tuple[str, list[SensorLayout]]:
    """The file's sensors, checked as the whole file's reading checks them, in the same order: Time present, not
    empty, numeric, in 1970-2100 and increasing (read in slices), every data set's declared size and shape, an
    accelerometer or gyroscope, distinct names; the rate from the ``Sample Rate`` attribute or all the steps."""
    try:
        layout, sensors = h5_sensors(f)
    except (KeyError, OSError, RuntimeError, TypeError, ValueError) as e:
        raise ConversionError(path, f"cannot read the sensor list ({e})") from None
    if not sensors:
        raise ConversionError(path, "no sensors (/Sensors/<id> or CaseIdList): not an APDM HDF5 file")
    out: list[SensorLayout] = []
    for sensor in sensors:
        where = sensor.paths["time"].rsplit("/", 1)[0]
        try:
            n, us0, us_last, steps, quantities = _scan_sensor(f, path, sensor, where)
        except (KeyError, OSError, RuntimeError, TypeError, ValueError) as e:
            if isinstance(e, ConversionError):
                raise
            raise ConversionError(path, f"{where}: cannot read ({e})") from None
        if "acc" not in quantities and "gyr" not in quantities:
            raise ConversionError(path, f"{where}: no accelerometer or gyroscope data set")
        name = _name(Sensor(label=sensor.label, case_id=sensor.case_id), names)
        if any(s.name == name for s in out):
            raise ConversionError(path, f"two sensors are both named {name!r} (give --device-name CASEID=NAME)")
        if sensor.rate is not None:
            rate = float(np.asarray(sensor.rate).reshape(-1)[0])
        else:
            step = median_of_counts(steps)
            rate = 1e9 / step if step is not None and step > 0 else None  # as estimate_rate_hz of every time
        out.append(SensorLayout(sensor, n, name, quantities, rate, us0, us_last))
    return layout, out


def _scan_sensor(f: Any, path: Path, sensor: H5Sensor, where: str) -> tuple[int, int, int, dict[int, int], list[str]]:
    """(samples, first and last time in us, step counts in ns when the file gives no rate, quantities present) of
    one sensor."""
    tpath = sensor.paths["time"]
    if tpath not in f:
        raise ConversionError(path, f"{tpath} is missing")
    ds = f[tpath]
    check_h5_size(path, ds, tpath)
    n = int(ds.size)
    if ds.ndim > 1 and int(ds.shape[0]) != n:
        raise ConversionError(path, f"{tpath} has shape {tuple(ds.shape)}, not one time per row")
    if n == 0:
        raise ConversionError(path, f"{tpath} is empty")
    if ds.dtype.kind not in "iuf":
        raise ConversionError(path, f"{tpath} holds {ds.dtype} values, not times")
    for rows in scan_slices(n):  # checked before the conversion to int64 ns: uint64 near 2^64 must not wrap to 1969
        raw = np.asarray(ds[rows]).reshape(-1)
        check_epoch_array(path, tpath, raw.astype(np.float64) * 1000.0, offset=rows.start)
    quantities = []
    for q, width in WIDTHS.items():
        p = sensor.paths.get(q)
        if p is None or p not in f:
            continue
        qs = f[p]
        check_h5_size(path, qs, p)
        shape = (int(qs.size),) if width == 1 else tuple(int(x) for x in qs.shape)
        if shape != ((n,) if width == 1 else (n, width)) or (width == 1 and qs.ndim > 1 and qs.shape[0] != n):
            raise ConversionError(path, f"{p} has shape {shape}, Time has {n} samples")
        quantities.append(q)
    steps: dict[int, int] = {}
    prev: int | None = None
    us0 = 0
    for rows in scan_slices(n):
        us = np.asarray(ds[rows]).reshape(-1).astype(np.int64)
        if prev is None:
            us0 = int(us[0])
        d = np.diff(us) if prev is None else np.diff(np.concatenate([[prev], us]))
        bad = np.nonzero(d <= 0)[0]
        if len(bad):
            at = int(bad[0]) + 1 + (rows.start - 1 if prev is not None else 0)
            raise ConversionError(path, f"{where}/Time does not increase at sample {at}")
        if sensor.rate is None:
            add_counts(steps, d * 1000)
        prev = int(us[-1])
    return n, us0, int(prev), steps, quantities


def _rows(f: Any, path: Path, sensors: list[SensorLayout], a: int, b: int) -> dict[str, tuple[np.ndarray, dict]]:
    """Rows ``[a, b)`` of every sensor that has them: name -> (times in us as int64, quantity -> float64 rows)."""
    out: dict[str, tuple[np.ndarray, dict]] = {}
    for s in sensors:
        if a >= s.n:
            continue
        rows = slice(a, min(b, s.n))
        where = s.sensor.paths["time"].rsplit("/", 1)[0]
        try:
            tpath = s.sensor.paths["time"]
            us = read_h5(path, f[tpath], tpath, rows=rows).reshape(-1).astype(np.int64)
            data = {}
            for q in s.quantities:
                p = s.sensor.paths[q]
                v = read_h5(path, f[p], p, dtype=np.float64, rows=rows)
                data[q] = v.reshape(-1) if WIDTHS[q] == 1 else v
        except (KeyError, OSError, RuntimeError, TypeError, ValueError) as e:
            if isinstance(e, ConversionError):
                raise
            raise ConversionError(path, f"{where}: cannot read ({e})") from None
        out[s.name] = (us, data)
    return out


def _is_apdm_h5(path: Path) -> bool:
    import h5py

    with h5py.File(path, "r") as f:
        if "Sensors" in f:
            return any("Time" in f["Sensors"][k] for k in f["Sensors"])
        return "CaseIdList" in f.attrs
