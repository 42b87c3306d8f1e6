"""Vicon Nexus CSV exports: Trajectories, Devices, Model Outputs, Segments and Joints sections.

Each section is: a name line (``Trajectories``), a rate line (``100``), a names row (``Subject:Marker`` over the
first column of each marker/device/output), a ``Frame,Sub Frame,X,Y,Z,...`` row, a units row (``mm``, ``V``,
``deg``) and data rows; sections are separated by blank lines. Empty cells are gaps: NaN with validity False,
never zeros. Time on the Vicon clock: ``t_ns = round((frame - 1 + sub_frame / n_sub) / rate_hz * 1e9)`` where
``rate_hz`` is the frame (trajectory) rate and ``n_sub`` the number of sub frames per frame.

Memory: in pieces (``iter_chunks``): the sections are found in one pass over the file a block at a time
(:mod:`imulog.converters.vicon_csv_sections`), then each section's data rows are read in pieces of about 16 MiB of
text by :func:`imulog.converters._pieces.iter_numeric` (the section's byte range alone), one section after the
other; a piece holds one section's stream. The first piece declares every section's span and stream ``meta``
(known from the headers and the first and last rows) and holds every section's stream, those of later sections
empty, so that the channels come in the order the whole file gives them. The whole-file ``convert`` is the one-piece
case (a piece per section).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._binary import concat_chunks
from imulog.converters._common import (
    TableSpec,
    check_increasing,
    looks_binary,
    read_head,
    text_head_lines,
    unit_overrides,
)
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError
from imulog.converters.vicon_csv_sections import (
    SECTIONS,
    Section,
    edge_rows,
    find_sections,
    first_cell,
    max_sub_frame,
    section_header,
)

from imulog.model import PIECES_RECORD, AnalogStream, MarkerStream, Recording, SignalStream
from imulog.numeric import finite_rows

__all__ = ["SECTIONS", "ViconCsvConverter", "find_sections", "iter_vicon_csv", "read_vicon_csv"]

LENGTH_TO_M = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}
# units converted on the way in (everything else is kept as found)
CONVERTED = {"mm": ("m", 1e-3), "cm": ("m", 1e-2), "n.mm": ("N.m", 1e-3), "nmm": ("N.m", 1e-3), "mm/s": ("m/s", 1e-3)}


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


def _time(
    path: Path,
    frame: np.ndarray,
    sub: np.ndarray,
    frame_rate: float,
    n_sub: int,
    first_line: int,
    before: int | None = None,
) -> np.ndarray:
    """Time stamps (ns) of rows from their frame and sub frame; ``before``: the previous piece's last time."""
    if np.any(frame != np.round(frame)) or np.any(sub != np.round(sub)) or np.any(sub < 0) or np.any(sub >= n_sub):
        bad = int(np.nonzero((frame != np.round(frame)) | (sub != np.round(sub)) | (sub < 0) | (sub >= n_sub))[0][0])
        raise ConversionError(path, f"bad frame/sub frame {frame[bad]:g}/{sub[bad]:g}", line=first_line + bad)
    t = np.round(((frame - 1.0) * n_sub + sub) * (1e9 / (frame_rate * n_sub))).astype(np.int64)
    check_increasing(path, t, first_line, "Frame", before=before)
    return t


class _Plan:
    """One section: its header as read and what its rows become (decided before any row is read)."""

    def __init__(self, path: Path, sec: Section, head: tuple, traj_rate: float | None, user_units: dict | None) -> None:
        rate, names, header, units, first_width = head
        self.sec, self.rate, self.header = sec, rate, header
        self.ncols_file = max(len(header), first_width)  # data rows may carry padding commas beyond the header
        self.n_sub, self.frame_rate = 1, rate
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
                top = max_sub_frame(path, sec, _pieces.PIECE_BYTES)
                n_sub = int(top) + 1 if np.isfinite(top) else 1
            self.n_sub, self.frame_rate = n_sub, rate / n_sub
        if sec.name == "Trajectories":
            self.groups = _groups(path, names, header, sec.line + 3, "marker")
            if user_units and "markers" in user_units:
                units = [*units[:2], *[user_units["markers"].strip().lower()] * (len(units) - 2)]  # the user's unit
            for label, cols in self.groups:
                if len(cols) != 3 or [header[c].upper() for c in cols] != ["X", "Y", "Z"]:
                    raise ConversionError(path, f"marker {label!r} must have X,Y,Z columns", line=sec.line + 4)
                for c in cols:
                    if units[c] not in LENGTH_TO_M:
                        raise ConversionError(
                            path, f"unknown length unit {units[c]!r}", line=sec.line + 5, column=f"{label} {header[c]}"
                        )
            self.scale = np.array([LENGTH_TO_M[u] for u in units[2 : 2 + 3 * len(self.groups)]])
            self.topic = None
            # text x unit factor: the archive stores the text's decimals as counts (imulog.archive.numbers)
            self.meta: dict[str, Any] = {
                "rate_hz": rate,
                "units": units[2],
                "source": path.name,
                "resolution": {"pos": {"scale": self.scale}},
            }
            self.device = dict(rate_hz=rate, marker_units=units[2], markers=len(self.groups), marker_source=path.name)
            return
        what = "device" if sec.name == "Devices" else "output"
        self.groups = _groups(path, names, header, sec.line + 3, what)
        self.columns, self.units, self.factors = [], [], []
        for label, cols in self.groups:
            for c in cols:
                conv = CONVERTED.get(units[c].lower())
                self.columns.append(f"{label}/{header[c]}" if what == "device" else f"{label}.{header[c]}")
                self.units.append(conv[0] if conv else units[c])
                self.factors.append((c, conv[1] if conv else 1.0))
        if sec.name == "Devices":
            if len(set(self.columns)) != len(self.columns):
                raise ConversionError(path, "duplicated device channel names", line=sec.line + 4)
            devices = [g[0] for g in self.groups]
            self.meta = {"rate_hz": rate, "source": path.name, "devices": devices}
            self.device = dict(analog_rate_hz=rate, sub_frames=self.n_sub, devices=devices, analog_source=path.name)
        else:
            self.meta = {}
            self.device = {f"{sec.name.lower().replace(' ', '_')}_source": path.name}

    def topic_of(self, name: str) -> str:
        kind = {"Trajectories": "/markers/", "Devices": "/analog/"}.get(self.sec.name)
        return f"{kind}{name}" if kind else "/vicon/" + self.sec.name.lower().replace(" ", "_")

    def times(self, path: Path, values: np.ndarray, first_line: int, before: int | None = None) -> np.ndarray:
        return _time(path, values[:, 0], values[:, 1], self.frame_rate, self.n_sub, first_line, before)

    def span(self, path: Path) -> list[int] | None:
        """First and last time stamp of the section (from its first and last rows), or None."""
        edges = edge_rows(path, self.sec)
        if edges is None:
            return None
        (f0, s0), (f1, s1) = edges
        t = np.round(((np.array([f0, f1]) - 1.0) * self.n_sub + [s0, s1]) * (1e9 / (self.frame_rate * self.n_sub)))
        return [int(t[0]), int(t[1])]

    def stream(self, path: Path, name: str, t_ns: np.ndarray, values: np.ndarray) -> Any:
        """This section's stream of one piece of rows."""
        if self.sec.name == "Trajectories":
            n = len(self.groups)
            pos = np.multiply(values[:, 2 : 2 + 3 * n], self.scale, order="C").reshape(len(values), n, 3)
            labels = [g[0] for g in self.groups]
            return MarkerStream(name=name, t_ns=t_ns, labels=labels, pos=pos, valid=finite_rows(pos), meta=self.meta)
        data = np.column_stack([values[:, c] * f for c, f in self.factors])
        if self.sec.name == "Devices":
            return AnalogStream(
                name=name,
                t_ns=t_ns,
                channel_names=list(self.columns),
                units=list(self.units),
                values=data,
                meta=self.meta,
            )
        return SignalStream(
            topic=self.topic_of(name), t_ns=t_ns, columns=list(self.columns), units=list(self.units), values=data
        )


def _plans(path: Path, user_units: dict[str, str] | None) -> list[_Plan]:
    head = read_head(path, 4096)
    if not head.strip():
        raise ConversionError(path, "empty file")
    if looks_binary(head):
        raise ConversionError(path, "binary data, not a text export")
    sections = find_sections(path)
    heads = [section_header(path, sec) for sec in sections]
    traj_rate = next((h[0] for sec, h in zip(sections, heads, strict=True) if sec.name == "Trajectories"), None)
    return [_Plan(path, sec, h, traj_rate, user_units) for sec, h in zip(sections, heads, strict=True)]


def iter_vicon_csv(
    path: Path,
    name: str = "vicon",
    user_units: dict[str, str] | None = None,
    piece_bytes: int | None = _pieces.PIECE_BYTES,
) -> Iterator[Recording]:
    """Every section of a Nexus CSV export, one after the other, each in pieces of about ``piece_bytes`` of text
    (None: a piece per section); the first piece declares every section's span and stream meta.

    ``user_units={"markers": "mm"}`` replaces the units row of the Trajectories section (``--unit markers=mm``)."""
    path = Path(path)
    plans = _plans(path, user_units)
    device: dict[str, Any] = {"format": "vicon-csv", "model": "Vicon Nexus"}
    for pl in plans:
        device.update(pl.device)
    declared: dict[str, Any] = {"spans": {}, "meta": {}}
    for pl in plans:
        declared["spans"][pl.topic_of(name)] = pl.span(path)
        if pl.meta:
            declared["meta"][pl.topic_of(name)] = pl.meta
    first = True
    for pl in plans:
        sec = pl.sec
        spec = TableSpec(
            path=path,
            delimiter=",",
            skip_lines=sec.line + 5,
            names=[*pl.header, *[""] * (pl.ncols_file - len(pl.header))],
            optional=set(range(2, pl.ncols_file)),
            ignore=set(range(len(pl.header), pl.ncols_file)),
            byte_range=(sec.data_start, sec.data_end),
            short_rows_are_errors=False,
        )
        before = None
        for part in _pieces.iter_numeric(spec, piece_bytes or max(1, sec.data_end - sec.data_start)):
            values = part.values[:, : len(pl.header)]
            t_ns = pl.times(path, values, part.first_line, before)
            before = int(t_ns[-1]) if len(t_ns) else before
            rec = Recording(sources=[str(path)], warnings=list(part.warnings))
            for other in plans if first else [pl]:  # the first piece opens every section's stream, in kind order
                if other is pl:
                    stream = pl.stream(path, name, t_ns, values)
                else:
                    stream = other.stream(path, name, t_ns[:0], np.zeros((0, len(other.header))))
                {MarkerStream: rec.markers, AnalogStream: rec.analogs}.get(type(stream), rec.signals).append(stream)
            rec.metadata[f"imulog.device.{name}"] = dict(device)
            if first and piece_bytes is not None:
                rec.metadata[PIECES_RECORD] = declared
            first = False
            yield rec


def read_vicon_csv(path: Path, name: str = "vicon", user_units: dict[str, str] | None = None) -> Recording:
    """Every section of a Nexus CSV export as one Recording (markers, analogs, model outputs): a piece per section
    of :func:`iter_vicon_csv`, joined."""
    return concat_chunks(iter_vicon_csv(path, name, user_units, piece_bytes=None))


class ViconCsvConverter(Converter):
    name = "vicon-csv"
    description = "Vicon Nexus CSV export (Trajectories, Devices, Model Outputs, Segments, Joints)"
    extensions = (".csv",)
    example = "imulog convert markers.csv analogs.csv -o trial.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 3)
        if not lines:
            return 0.0
        first = first_cell(lines[0])
        if first in SECTIONS and len(lines) > 1 and first_cell(lines[1]).replace(".", "", 1).isdigit():
            return 0.95
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        extra = options.extra if options else {}
        return read_vicon_csv(Path(path), name=extra.get("vicon_name", "vicon"), user_units=unit_overrides(extra))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        extra = options.extra if options else {}
        name = extra.get("vicon_name", "vicon")
        return iter_vicon_csv(Path(path), name, unit_overrides(extra), piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = ViconCsvConverter()
