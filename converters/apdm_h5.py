"""APDM Opal HDF5 files (formats 3-5), read by h5py in a guarded child process (see imulog.converters.apdm)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._common import estimate_rate_hz
from imulog.converters._lab import ORIENTATION_TOPIC, orientation_stream, trial_start
from imulog.converters.apdm_csv import Sensor, _name
from imulog.converters.bounds import check_epoch_array, read_h5
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording, SignalStream

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
