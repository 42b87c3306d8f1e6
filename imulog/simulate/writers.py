"""Writers of the raw export formats a lab would have (what ``imulog convert`` reads).

* BlueBuddy-style delimited IMU text ``<stem>_imu.csv`` and its mapping file
  ``<stem>_imu.mapping.json`` (format ``imulog.mapping/1``, conventions.md); several synchronised
  IMUs in one such file with a sensor row above the names row (the ``arm`` simulator);
* Vicon Nexus trajectories CSV ``<stem>_vicon.csv`` in the layout of a real Nexus export
  (``Trajectories`` line, rate line, ``Subject:Marker`` names, ``Frame,Sub Frame,X,Y,Z``, units
  row ``mm``, rows padded to full width, empty cells for gaps, CRLF line ends);
* raw ADC text ``X=512 Y=498 Z=600`` (Doshi thesis, WiTilt board) for the ``adl`` protocol.

Values are written from exact decimal integers (see :mod:`imulog.simulate.imu_model`), so a
reader recovers every value to the last written digit.
"""

from __future__ import annotations

import io
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from imulog.simulate.imu_model import QuantisedChannel

AXES = ("x", "y", "z")


def _table(columns: list[np.ndarray], formats: list[str], sep: str, newline: str) -> str:
    """Rows of printf-formatted columns; NaN cells are written empty."""
    fmt = sep.join(formats)
    lists = [c.tolist() for c in columns]
    text = newline.join(fmt % row for row in zip(*lists, strict=True)) + newline
    return (
        re.sub(r"(?<![^" + re.escape(sep + newline) + r"])nan(?![^" + re.escape(sep + newline) + r"])", "", text)
        if "nan" in text
        else text
    )


def write_imu_text(
    path: Path, t_dev_ns: np.ndarray, channels: dict[str, QuantisedChannel], device: dict[str, Any]
) -> tuple[Path, Path]:
    """Write ``path`` (comma-separated, time in ms with 3 decimals) and its mapping file beside it."""
    path = Path(path)
    t_us = np.asarray(t_dev_ns, dtype=np.int64) // 1000
    if np.any(np.asarray(t_dev_ns) % 1000):
        raise ValueError("device time stamps must be whole microseconds")
    cols = [t_us // 1000, t_us % 1000]
    formats = ["%d.%03d"]
    names = ["timestamp"]
    mapping_columns: dict[str, dict[str, str]] = {}
    prefix = {"acc": "a", "gyr": "g", "mag": "m"}
    for quantity, ch in channels.items():
        values = ch.file_values
        for k, axis in enumerate(AXES):
            name = prefix[quantity] + axis
            names.append(name)
            cols.append(values[:, k])
            formats.append(f"%.{ch.decimals}f")
            mapping_columns[name] = {"quantity": quantity, "axis": axis, "unit": ch.unit}
    text = ",".join(names) + "\n" + _table(cols, formats, ",", "\n")
    path.write_text(text)
    mapping = {
        "format": "imulog.mapping/1",
        "device": {"name": "wrist", **device},
        "delimiter": ",",
        "time": {"column": "timestamp", "unit": "ms"},
        "columns": mapping_columns,
    }
    mapping_path = path.with_name(path.name[: -len(path.suffix)] + ".mapping.json")
    mapping_path.write_text(json.dumps(mapping, indent=2) + "\n")
    return path, mapping_path


def write_multi_imu_text(
    path: Path,
    t_dev_ns: np.ndarray,
    sensors: dict[str, dict[str, QuantisedChannel]],
    device: dict[str, Any],
) -> tuple[Path, Path]:
    """Several synchronised IMUs in one delimited file (a multi-sensor station's export) + mapping file.

    A sensor row above the names row (``,upper_arm,upper_arm,...,forearm,...`` over
    ``timestamp,ax,ay,...``) gives every sensor's columns; the converter makes one ImuStream per
    sensor, named by that row. The mapping file names the columns ``<sensor>/<column>``
    (e.g. ``upper_arm/ax``); time in ms with 3 decimals as in :func:`write_imu_text`."""
    path = Path(path)
    t_us = np.asarray(t_dev_ns, dtype=np.int64) // 1000
    if np.any(np.asarray(t_dev_ns) % 1000):
        raise ValueError("device time stamps must be whole microseconds")
    cols = [t_us // 1000, t_us % 1000]
    formats = ["%d.%03d"]
    groups, names = [""], ["timestamp"]
    mapping_columns: dict[str, dict[str, str]] = {}
    prefix = {"acc": "a", "gyr": "g", "mag": "m"}
    for sensor, channels in sensors.items():
        if "," in sensor or "/" in sensor:
            raise ValueError(f"sensor name {sensor!r} must not contain ',' or '/'")
        for quantity, ch in channels.items():
            values = ch.file_values
            for k, axis in enumerate(AXES):
                name = prefix[quantity] + axis
                groups.append(sensor)
                names.append(name)
                cols.append(values[:, k])
                formats.append(f"%.{ch.decimals}f")
                mapping_columns[f"{sensor}/{name}"] = {"quantity": quantity, "axis": axis, "unit": ch.unit}
    text = ",".join(groups) + "\n" + ",".join(names) + "\n" + _table(cols, formats, ",", "\n")
    path.write_text(text)
    mapping = {
        "format": "imulog.mapping/1",
        "device": dict(device),
        "delimiter": ",",
        "time": {"column": "timestamp", "unit": "ms"},
        "columns": mapping_columns,
    }
    mapping_path = path.with_name(path.name[: -len(path.suffix)] + ".mapping.json")
    mapping_path.write_text(json.dumps(mapping, indent=2) + "\n")
    return path, mapping_path


def write_nexus_csv(
    path: Path, frames_pos_m: np.ndarray, labels: list[str], rate_hz: float, subject: str, decimals: int
) -> Path:
    """Nexus 'Trajectories' CSV: ``frames_pos_m`` (N, M, 3) m with NaN gaps, written in mm.

    Marker names are ``subject:label`` (Nexus style) or just ``label`` when ``subject`` is empty."""
    path = Path(path)
    n, m, _ = frames_pos_m.shape
    width = 2 + 3 * m
    nl = "\r\n"
    buf = io.StringIO()
    buf.write("Trajectories" + "," * (width - 1) + nl)
    buf.write(f"{rate_hz:g}" + "," * (width - 1) + nl)
    prefix = f"{subject}:" if subject else ""
    buf.write(",," + ",".join(f"{prefix}{lab},," for lab in labels) + nl)
    buf.write("Frame,Sub Frame," + ",".join(["X,Y,Z"] * m) + nl)
    buf.write(",," + ",".join(["mm"] * (3 * m)) + nl)
    cols = [np.arange(1, n + 1)]
    mm = frames_pos_m * 1e3
    for j in range(m):
        for k in range(3):
            cols.append(mm[:, j, k])
    buf.write(_table(cols, ["%d,0"] + [f"%.{decimals}f"] * (3 * m), ",", nl))
    path.write_bytes(buf.getvalue().encode("ascii"))
    return path


def write_adc_text(path: Path, counts: np.ndarray) -> Path:
    """Raw ADC lines ``X=512 Y=498 Z=600`` (tab separated) from (N, 3) integer counts."""
    path = Path(path)
    c = np.asarray(counts, dtype=np.int64)
    path.write_text(_table([c[:, 0], c[:, 1], c[:, 2]], ["X=%d", "Y=%d", "Z=%d"], "\t", "\n"))
    return path
