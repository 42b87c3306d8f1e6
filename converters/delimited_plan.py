"""What the header and the first rows of a delimited text file say: the reading plan and the units to infer."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._common import (
    LENGTH_TO_M,
    TableSpec,
    head_lines,
    is_number,
    sanitize_name,
    split_row,
    unit_factor,
)
from imulog.converters.delimited_header import (
    INFER,
    Column,
    Layout,
    _group_quantity,
    _quantity_of,
    _tokens,
    analyse_header,
)
from imulog.converters.errors import ConversionError, excerpt
from imulog.converters.mapping import Mapping


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
