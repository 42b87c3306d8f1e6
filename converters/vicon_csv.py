"""Vicon Nexus CSV exports: Trajectories, Devices, Model Outputs, Segments and Joints sections.

Each section is: a name line (``Trajectories``), a rate line (``100``), a names row (``Subject:Marker`` over the
first column of each marker/device/output), a ``Frame,Sub Frame,X,Y,Z,...`` row, a units row (``mm``, ``V``,
``deg``) and data rows; sections are separated by blank lines. Empty cells are gaps: NaN with validity False,
never zeros. Time on the Vicon clock: ``t_ns = round((frame - 1 + sub_frame / n_sub) / rate_hz * 1e9)`` where
``rate_hz`` is the frame (trajectory) rate and ``n_sub`` the number of sub frames per frame.

Memory: one piece on purpose: a Nexus CSV is one lab trial (its sections are read from the file's bytes once).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from imulog.converters._common import (
    TableSpec,
    check_increasing,
    decode,
    looks_binary,
    read_head,
    read_numeric,
    read_source,
    split_row,
    text_head_lines,
    unit_overrides,
)
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import AnalogStream, MarkerStream, Recording, SignalStream
from imulog.numeric import finite_rows

_BLANK_LINE = re.compile(rb"\n[ \t]*\r?(?=\n)")
SECTIONS = ("Trajectories", "Devices", "Model Outputs", "Segments", "Joints")
LENGTH_TO_M = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}
# units converted on the way in (everything else is kept as found)
CONVERTED = {"mm": ("m", 1e-3), "cm": ("m", 1e-2), "n.mm": ("N.m", 1e-3), "nmm": ("N.m", 1e-3), "mm/s": ("m/s", 1e-3)}


@dataclass
class Section:
    name: str
    line: int  # 0-based line index of the name line
    nrows: int  # data rows
    offset: int = 0  # byte offset of the name line
    data_start: int = 0  # byte range of the data rows
    data_end: int = 0


def _first_cell(line: str) -> str:
    return line.split(",", 1)[0].strip().strip('"')


def find_sections(path: Path, data: bytes) -> list[Section]:
    """Section starts and data byte ranges (one vectorised newline scan): sections begin at the top or after
    a blank line; a section's data rows end at the next blank line or the end of the file."""
    blanks = [(m.start() + 1, m.end() + 1) for m in _BLANK_LINE.finditer(data)]  # (blank line start, after it)
    blank_starts = np.array([b for b, _ in blanks], dtype=np.int64)
    candidates = [0] + [after for _, after in blanks if after < len(data)]
    starts: list[tuple[int, str]] = []
    for pos in sorted(set(candidates)):
        line_end = data.find(b"\n", pos)
        first = decode(data[pos : line_end if line_end != -1 else len(data)]).rstrip("\r")
        name = _first_cell(first)
        if name in SECTIONS:
            starts.append((pos, name))
        elif pos == 0:
            raise ConversionError(
                path, f"not a Vicon Nexus CSV: first line must be one of {', '.join(SECTIONS)}", line=1
            )
        elif first.strip(" ,\t\r\n"):
            line = data.count(b"\n", 0, pos) + 1
            raise ConversionError(
                path, f"unexpected text after a blank line (expected a section name): {first[:30]!r}", line=line
            )
    sections = []
    for k, (offset, name) in enumerate(starts):
        end = starts[k + 1][0] if k + 1 < len(starts) else len(data)
        line0 = data.count(b"\n", 0, offset) if offset else 0
        data_start = offset
        for j in range(5):
            nxt = data.find(b"\n", data_start, end)
            if nxt == -1:
                raise ConversionError(path, f"{name} section header ends early", line=line0 + j + 1)
            data_start = nxt + 1
        later = blank_starts[(blank_starts >= data_start) & (blank_starts < end)]
        stop = int(later[0]) if len(later) else end
        first_end = data.find(b"\n", data_start, stop)
        if data_start >= stop or not data[data_start : first_end if first_end != -1 else stop].strip(b"\r\t ,"):
            raise ConversionError(path, f"{name} section has no data rows", line=line0 + 6)
        sections.append(Section(name=name, line=line0, nrows=-1, offset=offset, data_start=data_start, data_end=stop))
    return sections


def _header(path: Path, data: bytes, sec: Section) -> tuple[float, list[str], list[str], list[str], int]:
    pos = sec.offset
    rows = []
    for k in range(5):
        nxt = data.find(b"\n", pos)
        if nxt == -1:
            raise ConversionError(path, f"{sec.name} section header ends early", line=sec.line + k + 1)
        rows.append(decode(data[pos:nxt]).rstrip("\r"))
        pos = nxt + 1
    rate_cell = split_row(rows[1], ",")[0]
    try:
        rate = float(rate_cell)
    except ValueError:
        raise ConversionError(path, f"{sec.name} rate {rate_cell!r} is not a number", line=sec.line + 2) from None
    if not (rate > 0 and np.isfinite(rate)):
        raise ConversionError(path, f"{sec.name} rate must be positive, got {rate_cell!r}", line=sec.line + 2)
    names, header, units = (split_row(r, ",") for r in rows[2:5])
    if len(header) < 2 or header[0].lower() != "frame" or header[1].lower() != "sub frame":
        raise ConversionError(path, "expected 'Frame,Sub Frame,...' header", line=sec.line + 4)
    width = len(header)
    while width > 2 and header[width - 1] == "":
        width -= 1
    header = header[:width]
    names = (names + [""] * width)[:width]
    units = (units + [""] * width)[:width]
    nxt = data.find(b"\n", pos)
    first_data = data[pos : nxt if nxt != -1 else len(data)]
    return rate, names, header, units, first_data.count(b",") + 1


def _read_block(
    path: Path, data: bytes, sec: Section, header: list[str], ncols_file: int, warnings: list[str]
) -> np.ndarray:
    """The section's numbers; a final row cut off by a truncated file is dropped with a warning (Nexus pads every
    row to the full width, so a short row would otherwise be read as gaps and the cut go unnoticed)."""
    spec = TableSpec(
        path=path,
        delimiter=",",
        skip_lines=sec.line + 5,
        names=[*header, *[""] * (ncols_file - len(header))],
        optional=set(range(2, ncols_file)),
        ignore=set(range(len(header), ncols_file)),
        byte_range=(sec.data_start, sec.data_end),
        warnings=warnings,
        short_rows_are_errors=False,
    )
    return read_numeric(spec, data)[:, : len(header)]


def _groups(path: Path, names: list[str], header: list[str], line: int, what: str) -> list[tuple[str, list[int]]]:
    """(name, column indices) for each labelled group of columns (a label spans until the next one)."""
    groups: list[tuple[str, list[int]]] = []
    for j in range(2, len(header)):
        if names[j]:
            groups.append((names[j], [j]))
        elif groups:
            groups[-1][1].append(j)
        else:
            raise ConversionError(path, f"column {j + 1} has no {what} name", line=line)
    labels = [g[0] for g in groups]
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise ConversionError(path, f"duplicated {what} {dup[0]!r}", line=line)
    return groups


def _time(path: Path, frame: np.ndarray, sub: np.ndarray, frame_rate: float, n_sub: int, first_line: int) -> np.ndarray:
    if np.any(frame != np.round(frame)) or np.any(sub != np.round(sub)) or np.any(sub < 0) or np.any(sub >= n_sub):
        bad = int(np.nonzero((frame != np.round(frame)) | (sub != np.round(sub)) | (sub < 0) | (sub >= n_sub))[0][0])
        raise ConversionError(path, f"bad frame/sub frame {frame[bad]:g}/{sub[bad]:g}", line=first_line + bad)
    t = np.round(((frame - 1.0) * n_sub + sub) * (1e9 / (frame_rate * n_sub))).astype(np.int64)
    check_increasing(path, t, first_line, "Frame")
    return t


def read_vicon_csv(path: Path, name: str = "vicon", user_units: dict[str, str] | None = None) -> Recording:
    """Read every section of a Nexus CSV export into one Recording (markers, analogs, model outputs).

    ``user_units={"markers": "mm"}`` replaces the units row of the Trajectories section (``--unit markers=mm``)."""
    path = Path(path)
    head = read_head(path, 4096)
    if not head.strip():
        raise ConversionError(path, "empty file")
    if looks_binary(head):
        raise ConversionError(path, "binary data, not a text export")
    data = read_source(path)
    sections = find_sections(path, data)
    parsed = []
    warnings: list[str] = []
    for sec in sections:
        rate, names, header, units, first_width = _header(path, data, sec)
        # width of the data rows (may carry padding commas beyond the header)
        ncols_file = max(len(header), first_width)
        values = _read_block(path, data, sec, header, ncols_file, warnings)
        parsed.append((sec, rate, names, header, units, values))
    traj_rate = next((p[1] for p in parsed if p[0].name == "Trajectories"), None)

    rec = Recording(sources=[str(path)], warnings=warnings)
    meta: dict = {"format": "vicon-csv", "model": "Vicon Nexus"}
    for sec, rate, names, header, units, values in parsed:
        first_line = sec.line + 6
        frame, sub = values[:, 0], values[:, 1]
        if sec.name == "Devices":
            if traj_rate:
                n_sub = round(rate / traj_rate)
                if n_sub < 1 or abs(n_sub * traj_rate - rate) > 1e-6 * rate:
                    raise ConversionError(
                        path,
                        f"device rate {rate:g} Hz is not a multiple of the frame rate {traj_rate:g} Hz",
                        line=sec.line + 2,
                    )
            else:
                n_sub = int(np.nanmax(sub)) + 1 if len(sub) else 1
            frame_rate = rate / n_sub
        else:
            n_sub = 1
            frame_rate = rate
        t_ns = _time(path, frame, sub, frame_rate, n_sub, first_line)
        if sec.name == "Trajectories":
            groups = _groups(path, names, header, sec.line + 3, "marker")
            labels = [g[0] for g in groups]
            if user_units and "markers" in user_units:
                units = [*units[:2], *[user_units["markers"].strip().lower()] * (len(units) - 2)]  # the user's unit
            for label, cols in groups:
                if len(cols) != 3 or [header[c].upper() for c in cols] != ["X", "Y", "Z"]:
                    raise ConversionError(path, f"marker {label!r} must have X,Y,Z columns", line=sec.line + 4)
                for c in cols:
                    if units[c] not in LENGTH_TO_M:
                        raise ConversionError(
                            path, f"unknown length unit {units[c]!r}", line=sec.line + 5, column=f"{label} {header[c]}"
                        )
            scale = np.array([LENGTH_TO_M[u] for u in units[2 : 2 + 3 * len(groups)]])
            pos = np.multiply(values[:, 2 : 2 + 3 * len(groups)], scale, order="C").reshape(len(values), len(groups), 3)
            valid = finite_rows(pos)
            rec.markers.append(
                MarkerStream(
                    name=name,
                    t_ns=t_ns,
                    labels=labels,
                    pos=pos,
                    valid=valid,
                    # text x unit factor: the archive stores the text's decimals as counts (imulog.archive.numbers)
                    meta={
                        "rate_hz": rate,
                        "units": units[2],
                        "source": path.name,
                        "resolution": {"pos": {"scale": scale}},
                    },
                )
            )
            meta.update(rate_hz=rate, marker_units=units[2], markers=len(labels), marker_source=path.name)
        elif sec.name == "Devices":
            groups = _groups(path, names, header, sec.line + 3, "device")
            ch_names, ch_units, cols_all = [], [], []
            for dev, cols in groups:
                for c in cols:
                    unit = units[c]
                    conv = CONVERTED.get(unit.lower())
                    ch_names.append(f"{dev}/{header[c]}")
                    ch_units.append(conv[0] if conv else unit)
                    cols_all.append(values[:, c] * (conv[1] if conv else 1.0))
            if len(set(ch_names)) != len(ch_names):
                raise ConversionError(path, "duplicated device channel names", line=sec.line + 4)
            rec.analogs.append(
                AnalogStream(
                    name=name,
                    t_ns=t_ns,
                    channel_names=ch_names,
                    units=ch_units,
                    values=np.column_stack(cols_all),
                    meta={"rate_hz": rate, "source": path.name, "devices": [g[0] for g in groups]},
                )
            )
            meta.update(analog_rate_hz=rate, sub_frames=n_sub, devices=[g[0] for g in groups], analog_source=path.name)
        else:
            groups = _groups(path, names, header, sec.line + 3, "output")
            cols_out, units_out, data_out = [], [], []
            for label, cols in groups:
                for c in cols:
                    conv = CONVERTED.get(units[c].lower())
                    cols_out.append(f"{label}.{header[c]}")
                    units_out.append(conv[0] if conv else units[c])
                    data_out.append(values[:, c] * (conv[1] if conv else 1.0))
            topic = "/vicon/" + sec.name.lower().replace(" ", "_")
            meta[f"{sec.name.lower().replace(' ', '_')}_source"] = path.name
            rec.signals.append(
                SignalStream(
                    topic=topic, t_ns=t_ns, columns=cols_out, units=units_out, values=np.column_stack(data_out)
                )
            )
    rec.metadata[f"imulog.device.{name}"] = meta
    return rec


class ViconCsvConverter(Converter):
    name = "vicon-csv"
    description = "Vicon Nexus CSV export (Trajectories, Devices, Model Outputs, Segments, Joints)"
    extensions = (".csv",)
    example = "imulog convert markers.csv analogs.csv -o trial.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 3)
        if not lines:
            return 0.0
        first = _first_cell(lines[0])
        if first in SECTIONS and len(lines) > 1 and _first_cell(lines[1]).replace(".", "", 1).isdigit():
            return 0.95
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        extra = options.extra if options else {}
        return read_vicon_csv(Path(path), name=extra.get("vicon_name", "vicon"), user_units=unit_overrides(extra))


CONVERTER = ViconCsvConverter()
