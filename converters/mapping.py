"""The column mapping file (``imulog.mapping/1``, JSON or TOML) for delimited IMU text whose headers lack units.

Example (``wrist_imu.mapping.json`` beside ``wrist_imu.csv``)::

    {"format": "imulog.mapping/1",
     "device": {"name": "wrist", "model": "BlueBuddy", "serial": "BB-0042", "rate_hz": 115.0,
                "acc_range_g": 16, "gyr_range_dps": 2000},
     "delimiter": ",",
     "time": {"column": "timestamp", "unit": "ms"},
     "columns": {"ax": {"quantity": "acc", "axis": "x", "unit": "g"},
                 "gx": {"quantity": "gyr", "axis": "x", "unit": "dps"},
                 "mx": {"quantity": "mag", "axis": "x", "unit": "uT"}}}

``time.host_clock: true`` marks jittery host receive stamps (a uniform clock is fitted when they repeat).
``time.column`` may be null when the file has no time column (then ``device.rate_hz`` or ``--rate`` gives the rate).

Several sensors in one file: a column's ``"sensor": "seg1"`` puts it in ``/imu/seg1`` (default: ``device.name``).
Markers, one column per marker axis: ``{"quantity": "marker", "marker": "seg1_marker1", "axis": "x", "unit": "mm"}``
(``/markers/<sensor or "markers">``, m). ``"unmapped": "ignore"`` reads only the columns the mapping names (default
``"keep"``: the others are still recognised from their headers).
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imulog.converters._common import NORMALISED_MAG_UNITS, QUANTITIES, normalise_unit, unit_factor
from imulog.converters.errors import ConversionError

MAPPING_FORMAT = "imulog.mapping/1"


@dataclass(frozen=True)
class ColumnMap:
    quantity: str  # acc | gyr | mag | temperature | marker
    axis: str | None  # x | y | z (None for temperature)
    unit: str
    sensor: str | None = None  # the IMU (or marker set) the column belongs to; None = device.name
    marker: str | None = None  # the marker's label (quantity marker)


@dataclass
class Mapping:
    path: Path
    device: dict[str, Any] = field(default_factory=dict)
    delimiter: str | None = None
    time_column: str | None = None
    time_unit: str | None = None
    has_time: bool = False
    host_clock: bool = False
    columns: dict[str, ColumnMap] = field(default_factory=dict)
    unmapped: str = "keep"  # keep: other columns recognised from their headers; ignore: not read


def sibling_mapping(data_path: Path) -> Path | None:
    """``foo.mapping.json`` or ``foo.mapping.toml`` beside ``foo.csv``, if present."""
    for ext in (".json", ".toml"):
        candidate = data_path.with_name(data_path.stem + ".mapping" + ext)
        if candidate.is_file():
            return candidate
    return None


def is_mapping_file(path: Path) -> bool:
    return path.name.endswith((".mapping.json", ".mapping.toml"))


def load_mapping(path: Path) -> Mapping:
    """Read and validate a mapping file; any problem is a ConversionError naming the file and key."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ConversionError(path, f"cannot read mapping file: {e.strerror}") from None
    try:
        text = raw.decode("utf-8-sig")
        doc = tomllib.loads(text) if path.suffix.lower() == ".toml" else json.loads(text)
    except (UnicodeDecodeError, json.JSONDecodeError, tomllib.TOMLDecodeError) as e:
        line = getattr(e, "lineno", None)
        msg = getattr(e, "msg", str(e))
        raise ConversionError(path, f"not a valid mapping file: {msg}", line=line) from None
    if not isinstance(doc, dict):
        raise ConversionError(path, "a mapping file must be a JSON/TOML object")
    fmt = doc.get("format", MAPPING_FORMAT)
    if fmt != MAPPING_FORMAT:
        raise ConversionError(path, f"unknown mapping format {fmt!r} (expected {MAPPING_FORMAT!r})")
    device = doc.get("device", {})
    if not isinstance(device, dict):
        raise ConversionError(path, "'device' must be an object")
    rate = device.get("rate_hz")
    if rate is not None and (not isinstance(rate, int | float) or isinstance(rate, bool) or not rate > 0):
        raise ConversionError(path, f"device.rate_hz must be a positive number, got {rate!r}")
    mapping = Mapping(path=path, device=dict(device))
    delimiter = doc.get("delimiter")
    if delimiter is not None:
        if delimiter in ("\\t", "tab"):
            delimiter = "\t"
        if not isinstance(delimiter, str) or len(delimiter) != 1:
            raise ConversionError(path, f"'delimiter' must be one character, got {delimiter!r}")
        mapping.delimiter = delimiter
    time = doc.get("time")
    if time is not None:
        if not isinstance(time, dict):
            raise ConversionError(path, "'time' must be an object with 'column' and 'unit'")
        mapping.has_time = True
        mapping.time_column = time.get("column")
        mapping.time_unit = time.get("unit")
        mapping.host_clock = bool(time.get("host_clock", False))
        if mapping.time_column is not None:
            if not isinstance(mapping.time_column, str):
                raise ConversionError(path, "time.column must be a column name or null")
            if mapping.time_unit is None or unit_factor("time", str(mapping.time_unit)) is None:
                raise ConversionError(path, f"time.unit {mapping.time_unit!r} unknown (use s, ms, us or ns)")
        # time.column null: the rate comes from device.rate_hz or --rate (checked when converting)
    unmapped = doc.get("unmapped", "keep")
    if unmapped not in ("keep", "ignore"):
        raise ConversionError(path, f'\'unmapped\' must be "keep" or "ignore", got {unmapped!r}')
    mapping.unmapped = unmapped
    columns = doc.get("columns", {})
    if not isinstance(columns, dict):
        raise ConversionError(path, "'columns' must be an object: column name -> {quantity, axis, unit}")
    for name, spec in columns.items():
        if not isinstance(spec, dict):
            raise ConversionError(path, f"columns.{name} must be an object")
        q = spec.get("quantity")
        sensor = spec.get("sensor")
        if sensor is not None and (not isinstance(sensor, str) or not sensor.strip()):
            raise ConversionError(path, f"columns.{name}.sensor must be a name, got {sensor!r}")
        if q == "marker":
            mapping.columns[str(name)] = _marker_column(path, str(name), spec, sensor)
            continue
        if q not in QUANTITIES:
            raise ConversionError(
                path, f"columns.{name}.quantity {q!r} unknown (use {', '.join(QUANTITIES)} or marker)"
            )
        axis = spec.get("axis")
        if q != "temperature":
            axis = str(axis).lower() if axis is not None else None
            if axis not in ("x", "y", "z"):
                raise ConversionError(path, f"columns.{name}.axis {spec.get('axis')!r} must be x, y or z")
        unit = spec.get("unit")
        if not isinstance(unit, str) or (
            unit_factor(q, unit) is None and not (q == "mag" and normalise_unit(unit) in NORMALISED_MAG_UNITS)
        ):
            raise ConversionError(path, f"columns.{name}.unit {unit!r} is not a known {q} unit")
        mapping.columns[str(name)] = ColumnMap(q, axis, unit, sensor=sensor)
    return mapping


def _marker_column(path: Path, name: str, spec: dict, sensor: str | None) -> ColumnMap:
    """A ``quantity: marker`` column: its marker label, axis and length unit."""
    from imulog.converters._common import LENGTH_TO_M

    marker = spec.get("marker")
    if not isinstance(marker, str) or not marker.strip():
        raise ConversionError(path, f'columns.{name}.marker must name the marker (e.g. "seg1_marker1")')
    axis = str(spec.get("axis", "")).lower()
    if axis not in ("x", "y", "z"):
        raise ConversionError(path, f"columns.{name}.axis {spec.get('axis')!r} must be x, y or z")
    unit = spec.get("unit")
    if not isinstance(unit, str) or unit.strip().lower() not in LENGTH_TO_M:
        raise ConversionError(path, f"columns.{name}.unit {unit!r} is not a length unit (m, cm or mm)")
    return ColumnMap("marker", axis, unit.strip().lower(), sensor=sensor, marker=marker.strip())
