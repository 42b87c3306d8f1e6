"""Header analysis of delimited IMU text: which column holds which quantity, axis, device and unit."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from imulog.converters._common import (
    LENGTH_TO_M,
    NORMALISED_MAG_UNITS,
    UNIT_FACTORS,
    is_number,
    normalise_unit,
    sanitize_name,
    split_row,
    unit_factor,
)
from imulog.converters.errors import ConversionError
from imulog.converters.mapping import Mapping

_SHIMMER_DEVICE = re.compile(r"^(Shimmer_[0-9A-Za-z]+)_")


_SEP_LINE = re.compile(r'^\s*"?sep=(.)"?\s*$')


_UNIT_IN_NAME = re.compile(r"^(.*?)\s*[\(\[]\s*([^\)\]]*)\s*[\)\]]\s*$")


_COMPACT = re.compile(r"^(acc|accel|gyr|gyro|mag|a|g|m)([xyz])$")  # accx, gyroz; ax, gy, mz


_ALL_UNITS = {u for table in UNIT_FACTORS.values() for u in table} | NORMALISED_MAG_UNITS


_EXTRA_UNIT_WORDS = {"mv", "v", "no_units", "kohms", "us", "kpa", "pa", "%", "hpa", "degrees", "deg", "rad", "n", "nm"}


@dataclass
class Column:
    index: int
    name: str
    device: str
    quantity: str | None = None  # acc gyr mag temperature time extra index
    axis: str | None = None
    variant: str = ""
    unit: str = ""
    factor: float = 1.0


@dataclass
class Layout:
    delimiter: str
    skip_lines: int
    names: list[str]
    columns: list[Column] = field(default_factory=list)


def _quantity_of(tokens: list[str]) -> tuple[str | None, str | None, str]:
    """(quantity, axis, variant) from name tokens, e.g. ['shimmer','40ac','accel','ln','x','cal']."""
    quantity = None
    axis = None
    variant: list[str] = []
    qpos = -1
    for i, tok in enumerate(tokens):
        m = _COMPACT.match(tok)
        if m and quantity is None:
            quantity = {
                "acc": "acc",
                "accel": "acc",
                "gyr": "gyr",
                "gyro": "gyr",
                "mag": "mag",
                "a": "acc",
                "g": "gyr",
            }.get(m.group(1), "mag")
            axis = m.group(2)
            qpos = i
            continue
        if quantity is None:
            if tok.startswith("acc") and not tok.startswith("accur"):
                quantity, qpos = "acc", i
            elif tok.startswith("gyr"):
                quantity, qpos = "gyr", i
            elif tok.startswith("magnet") or tok == "mag":
                quantity, qpos = "mag", i
            elif tok.startswith("temp"):
                quantity, qpos = "temperature", i
            elif tok in ("time", "timestamp", "timestamps") or tok.startswith("timestamp"):
                quantity, qpos = "time", i
    if quantity in ("acc", "gyr", "mag") and axis is None:
        for tok in tokens[qpos + 1 :]:
            if tok in ("x", "y", "z"):
                axis = tok
                break
            if tok not in ("cal", "raw", "uncal"):
                variant.append(tok)
    return quantity, axis, "_".join(variant)


def _tokens(name: str) -> list[str]:
    return [t for t in re.split(r"[\s_\-\.:/]+", name.lower()) if t]


def _is_units_row(cells: list[str]) -> bool:
    nonempty = [c for c in cells if c]
    if not nonempty or any(is_number(c) for c in nonempty):
        return False
    known = sum(1 for c in nonempty if normalise_unit(c) in _ALL_UNITS or normalise_unit(c) in _EXTRA_UNIT_WORDS)
    return known * 2 >= len(nonempty)


INFER = "?"  # unit placeholder: not in the header, to be inferred from the values


def _bare_axis(name: str) -> str | None:
    """``X`` / ``y`` / ``attr_z`` / ``axis X`` -> the axis; anything naming more than an axis -> None."""
    tokens = _tokens(name)
    if (
        tokens
        and tokens[-1] in ("x", "y", "z")
        and len(tokens) <= 2
        and (len(tokens) == 1 or tokens[0] in _AXIS_PREFIX)
    ):
        return tokens[-1]
    return None


_AXIS_PREFIX = {"attr", "axis", "value", "values", "data", "raw"}


def _group_quantity(label: str) -> str | None:
    """``acc`` / ``Gyroscope`` / ``Magnetometer`` group labels -> the quantity (None for sensor names)."""
    q, axis, _ = _quantity_of(_tokens(label))
    return q if q in ("acc", "gyr", "mag") and axis is None else None


def _span_labels(labels: list[str]) -> list[str]:
    """A group label spans the empty cells to its right until the next label (``acc,,,gyr,,``)."""
    out, current = [], ""
    for cell in labels:
        current = cell or current
        out.append(current)
    return out


_QUAT_AXES = {"w": "w", "x": "x", "y": "y", "z": "z", "qw": "w", "qx": "x", "qy": "y", "qz": "z"}
_QUAT_AXES |= {"q0": "w", "q1": "x", "q2": "y", "q3": "z"}


_ORIENTATION_WORDS = ("orientation", "quaternion", "quat", "rotation")


def _orientation_group(label: str) -> bool:
    """``Vicon Orientation`` / ``Reference quaternion``: a group of w, x, y, z quaternion columns."""
    return any(t in _ORIENTATION_WORDS for t in _tokens(label))


_POSITION_WORDS = ("position", "translation", "pos")


def _position_group(label: str) -> bool:
    """``Vicon Position (mm)``: a group of X, Y, Z position columns of a reference system."""
    return any(t in _POSITION_WORDS for t in _tokens(label))


def _orientation_device(label: str, words: tuple[str, ...] = _ORIENTATION_WORDS) -> str:
    """``Vicon Orientation`` -> ``vicon`` (the group label without the orientation or position word)."""
    rest = [t for t in _tokens(label) if t not in words]
    return sanitize_name("_".join(rest) or "reference")


def _fit_width(row: list[str], data_cells: list[str]) -> list[str]:
    """A header row fitted to the data rows' field count where only trailing delimiters differ: empty cells past
    the data's last field are dropped, empty data fields past the header's last cell get an empty name."""
    row = list(row)
    while len(row) > len(data_cells) and row and not row[-1]:
        row.pop()
    while len(row) < len(data_cells) and not data_cells[len(row)]:
        row.append("")
    return row


def detect_delimiter(line: str) -> str | None:
    counts = {d: line.count(d) for d in (",", ";", "\t")}
    best = max(counts, key=lambda d: counts[d])
    return best if counts[best] > 0 else None


def analyse_header(
    path: Path,
    lines: list[str],
    *,
    mapping: Mapping | None = None,
    default_units: dict[str, str] | None = None,
    device_name: str = "imu",
    units: dict[str, str] | None = None,
    raw: set[int] | None = None,
) -> Layout:
    """Find delimiter, header rows, units and the role of every column; ConversionError on problems.

    ``units``: the user's unit per quantity (``--unit gyr=deg/s``), replacing the header's. Columns whose unit
    the header does not give get unit :data:`INFER`; bare ``X``/``Y``/``Z`` columns without a quantity word get
    quantity ``auto``: both are resolved from the values by :func:`resolve_inferred`. ``raw``: indexes of
    uncalibrated columns (ADC counts, e.g. Shimmer ``RAW``): kept as found in the signals, never as IMU data.
    """
    overrides = dict(units or {})
    idx = 0
    delimiter = mapping.delimiter if mapping and mapping.delimiter else None
    m = _SEP_LINE.match(lines[0]) if lines else None
    if m:
        delimiter = delimiter or m.group(1)
        idx = 1
    while idx < len(lines) and (lines[idx].lstrip().startswith("#") or not lines[idx].strip()):
        idx += 1
    if idx >= len(lines):
        raise ConversionError(path, "no header row found", line=idx)
    delimiter = delimiter or detect_delimiter(lines[idx])
    if delimiter is None:
        raise ConversionError(
            path, "cannot tell the delimiter (no comma, semicolon or tab in the header)", line=idx + 1
        )
    rows = [split_row(lines[idx], delimiter)]
    header_start = idx
    idx += 1
    units_row: list[str] | None = None
    groups_row: list[str] | None = None
    while idx < len(lines):
        cells = split_row(lines[idx], delimiter)
        if all(c == "" or is_number(c) for c in cells):
            break
        if _is_units_row(cells) and units_row is None:
            units_row = cells
        elif groups_row is None and units_row is None and len(rows) == 1:
            groups_row = rows[0]
            rows = [cells]
        else:
            raise ConversionError(path, "unexpected non-numeric row after the header", line=idx + 1)
        idx += 1
    if idx >= len(lines):
        raise ConversionError(path, "no data rows after the header", line=idx)
    data_cells = split_row(lines[idx], delimiter)
    names = _fit_width(rows[0], data_cells)
    units_row = _fit_width(units_row, data_cells) if units_row is not None else None
    groups_row = _fit_width(groups_row, data_cells) if groups_row is not None else None
    ncols = len(names)
    for other, what in ((units_row, "units row"), (groups_row, "sensor row")):
        if other is not None and len(other) != ncols:
            raise ConversionError(path, f"{what} has {len(other)} fields, names row has {ncols}", line=header_start + 1)
    layout = Layout(delimiter=delimiter, skip_lines=idx, names=[])
    own_groups = list(groups_row) if groups_row is not None else None  # each group label where it is written
    if groups_row is not None:
        groups_row = _span_labels(groups_row)
    full_names: list[str] = []
    for i, name in enumerate(names):
        group = groups_row[i] if groups_row else ""
        if not name and own_groups is not None and not own_groups[i]:
            group = ""  # an empty cell under a spanned group label (a trailing delimiter): no column
        full = f"{group}/{name}" if group and name else (name or group)
        full_names.append(full)
    seen: dict[str, int] = {}
    for i, full in enumerate(full_names):
        if full and full in seen:
            if _bare_axis(names[i]) is None:
                raise ConversionError(
                    path, f"duplicated column {full!r} (also column {seen[full] + 1})", line=header_start + 1
                )
            full_names[i] = f"{full} (column {i + 1})"  # X,Y,Z,X,Y,Z: told apart by position (a mapping
            seen[full_names[i]] = i  # file names the second one "Y (column 6)")
            continue
        seen[full] = i
    layout.names = full_names

    mapped = dict(mapping.columns) if mapping else {}
    for key in mapped:
        if key not in seen:
            raise ConversionError(
                path, f"mapping file {mapping.path.name} names column {key!r}, which is not in the header"
            )
    time_col = mapping.time_column if mapping and mapping.has_time else None
    if time_col is not None and time_col not in seen:
        raise ConversionError(path, f"time column {time_col!r} of the mapping file is not in the header")

    have_time = False
    for i, full in enumerate(full_names):
        name = names[i]
        group = groups_row[i] if groups_row else ""
        col = Column(index=i, name=full, device=device_name)
        group_unit = ""
        if (m_group := _UNIT_IN_NAME.match(group)) and name:  # `IMU Gyroscope (deg/s)`: the unit of its columns
            group, group_unit = m_group.group(1), m_group.group(2)
        group_quantity = _group_quantity(group)
        if groups_row is not None and group.lower() not in ("", "sensor") and group_quantity is None:
            col.device = sanitize_name(group)
        elif (shimmer := _SHIMMER_DEVICE.match(name)) and not (mapping and mapping.device.get("name")):
            col.device = sanitize_name(shimmer.group(1))  # per column: a Consensys file may hold several Shimmers
        header_unit = (units_row[i] if units_row else "") or group_unit
        base = name or (own_groups[i] if own_groups is not None else "")  # `Time (s)` in the group row, no axis
        m_unit = _UNIT_IN_NAME.match(base)
        if m_unit:
            base, header_unit = m_unit.group(1), m_unit.group(2)
        if not full:
            col.quantity = "ignore"
        elif _orientation_group(group) and name.lower() in _QUAT_AXES and not (mapping and full in mapped):
            col.quantity, col.axis = "quat", _QUAT_AXES[name.lower()]
            col.device = _orientation_device(group)
        elif _position_group(group) and _bare_axis(name) and not (mapping and full in mapped):
            unit = (overrides.get("markers") or header_unit or "").strip().lower()
            col.device = _orientation_device(group, _POSITION_WORDS)
            col.quantity, col.axis, col.unit = "marker", _bare_axis(name), unit  # unit checked by _plan
            col.variant, col.factor = col.device, LENGTH_TO_M.get(unit, float("nan"))
            layout.columns.append(col)
            continue
        elif raw and i in raw:
            col.quantity, col.unit = "extra", header_unit or "counts"
        elif full in mapped:
            cm = mapped[full]
            col.quantity, col.axis, col.unit = cm.quantity, cm.axis, cm.unit
            if cm.sensor:
                col.device = sanitize_name(cm.sensor)
            if cm.quantity == "marker":
                col.variant = str(cm.marker)
                col.factor = LENGTH_TO_M[cm.unit]
                col.device = sanitize_name(cm.sensor) if cm.sensor else "markers"
                layout.columns.append(col)
                continue
        elif mapping is not None and mapping.unmapped == "ignore" and not (time_col is not None and full == time_col):
            col.quantity = "ignore"
        elif time_col is not None and full == time_col:
            col.quantity, col.unit = "time", str(mapping.time_unit)
        elif groups_row is not None and i == 0 and group.lower() in ("", "sensor") and name.lower() in ("", "axis"):
            col.quantity = "index"
        else:
            q, axis, variant = _quantity_of(_tokens(base))
            if q == "time" and (have_time or time_col is not None or (mapping and mapping.has_time)):
                q = None
            if q is None and _bare_axis(base) is not None:
                # X, Y, Z under an acc/gyr/mag group label, or a unit-less axis whose quantity the values tell
                q, axis = group_quantity or "auto", _bare_axis(base)
            col.quantity, col.axis, col.variant, col.unit = q, axis, variant, header_unit
            if q in ("acc", "gyr", "mag") and axis is None:
                col.quantity = None
            if col.quantity is not None and not col.unit and default_units:
                col.unit = default_units.get(col.quantity, "")
        if col.quantity in overrides:
            col.unit = overrides[col.quantity]
        if col.quantity is None:
            col.quantity = "extra"
            col.unit = header_unit
        if col.quantity == "time":
            have_time = True
        if col.quantity in ("acc", "gyr", "mag", "temperature", "time"):
            if not col.unit:
                if col.quantity == "temperature":
                    col.unit = "degC"  # the only temperature unit IMUs export
                else:
                    col.unit = INFER  # no unit in the header: inferred from the values (read_delimited says so)
                    layout.columns.append(col)
                    continue
            factor = unit_factor(col.quantity, col.unit)
            if factor is None:
                if col.quantity == "mag" and normalise_unit(col.unit) in NORMALISED_MAG_UNITS:
                    col.quantity = "extra"  # normalised field, not uT: kept as found
                else:
                    raise ConversionError(path, f"unknown {col.quantity} unit {col.unit!r}", column=full)
            else:
                col.factor = factor
        layout.columns.append(col)
    return layout
