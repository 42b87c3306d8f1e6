"""Generic delimited IMU text (CSV, TSV, semicolon): units from headers, a units row, or a mapping file.

Understands
* unit-bearing headers: ``Time (s),Gyroscope X (deg/s),...,Accelerometer X (g),...,Magnetometer X (uT)``;
* Shimmer Consensys exports: a ``"sep=;"`` line, a names row (``Shimmer_40AC_Accel_LN_X_CAL``) and a units
  row (``ms;m/(s^2);...;deg/s``);
* two-row headers (a sensor row above an axis row, as in the gaitmap sample): one IMU stream per sensor;
* a mapping file (``imulog.mapping/1``, see :mod:`imulog.converters.mapping`) for exports whose headers carry no units,
  such as the BlueBuddy wrist IMU of the R2G thesis.

Recognised IMU columns go to :class:`~imulog.model.ImuStream` in SI units; other numeric columns are kept,
units as found, in a :class:`~imulog.model.SignalStream` ``/signals/<device>``.
"""

from __future__ import annotations

import hashlib
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._common import (
    LENGTH_TO_M,
    NORMALISED_MAG_UNITS,
    SI_UNIT,
    UNIT_FACTORS,
    TableSpec,
    check_increasing,
    drop_cut_final_row,
    estimate_rate_hz,
    head_lines,
    is_number,
    normalise_unit,
    read_head,
    read_numeric,
    read_source,
    remember_sha256,
    sanitize_name,
    split_row,
    text_head_lines,
    to_ns,
    unit_factor,
    unit_overrides,
)
from imulog.converters._lab import orientation_stream
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError, excerpt
from imulog.converters.mapping import Mapping, load_mapping, sibling_mapping

from imulog.model import ImuStream, MarkerStream, PoseStream, Recording, SignalStream

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


def _check_infinite(path: Path, layout: Layout, values: np.ndarray, first_line: int) -> None:
    """NaN and empty cells are gaps; +-inf is not a missing sample but a broken number: refuse it."""
    if not np.isinf(values).any():  # one pass over the table; the column and line are found only when needed
        return
    for c in layout.columns:
        if c.quantity in ("acc", "gyr", "mag", "temperature", "auto", "marker"):
            bad = np.isinf(values[:, c.index])
            if bad.any():
                raise ConversionError(
                    path,
                    "infinite value (empty or NaN cells are gaps)",
                    line=first_line + int(np.argmax(bad)),
                    column=c.name,
                )


TIME_UNITS = ("s", "ms", "us", "ns")
PLAUSIBLE_RATE_HZ = (5.0, 5000.0)


def _infer_time_unit(path: Path, col: Column, t: np.ndarray) -> str:
    """The unit (s, ms, us, ns) that gives a wearable's sampling rate (5-5000 Hz); sets ``col.unit/factor``."""
    dt = np.diff(t[np.isfinite(t)])
    dt = float(np.median(dt)) if len(dt) else 0.0
    fits = [
        u
        for u in TIME_UNITS
        if dt > 0 and PLAUSIBLE_RATE_HZ[0] <= 1e9 / (dt * unit_factor("time", u)) <= PLAUSIBLE_RATE_HZ[1]
    ]
    if len(fits) != 1:
        raise ConversionError(
            path,
            f"no time unit in the header and a step of {dt:g} fits {', '.join(fits) or 'no unit'} "
            "at 5-5000 Hz: give --unit time=s (or ms, us) or a mapping file",
            column=col.name,
        )
    col.unit, col.factor = fits[0], float(unit_factor("time", fits[0]))
    return f"time in {fits[0]} ({1e9 / (dt * col.factor):.4g} Hz)"


def _triples(cols: list[Column]) -> list[list[Column]]:
    """Consecutive x, y, z columns (any order) of one device, in file order."""
    out: list[list[Column]] = []
    current: list[Column] = []
    for c in cols:
        if current and (c.axis in {x.axis for x in current} or c.device != current[0].device):
            out.append(current)
            current = []
        current.append(c)
        if len(current) == 3:
            out.append(current)
            current = []
    if current:
        out.append(current)
    return out


def _axes_problem(dev: str, q: str, cols: list[Column]) -> str:
    """A readable reason why ``cols`` are not one x, y, z triple (short even for a file of many sensors)."""
    counts = {a: sum(1 for c in cols if c.axis == a) for a in "xyz"}
    shown = ", ".join(repr(excerpt(c.name, 24)) for c in cols[:3]) + (", ..." if len(cols) > 3 else "")
    what = f"{len(cols)} {q} columns ({counts['x']} x, {counts['y']} y, {counts['z']} z: {shown})"
    if max(counts.values()) > 1:
        return (
            f"device {dev!r}: {what}: several sensors in one file; a mapping file names the sensor of each column "
            '("sensor": "seg1", docs/converters.md)'
        )
    return f"device {dev!r}: {what}: {q} needs one x, one y and one z column"


def resolve_inferred(
    path: Path, layout: Layout, values: np.ndarray, t_ns: np.ndarray, overrides: dict[str, str]
) -> list[str]:
    """Give ``auto`` columns a quantity and :data:`INFER` units a unit from physical plausibility.

    Bare X,Y,Z triples: the quantity named by the file name (``wrist_gyro.csv``) when there is one triple, else
    the triple with a constant non-zero norm at rest near 1 g / 9.81 m/s^2 / 1000 mg is the accelerometer, one
    near 20-80 uT the magnetometer, the rest gyroscopes. Units: see :mod:`imulog.converters.plausibility`. Returns the
    assumptions, one phrase each; ConversionError naming the column and the option when the values cannot tell.
    """
    from imulog.converters import plausibility as plaus

    notes: list[str] = []
    if not any(c.quantity == "auto" or c.unit == INFER for c in layout.columns):
        return notes  # every quantity and unit is known: nothing to judge from the values
    t_ns, (values,) = plaus.excerpts(t_ns, values)  # long recordings: judged on evenly spread excerpts
    auto = [c for c in layout.columns if c.quantity == "auto"]
    name_q = _group_quantity(path.stem) or _quantity_of(_tokens(path.stem))[0]
    triples = _triples(auto)
    for tri in triples:
        if len(tri) != 3:
            raise ConversionError(
                path, "an axis column without its x, y, z neighbours and no quantity", column=tri[0].name
            )
        raw = values[:, [c.index for c in sorted(tri, key=lambda c: c.axis or "")]]
        if name_q in ("acc", "gyr", "mag") and len(triples) == 1:
            q, why = name_q, "the file name"
        elif plaus.rest_windows(raw, t_ns) and plaus.infer_acc_unit(raw, t_ns).unit:
            q, why = "acc", "its norm at rest is gravity"
        elif plaus.rest_windows(raw, t_ns) and 20 <= plaus.rest_acc_norm(raw, t_ns)[0] <= 80:
            q, why = "mag", "its norm at rest is the Earth's field in uT"
        else:
            q, why = "gyr", "its norm is not constant at rest"
        for c in tri:
            c.quantity = q
            c.unit = overrides.get(q) or c.unit or INFER
            if c.unit != INFER:
                factor = unit_factor(q, c.unit)
                if factor is None:
                    raise ConversionError(path, f"unknown {q} unit {c.unit!r}", column=c.name)
                c.factor = float(factor)
        notes.append(f"columns {', '.join(c.name for c in tri)} are {q} ({why})")
    acc_raw: dict[str, np.ndarray] = {}
    for q in ("acc", "mag", "gyr"):  # acc first: the gyroscope's unit is judged against it
        groups: dict[str, list[Column]] = {}
        for c in layout.columns:
            if c.quantity == q and c.unit == INFER:
                groups.setdefault(c.device, []).append(c)
        for c in layout.columns:
            if c.quantity == "acc" and c.axis in ("x", "y", "z"):
                acc_raw.setdefault(c.device, np.zeros((len(values), 3)))[:, "xyz".index(c.axis)] = values[:, c.index]
        for dev, cols in groups.items():
            if sorted(c.axis or "" for c in cols) != ["x", "y", "z"]:
                raise ConversionError(path, _axes_problem(dev, q, cols))
            raw = values[:, [c.index for c in sorted(cols, key=lambda c: c.axis or "")]]
            if q == "acc":
                guess = plaus.infer_acc_unit(raw, t_ns)
            elif q == "gyr":
                acc = acc_raw.get(dev)
                guess = plaus.infer_gyr_unit(raw, acc if acc is not None and np.isfinite(acc).any() else None, t_ns)
            else:
                norm = plaus.rest_acc_norm(raw, t_ns)[0]
                unit = "uT" if 15 <= norm <= 100 else "gauss" if 0.15 <= norm <= 1.0 else None
                guess = plaus.UnitGuess(unit, f"field norm {norm:.3g}")
            if guess.unit is None:
                raise ConversionError(
                    path,
                    f"no {q} unit in the header and the values cannot tell ({guess.evidence}): "
                    f"give --unit {q}=UNIT or a mapping file",
                    column=cols[0].name,
                )
            for c in cols:
                c.unit, c.factor = guess.unit, float(unit_factor(q, guess.unit) or 1.0)
            notes.append(f"{q} in {guess.unit} ({guess.evidence})")
    return notes


def _fit_host_clock(path: Path, t_ns: np.ndarray, first_line: int, column: str) -> np.ndarray:
    """Uniform device clock fitted to jittery host time stamps (e.g. Shimmer ``Timestamp_Unix``, 1 ms resolution).

    The sensor samples at a fixed rate; the host stamps packets on arrival, so stamps repeat and jitter. A
    least-squares line through (sample index, stamp) gives start and period; stamps further than 1 s from the
    line mean a real clock problem and are reported.
    """
    i = np.arange(len(t_ns), dtype=np.float64)
    rel = (t_ns - t_ns[0]).astype(np.float64)
    slope, intercept = np.polyfit(i, rel, 1)
    if not slope > 0:
        raise ConversionError(path, "host time stamps do not increase", column=column)
    resid = np.abs(rel - (slope * i + intercept))
    if resid.max() > 1e9:
        bad = int(np.argmax(resid))
        raise ConversionError(
            path, "host time stamp more than 1 s off the sample clock", line=first_line + bad, column=column
        )
    return t_ns[0] + np.round(intercept + slope * i).astype(np.int64)


def _first_data_cells(path: Path, lines: list[str], layout: Layout) -> list[str]:
    if layout.skip_lines < len(lines):
        return split_row(lines[layout.skip_lines], layout.delimiter)
    return []


@dataclass
class _Plan:
    """What the header says, shared by the whole-file and the piece-by-piece reader."""

    path: Path
    mapping: Mapping | None
    layout: Layout
    spec: TableSpec
    device_meta: dict[str, Any]
    rate: float | None
    fmt: str
    units: dict[str, str]


def _plan(
    path: Path,
    head: bytes | None,
    *,
    mapping: Mapping | None,
    rate_hz: float | None,
    default_units: dict[str, str] | None,
    device_meta: dict[str, Any] | None,
    fmt: str,
    units: dict[str, str] | None,
    header_lines: list[str] | None = None,
    raw: set[int] | None = None,
) -> _Plan:
    # empty or binary files are refused before the whole file is read
    lines = header_lines if header_lines is not None else head_lines(path, head)
    device_meta = dict(device_meta or {})
    if mapping is not None:
        device_meta.update(mapping.device)
    device_name = sanitize_name(str(device_meta.get("name", "imu")))
    layout = analyse_header(
        path, lines, mapping=mapping, default_units=default_units, device_name=device_name, units=units, raw=raw
    )
    for c in layout.columns:
        if c.quantity == "marker" and c.unit not in LENGTH_TO_M:
            group = c.name.rsplit("/", 1)[0]
            raise ConversionError(
                path,
                f"position group {group!r} has no length unit: write it in the label ({group} (mm)) or give "
                "--unit markers=mm (or m, cm)",
                column=c.name,
            )
    first = _first_data_cells(path, lines, layout)
    ignore = {c.index for c in layout.columns if c.quantity == "ignore"}
    # text columns (non-numeric in the first data row) that are not IMU data are skipped, not parsed
    for c in layout.columns:
        if c.quantity == "extra" and c.index < len(first) and first[c.index] and not is_number(first[c.index]):
            c.quantity = "ignore"
            ignore.add(c.index)
    # IMU and extra columns may be empty or NaN (gaps); time and index columns may not
    optional = {c.index for c in layout.columns if c.quantity not in ("time", "index", "ignore")}
    spec = TableSpec(
        path=path,
        delimiter=layout.delimiter,
        skip_lines=layout.skip_lines,
        names=layout.names,
        optional=optional,
        ignore=ignore,
    )
    rate = rate_hz or device_meta.get("rate_hz")
    return _Plan(path, mapping, layout, spec, device_meta, rate, fmt, dict(units or {}))


def _is_host_clock(plan: _Plan, column: Column) -> bool:
    return "unix" in _tokens(column.name) or bool(plan.mapping and plan.mapping.host_clock)


def _times(
    plan: _Plan,
    values: np.ndarray,
    first_line: int,
    *,
    first_row: int = 0,
    origin: float | None = None,
    before: float | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Sample times (int64 ns) of the rows ``values`` and how they were found; ConversionError naming the line.

    For a later piece of the file: ``first_row`` its first row's index in the recording, ``origin`` the recording's
    first time value, ``before`` the last time (or index) value of the piece before it.
    """
    path = plan.path
    time_cols = [c for c in plan.layout.columns if c.quantity == "time"]
    index_cols = [c for c in plan.layout.columns if c.quantity == "index"]
    if time_cols:
        tc = time_cols[0]
        try:
            t_ns = to_ns(values[:, tc.index], tc.factor, origin)
        except ValueError:
            raise ConversionError(path, "time stamps out of range", column=tc.name) from None
        time_desc: dict[str, Any] = {"column": tc.name, "unit": tc.unit}
        if _is_host_clock(plan, tc) and len(t_ns) > 2 and np.any(np.diff(t_ns) <= 0):
            t_ns = _fit_host_clock(path, t_ns, first_line, tc.name)
            time_desc["clock"] = "host receive time with repeated stamps: least-squares fit of a uniform rate"
        _check_increasing(path, t_ns, first_line, tc.name, before)
    elif plan.rate:
        rate = float(plan.rate)
        if index_cols:
            idx = values[:, index_cols[0].index]
            _check_increasing(path, idx, first_line, index_cols[0].name, before)
            t_ns = np.round(idx * (1e9 / rate)).astype(np.int64)
        else:
            t_ns = np.round(np.arange(first_row, first_row + len(values)) * (1e9 / rate)).astype(np.int64)
        time_desc = {"column": None, "rate_hz": rate}
    else:
        raise ConversionError(path, "no time column in the header and no rate given (mapping device.rate_hz or --rate)")
    return t_ns, time_desc


def _check_increasing(path: Path, t: np.ndarray, first_line: int, column: str, before: float | None) -> None:
    """:func:`check_increasing` of ``t``, continuing from ``before`` (the previous piece's last value)."""
    if before is None:
        check_increasing(path, t, first_line, column)
    else:
        check_increasing(path, np.concatenate([[before], t]), first_line - 1, column)


def _assumed_units(plan: _Plan, values: np.ndarray) -> list[str]:
    """Infer the units the header does not give (time first, then quantities); the assumptions, one phrase each."""
    assumed: list[str] = []
    time_cols = [c for c in plan.layout.columns if c.quantity == "time"]
    if time_cols and time_cols[0].unit == INFER:
        assumed.append(_infer_time_unit(plan.path, time_cols[0], values[:, time_cols[0].index]))
    return assumed


def _units_warning(path: Path, assumed: list[str]) -> list[str]:
    if not assumed:
        return []
    return [
        f"{path.name}: no units in the header: assumed {'; '.join(assumed)}; "
        "if wrong, give --unit QUANTITY=UNIT or a mapping file"
    ]


def read_delimited(
    path: Path,
    *,
    mapping: Mapping | None = None,
    rate_hz: float | None = None,
    default_units: dict[str, str] | None = None,
    device_meta: dict[str, Any] | None = None,
    fmt: str = "delimited",
    head: bytes | None = None,
    units: dict[str, str] | None = None,
    header_lines: list[str] | None = None,
    raw: set[int] | None = None,
) -> Recording:
    """Read one delimited IMU text file into a Recording (see module docstring).

    Empty or NaN cells in IMU columns are gaps (NaN in the stream); ``units`` replaces the header's unit per
    quantity (``{"gyr": "deg/s"}``); units the header does not give are inferred from the values and said in
    ``Recording.warnings``. ``header_lines``: the file's first lines as a format reader normalised them (same
    number of lines, e.g. Shimmer's four header rows as a names and a units row); ``raw``: see :func:`analyse_header`.
    """
    path = Path(path)
    plan = _plan(
        path,
        head,
        mapping=mapping,
        rate_hz=rate_hz,
        default_units=default_units,
        device_meta=device_meta,
        fmt=fmt,
        units=units,
        header_lines=header_lines,
        raw=raw,
    )
    data = read_source(path)  # read once: parsed from memory, its SHA-256 computed from these bytes
    values = read_numeric(plan.spec, data)
    del data
    first_line = plan.layout.skip_lines + 1
    warnings = list(plan.spec.warnings)
    _check_infinite(path, plan.layout, values, first_line)
    assumed = _assumed_units(plan, values)
    t_ns, time_desc = _times(plan, values, first_line)
    assumed.extend(resolve_inferred(path, plan.layout, values, t_ns, plan.units))
    warnings.extend(_units_warning(path, assumed))
    rate_meta = float(plan.rate) if plan.rate else estimate_rate_hz(t_ns)
    rec = _recording(plan, values, t_ns, time_desc, rate_meta, warnings)
    start = unix_start(plan.layout, values, t_ns)
    if start is not None:
        rec.metadata["imulog.trial"] = start
    return rec


UNIX_S_RANGE = (9.0e8, 4.2e9)  # 1998 .. 2103: a first stamp in this range (s since 1970) is a Unix time


def unix_start(layout: Layout, values: np.ndarray, t_ns: np.ndarray) -> dict[str, str] | None:
    """``imulog.trial`` start (UTC) from a Unix time column (``Timestamp_Unix``, ``System_Timestamp``): the time
    column itself when it is one (its first, fitted, stamp), else a Unix column beside the device's clock (its
    first cell, the host time of the first sample). None when the file has no Unix time."""
    from datetime import UTC, datetime

    cols = [c for c in layout.columns if c.quantity == "time"] + [c for c in layout.columns if c.quantity == "extra"]
    for c in cols:
        tokens = _tokens(c.name)
        is_unix = "unix" in tokens or ("system" in tokens and any(t.startswith("timestamp") for t in tokens))
        if not is_unix or len(values) == 0:
            continue
        if c.quantity == "time":
            first_s = float(t_ns[0]) / 1e9
        else:
            factor = unit_factor("time", c.unit or "ms") or 1e6
            first_s = float(values[0, c.index]) * factor / 1e9
        if not UNIX_S_RANGE[0] < first_s < UNIX_S_RANGE[1]:
            continue
        when = datetime.fromtimestamp(first_s, tz=UTC)
        return {
            "start_time": when.isoformat(timespec="milliseconds"),
            "time_zone": "UTC",
            "start_time_source": f"column {c.name!r} (Unix time of the first sample)",
        }
    return None


#: bytes of text per piece when a large file is converted piece by piece (``iter_delimited``)
PIECE_BYTES = 16 * 1024 * 1024


def iter_delimited(
    path: Path,
    *,
    mapping: Mapping | None = None,
    rate_hz: float | None = None,
    units: dict[str, str] | None = None,
    piece_bytes: int = PIECE_BYTES,
) -> Iterator[Recording]:
    """The Recording of :func:`read_delimited` as consecutive pieces of about ``piece_bytes`` of text each.

    Every value, time stamp, gap and error (file, line, column) is what the whole-file reader gives; the units the
    header lacks are inferred from the first piece (an hour or more), a cut final row is dropped from the last.
    Host-clock time stamps that repeat need a least-squares fit over the whole recording: such a file comes
    whole, as one piece. While reading, the file's SHA-256 is computed (the conversion record reuses it).
    """
    path = Path(path)
    head = read_head(path)
    plan = _plan(
        path, head, mapping=mapping, rate_hz=rate_hz, default_units=None, device_meta=None, fmt="delimited", units=units
    )
    time_cols = [c for c in plan.layout.columns if c.quantity == "time"]
    if time_cols and _is_host_clock(plan, time_cols[0]):
        yield read_delimited(path, mapping=mapping, rate_hz=rate_hz, head=head, units=units)
        return
    index_cols = [c for c in plan.layout.columns if c.quantity == "index"]
    digest = hashlib.sha256()
    total = 0
    with open(path, "rb") as f:
        for _ in range(plan.layout.skip_lines):
            line = f.readline()
            if not line.endswith(b"\n"):
                raise ConversionError(path, "file ends inside the header", line=plan.layout.skip_lines)
            digest.update(line)
            total += len(line)
        lines_before = plan.layout.skip_lines
        first_row = 0
        origin: float | None = None  # the recording's first time value: every piece's ns are relative to it
        before: float | None = None  # the previous piece's last time (ns) or index: time must keep increasing
        rate_meta: float | None = None
        started = False
        steps = _StepCounts() if time_cols and not plan.rate else None  # the exact median step, piece by piece
        buf = f.read(piece_bytes)
        digest.update(buf)
        total += len(buf)
        last = False
        while not last:
            nxt = f.read(piece_bytes)
            digest.update(nxt)
            total += len(nxt)
            if len(nxt) < min(piece_bytes, 1 << 20):  # the file ends: a last piece of at least 1 MiB (or a piece)
                piece, buf, last = buf + nxt, b"", True  # so the cut-row check sees the rows above the last one
            else:
                cut = buf.rfind(b"\n") + 1
                if cut == 0:  # a line longer than a piece: read on
                    buf += nxt
                    continue
                piece, buf = buf[:cut], buf[cut:] + nxt
            spec = replace(
                plan.spec,
                skip_lines=lines_before,
                byte_range=(0, len(piece)),
                in_memory=True,
                check_final_row=False,
                allow_trailing_blank=last,
                warnings=[],
            )
            warnings: list[str] = []
            if last:
                end, warning = drop_cut_final_row(path, piece, spec.delimiter, line_offset=lines_before)
                if warning is not None:
                    spec = replace(spec, byte_range=(0, end))
                    warnings.append(warning)
                if first_row and not piece[:end].strip(b" \t\r\n"):
                    break  # nothing but blank lines after the previous piece
            values = read_numeric(spec, piece)
            first_line = lines_before + 1
            _check_infinite(path, plan.layout, values, first_line)
            if not started:
                assumed = _assumed_units(plan, values)
                if time_cols:
                    origin = float(values[0, time_cols[0].index])
            t_ns, time_desc = _times(plan, values, first_line, first_row=first_row, origin=origin, before=before)
            if not started:
                assumed.extend(resolve_inferred(path, plan.layout, values, t_ns, plan.units))
                warnings.extend(_units_warning(path, assumed))
                rate_meta = float(plan.rate) if plan.rate else estimate_rate_hz(t_ns)
                started = True
            if steps is not None:
                steps.add(np.diff(t_ns) if before is None else np.diff(np.concatenate([[before], t_ns])))
                rate_meta = steps.rate_hz() if steps.exact else rate_meta  # the last piece's: the whole recording's
            if time_cols:
                before = int(t_ns[-1])
            elif index_cols:
                before = float(values[-1, index_cols[0].index])
            yield _recording(plan, values, t_ns, time_desc, rate_meta, warnings)
            lines_before += piece.count(b"\n")
            first_row += len(values)
        st = os.fstat(f.fileno())
    if st.st_size == total:
        remember_sha256(path, st, digest.hexdigest())


class _StepCounts:
    """How often each time step (ns) occurs, to give the whole recording's median rate (as
    :func:`estimate_rate_hz` of all time stamps) from its pieces; gives up beyond a million distinct steps."""

    MAX_DISTINCT = 1_000_000

    def __init__(self) -> None:
        self.counts: dict[int, int] = {}
        self.exact = True

    def add(self, steps: np.ndarray) -> None:
        if not self.exact or not len(steps):
            return
        values, counts = np.unique(steps, return_counts=True)
        for v, c in zip(values.tolist(), counts.tolist(), strict=True):
            self.counts[v] = self.counts.get(v, 0) + c
        if len(self.counts) > self.MAX_DISTINCT:
            self.exact, self.counts = False, {}

    def rate_hz(self) -> float | None:
        """1e9 / the median step (the mean of the two middle steps for an even count), None without steps."""
        if not self.counts:
            return None
        values = np.array(sorted(self.counts), dtype=np.int64)
        cum = np.cumsum([self.counts[int(v)] for v in values])
        n = int(cum[-1])
        lo, hi = (n - 1) // 2, n // 2
        pick = values[np.searchsorted(cum, [lo + 1, hi + 1])]
        dt = float(np.mean(pick)) if n % 2 == 0 else float(pick[1])
        return 1e9 / dt if dt > 0 else None


def _recording(
    plan: _Plan,
    values: np.ndarray,
    t_ns: np.ndarray,
    time_desc: dict[str, Any],
    rate_meta: float | None,
    warnings: list[str],
) -> Recording:
    """The IMU streams (SI units) and the other numeric columns of ``values``, device by device."""
    path, mapping, device_meta, fmt = plan.path, plan.mapping, plan.device_meta, plan.fmt
    devices: dict[str, list[Column]] = {}
    for c in plan.layout.columns:
        if c.quantity not in ("ignore", "index", "time"):
            devices.setdefault(c.device, []).append(c)
    rec = Recording(sources=[str(path)] + ([str(mapping.path)] if mapping else []), warnings=warnings)
    for dev, cols in devices.items():
        streams: dict[str, np.ndarray] = {}
        units: dict[str, str] = {}
        extra_cols: list[Column] = []
        chosen_variant: dict[str, str] = {}
        slots: dict[tuple[str, str | None], Column] = {}
        marks = [c for c in cols if c.quantity == "marker"]
        quat_cols = {c.axis: c for c in cols if c.quantity == "quat"}
        if marks and set(quat_cols) == set("wxyz") and {c.variant for c in marks} == {dev}:
            pos = _marker_stream(path, dev, marks, values, t_ns).pos[:, 0]
            q = np.column_stack([values[:, quat_cols[a].index] for a in "wxyz"])
            rec.poses.append(
                PoseStream(topic=f"/poses/{dev}", t_ns=t_ns, position=pos, orientation=q, frame_id="world")
            )
            rec.metadata[f"imulog.device.{dev}"] = {
                "format": fmt,
                "kind": "reference pose (position m, quaternion w, x, y, z as exported)",
                "columns": [c.name for c in marks] + [quat_cols[a].name for a in "wxyz"],
                "source": path.name,
            }
            continue
        if marks:
            rec.markers.append(_marker_stream(path, dev, marks, values, t_ns))
            rec.metadata.setdefault(
                f"imulog.device.{dev}", {"format": fmt, "kind": "markers (mapping file)", "source": path.name}
            )
        quat = {c.axis: c for c in cols if c.quantity == "quat"}
        if quat:
            if set(quat) != set("wxyz"):
                missing = ", ".join(a for a in "wxyz" if a not in quat)
                raise ConversionError(path, f"orientation group {dev!r}: no quaternion column {missing}")
            q = np.column_stack([values[:, quat[a].index] for a in "wxyz"])
            rec.signals.append(orientation_stream(dev, t_ns, q, frame_id="reference"))
            rec.metadata[f"imulog.device.{dev}"] = {
                "format": fmt,
                "kind": "reference orientation (quaternion w, x, y, z as exported)",
                "orientation": {"topic": f"/orientation/{dev}", "columns": [quat[a].name for a in "wxyz"]},
                "source": path.name,
            }
        for c in cols:
            if c.quantity in ("quat", "marker"):
                continue
            if c.quantity in ("acc", "gyr", "mag", "temperature"):
                v = chosen_variant.setdefault(c.quantity, c.variant)
                if c.variant != v:
                    extra_cols.append(c)
                    continue
                key = (c.quantity, c.axis)
                if key in slots:
                    raise ConversionError(
                        path, f"two columns give {c.quantity} {c.axis or ''}: {slots[key].name!r} and {c.name!r}"
                    )
                slots[key] = c
            else:
                extra_cols.append(c)
        resolution: dict[str, dict[str, list[float]]] = {}
        for q in ("acc", "gyr", "mag"):
            axes = {a: slots.get((q, a)) for a in "xyz"}
            present = [a for a, c in axes.items() if c is not None]
            if not present:
                continue
            if len(present) != 3:
                missing = ", ".join(f"{q} {a}" for a, c in axes.items() if c is None)
                raise ConversionError(path, f"device {dev!r}: missing column(s) for {missing}")
            vec = streams[q] = np.empty((len(values), 3))
            for k, a in enumerate("xyz"):  # scaled straight into the (N, 3) array: no temporary per axis
                np.multiply(values[:, axes[a].index], axes[a].factor, out=vec[:, k])
            units[q] = axes["x"].unit
            factors = [float(axes[a].factor) for a in "xyz"]
            if any(f != 1.0 for f in factors):  # text * unit factor: the archive stores the text's numbers
                resolution[q] = {"scale": factors}
        if ("temperature", None) in slots:
            c = slots[("temperature", None)]
            streams["temperature"] = values[:, c.index] * c.factor
            units["temperature"] = c.unit
        if not streams and not extra_cols:
            continue
        if streams:
            meta = {
                "format": fmt,
                "model": device_meta.get("model", "Shimmer" if dev.startswith("shimmer") else ""),
                "serial": device_meta.get("serial", dev.split("_", 1)[1].upper() if dev.startswith("shimmer_") else ""),
                "rate_hz": rate_meta,
                "units": units,
                "time": time_desc,
                "source": path.name,
            }
            for k, v in device_meta.items():
                if k not in ("name",) and k not in meta:
                    meta[k] = v
            imu_meta = {**meta, "resolution": resolution} if resolution else dict(meta)
            rec.imus.append(ImuStream(name=dev, t_ns=t_ns, meta=imu_meta, **streams))
            rec.metadata[f"imulog.device.{dev}"] = meta
        if extra_cols:
            cols_out = []
            units_out = []
            data = []
            for c in extra_cols:
                conv = c.quantity in ("acc", "gyr", "mag", "temperature")
                cols_out.append(c.name)
                units_out.append(SI_UNIT[c.quantity] if conv else c.unit)
                data.append(values[:, c.index] * (c.factor if conv else 1.0))
            rec.signals.append(
                SignalStream(
                    topic=f"/signals/{dev}", t_ns=t_ns, columns=cols_out, units=units_out, values=np.column_stack(data)
                )
            )
    if not rec.imus and not rec.signals and not rec.markers:
        raise ConversionError(path, "no IMU or numeric columns found")
    return rec


def _marker_stream(path: Path, dev: str, cols: list[Column], values: np.ndarray, t_ns: np.ndarray) -> MarkerStream:
    """Marker columns (one per marker axis, from a mapping file) as one marker set, in m."""
    labels: list[str] = []
    axes: dict[tuple[str, str], Column] = {}
    for c in cols:
        if c.variant not in labels:
            labels.append(c.variant)
        if (c.variant, str(c.axis)) in axes:
            raise ConversionError(
                path,
                f"marker {c.variant!r} axis {c.axis}: two columns ({axes[(c.variant, str(c.axis))].name!r}, {c.name!r})",
            )
        axes[(c.variant, str(c.axis))] = c
    pos = np.full((len(values), len(labels), 3), np.nan)
    for m, label in enumerate(labels):
        missing = [a for a in "xyz" if (label, a) not in axes]
        if missing:
            raise ConversionError(
                path, f"marker {label!r}: no column for axis {', '.join(missing)} in the mapping file"
            )
        for k, a in enumerate("xyz"):
            c = axes[(label, a)]
            pos[:, m, k] = values[:, c.index] * c.factor
    return MarkerStream(name=dev, t_ns=t_ns, labels=labels, pos=pos, meta={"source": path.name})


class DelimitedConverter(Converter):
    name = "delimited"
    description = "delimited IMU text (CSV/TSV/semicolon; units in headers, a units row, or a mapping file)"
    extensions = (".csv", ".tsv", ".txt")
    example = "imulog convert fusion_sensor_data.csv -o trial.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head)
        if not lines:
            return 0.0
        if path.suffix.lower() in (".json", ".toml", ".md"):
            return 0.0
        if sibling_mapping(path) is not None:
            return 0.6
        try:
            layout = analyse_header(path, lines[:20])
        except ConversionError:
            return 0.0
        kinds = {c.quantity for c in layout.columns}
        if kinds & {"acc", "gyr"}:
            return 0.5
        axes = [c for c in layout.columns if c.quantity == "auto"]
        # bare X,Y,Z columns (units and quantity from the values): below every format that knows its layout
        return 0.35 if len(axes) >= 3 and {c.axis for c in axes} == {"x", "y", "z"} else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        path = Path(path)
        mapping_path = options.mapping or sibling_mapping(path)
        mapping = load_mapping(mapping_path) if mapping_path else None
        return read_delimited(
            path, mapping=mapping, rate_hz=options.rate_hz, head=read_head(path), units=unit_overrides(options.extra)
        )

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MB of text each (``imulog convert`` streams text files of 32 MB and more)."""
        options = options or ConvertOptions()
        path = Path(path)
        mapping_path = options.mapping or sibling_mapping(path)
        mapping = load_mapping(mapping_path) if mapping_path else None
        return iter_delimited(
            path, mapping=mapping, rate_hz=options.rate_hz, units=unit_overrides(options.extra), piece_bytes=PIECE_BYTES
        )


CONVERTER = DelimitedConverter()
