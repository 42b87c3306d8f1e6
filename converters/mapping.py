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
``time.column`` may be null when the file has no time column (then ``device.rate_hz`` is required).
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from converters._common import NORMALISED_MAG_UNITS, QUANTITIES, normalise_unit, unit_factor
from converters.errors import ConversionError

MAPPING_FORMAT = "imulog.mapping/1"


@dataclass(frozen=True)
class ColumnMap:
    quantity: str  # acc | gyr | mag | temperature
    axis: str | None  # x | y | z (None for temperature)
    unit: str


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
        elif rate is None:
            raise ConversionError(path, "time.column is null: device.rate_hz is required")
    columns = doc.get("columns", {})
    if not isinstance(columns, dict):
        raise ConversionError(path, "'columns' must be an object: column name -> {quantity, axis, unit}")
    for name, spec in columns.items():
        if not isinstance(spec, dict):
            raise ConversionError(path, f"columns.{name} must be an object")
        q = spec.get("quantity")
        if q not in QUANTITIES:
            raise ConversionError(path, f"columns.{name}.quantity {q!r} unknown (use {', '.join(QUANTITIES)})")
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
        mapping.columns[str(name)] = ColumnMap(q, axis, unit)
    return mapping
