"""Qualisys Track Manager (QTM) ``.tsv`` 3D export: markers in mm -> ``/markers/qualisys`` in m.

Layout (tab separated)::

    NO_OF_FRAMES    1200
    NO_OF_CAMERAS   8
    NO_OF_MARKERS   3
    FREQUENCY       100
    NO_OF_ANALOG    0
    ANALOG_FREQUENCY    0
    DESCRIPTION     --
    TIME_STAMP      2019-05-22, 14:15:16.123    5021.334      (date, then seconds since the QTM PC started)
    DATA_INCLUDED   3D
    MARKER_NAMES    LASI    RASI    C7
    TRAJECTORY_TYPES    Measured    Measured    Gap-filled    (newer QTM)
    Frame   Time    LASI X  LASI Y  LASI Z  ...              (when exported with the TSV header / time data)
    1       0.00000 123.456 ...

Missing 3D data is exported as empty cells, ``NULL`` or ``0.000 0.000 0.000``; all three are gaps (invalid samples).
The clock is the ``Time`` column (s) when present, else ``(Frame - 1) / FREQUENCY`` (else sample index /
``FREQUENCY``). ``TIME_STAMP`` (the QTM PC's local time, no zone) -> ``imulog.trial`` ``start_time``.
``NO_OF_FRAMES`` is checked against the rows (a cut-off file is an error naming its last line).

Memory: in pieces of about 16 MB of text (:func:`iter_qualisys`), the whole-file ``convert`` being the one-piece
case. What only the whole file shows (whether the ``Time``/``Frame`` column has an empty cell anywhere, the row count
against ``NO_OF_FRAMES``) comes from a first pass over those two columns; the zero-sample count in the device record
is the running total, the last piece's being the file's.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import check_increasing, head_lines, is_number, text_head_lines, to_ns
from imulog.converters._lab import trial_start
from imulog.converters._pieces import PIECE_BYTES, hand_over, iter_table
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import MarkerStream, Recording

_KEY = re.compile(r"^[A-Z][A-Z0-9_]+$")


def parse_time_stamp(value: str) -> datetime | None:
    """``2019-05-22, 14:15:16.123`` (QTM's TIME_STAMP date part) -> naive local datetime."""
    text = value.split("\t")[0].strip()
    for fmt in ("%Y-%m-%d, %H:%M:%S.%f", "%Y-%m-%d, %H:%M:%S", "%Y-%m-%d %H:%M:%S.%f", "%Y-%m-%d %H:%M:%S"):
        try:
            return datetime.strptime(text, fmt)
        except ValueError:
            continue
    return None


def read_qualisys(path: Path) -> Recording:
    """The whole export: :func:`iter_qualisys` as one piece."""
    (rec,) = iter_qualisys(path, piece_bytes=None)
    return rec


def _no_null(data: bytes) -> bytes:
    """QTM's ``NULL`` cells (missing 3D data) as empty cells."""
    return data.replace(b"\tNULL", b"\t").replace(b"\tnull", b"\t")


def iter_qualisys(path: Path, piece_bytes: int | None = PIECE_BYTES) -> Iterator[Recording]:
    """The export in pieces of about ``piece_bytes`` of text (None: one piece), rows read by
    :func:`~imulog.converters._pieces.iter_table`. Which clock the file has (a ``Time`` or ``Frame`` column with no
    empty cell in the whole file) and its row count (against ``NO_OF_FRAMES``) come from a first pass over those
    columns; the count of samples exported as zeros grows piece by piece in the device record (the last piece's is
    the file's)."""
    path = Path(path)
    lay = _layout(path)
    names, index, freq, n_frames = lay["names"], lay["index"], lay["freq"], lay["n_frames"]
    first_line = lay["skip"] + 1
    table: dict[str, Any] = dict(delimiter="\t", skip_lines=lay["skip"], names=names, transform=_no_null)
    notes: list[str] = []  # a cut final row: from the one parse, else from the pass that reads the markers
    cached = next(iter_table(path, **table, piece_bytes=None, warnings=notes)) if piece_bytes is None else None

    def pieces(skip_columns: list[int]) -> Iterator[tuple[np.ndarray, int]]:
        if cached is not None:
            return iter([cached])
        warnings = None if skip_columns else notes
        return iter_table(path, **table, piece_bytes=piece_bytes, skip_columns=skip_columns, warnings=warnings)

    clocks = [c for c in ("Time", "Frame") if c in index]
    finite = dict.fromkeys(clocks, True)
    rows: int | None = None
    if clocks:  # pass 1: the clock columns only
        rows = 0
        others = [j for j in range(len(names)) if j not in {index[c] for c in clocks}]
        for values, _ in pieces(others):
            rows += len(values)
            for c in clocks:
                finite[c] = finite[c] and bool(np.isfinite(values[:, index[c]]).all())
        _check_frames(path, rows, n_frames, first_line)
    if finite.get("Time", False):
        time_source = "Time column (s)"
    elif finite.get("Frame", False):
        time_source = f"(Frame - 1) / {freq:g} Hz"
    else:
        time_source = f"row index / {freq:g} Hz"
    device = {**lay["device"], "time": time_source}
    done, zeros_total = 0, 0
    origin: float | None = None
    before: int | None = None
    for k, (values, line) in enumerate(pieces([])):
        if time_source.startswith("Time"):
            origin = float(values[0, index["Time"]]) if origin is None and len(values) else origin
            t_ns = to_ns(values[:, index["Time"]], 1e9, origin=origin)
        elif time_source.startswith("(Frame"):
            t_ns = np.round((values[:, index["Frame"]] - 1) * (1e9 / freq)).astype(np.int64)
        else:
            t_ns = np.round(np.arange(done, done + len(values)) * (1e9 / freq)).astype(np.int64)
        done += len(values)
        check_increasing(path, t_ns, line, before=before)
        if len(t_ns):
            before = int(t_ns[-1])
        pos = np.stack([values[:, c] for c in lay["cols"]], axis=1) / 1000.0  # mm -> m
        zeros = np.all(pos == 0.0, axis=2)
        pos[zeros] = np.nan
        zeros_total += int(zeros.sum())
        rec = Recording(sources=[str(path)])
        meta = {"units": "m", "source": path.name}
        rec.markers.append(MarkerStream("qualisys", t_ns, lay["markers"], pos, meta=meta))
        rec.metadata["imulog.device.qualisys"] = {**device, "missing_as_zero_samples": zeros_total}
        if k == 0 and lay["stamp"] is not None:
            rec.metadata["imulog.trial"] = trial_start(lay["stamp"], f"{path.name}: TIME_STAMP (QTM PC local time)")
        yield hand_over(notes, rec)
    if rows is None:
        _check_frames(path, done, n_frames, first_line)


def _check_frames(path: Path, rows: int, n_frames: int, first_line: int) -> None:
    """A file with fewer rows than its ``NO_OF_FRAMES`` is cut off: one line naming its last row."""
    if rows < n_frames:
        raise ConversionError(
            path, f"file ends after {rows} of NO_OF_FRAMES {n_frames} frames (cut off?)", line=first_line + rows - 1
        )


def _layout(path: Path) -> dict[str, Any]:
    """The header: keys, markers, column names, where the rows start and the device record (errors name lines)."""
    lines = head_lines(path, max_lines=400)
    info: dict[str, list[str]] = {}
    n = 0
    for line in lines:
        cells = line.rstrip("\r").split("\t")
        if not _KEY.match(cells[0].strip()):
            break
        info[cells[0].strip()] = [c.strip() for c in cells[1:]]
        n += 1
    for key in ("NO_OF_FRAMES", "FREQUENCY", "MARKER_NAMES"):
        if key not in info:
            raise ConversionError(path, f"no {key} line in the header", line=n + 1)
    markers = [m for m in info["MARKER_NAMES"] if m]
    try:
        n_frames = int(info["NO_OF_FRAMES"][0])
        freq = float(info["FREQUENCY"][0])
    except (ValueError, IndexError):
        raise ConversionError(path, "NO_OF_FRAMES or FREQUENCY is not a number") from None
    if freq <= 0:
        raise ConversionError(path, f"FREQUENCY {freq:g} must be positive")
    if "NO_OF_MARKERS" in info and info["NO_OF_MARKERS"] and int(info["NO_OF_MARKERS"][0]) != len(markers):
        raise ConversionError(
            path, f"NO_OF_MARKERS is {info['NO_OF_MARKERS'][0]} but MARKER_NAMES lists {len(markers)}", line=n
        )
    if len(set(markers)) != len(markers):
        raise ConversionError(path, "a marker name appears twice in MARKER_NAMES")
    if n >= len(lines):
        raise ConversionError(path, "no data after the header", line=n)
    first = lines[n].rstrip("\r").split("\t")
    has_names_row = bool(first) and not is_number(first[0].strip())
    if has_names_row:
        names = [c.strip() for c in first]
        while names and names[-1] == "":
            names.pop()
        skip = n + 1
    else:
        width = len([c for c in first])
        extra = width - 3 * len(markers)
        if extra not in (0, 2) and not (extra == 3 and first[-1].strip() == ""):
            raise ConversionError(
                path, f"{width} fields: expected 3 per marker ({len(markers)} markers), plus Frame and Time", line=n + 1
            )
        names = (["Frame", "Time"] if extra >= 2 else []) + [f"{m} {a}" for m in markers for a in "XYZ"]
        skip = n
    index = {c: i for i, c in enumerate(names)}
    cols = []
    for m in markers:
        try:
            cols.append([index[f"{m} {a}"] for a in "XYZ"])
        except KeyError:
            raise ConversionError(path, f"no '{m} X/Y/Z' columns for marker {m!r}", line=skip) from None
    device: dict[str, Any] = {
        "format": "qualisys-tsv",
        "model": "Qualisys QTM",
        "rate_hz": freq,
        "units_in_file": "mm",
        "time": "",
        "header": {k: "\t".join(v) for k, v in info.items() if k != "MARKER_NAMES"},
        "missing_as_zero_samples": 0,
        "source": path.name,
    }
    if "TRAJECTORY_TYPES" in info:
        device["trajectory_types"] = dict(zip(markers, info["TRAJECTORY_TYPES"], strict=False))
    stamp = parse_time_stamp("\t".join(info.get("TIME_STAMP", [])))
    return dict(
        names=names, index=index, skip=skip, cols=cols, markers=markers, freq=freq, n_frames=n_frames,
        device=device, stamp=stamp,
    )  # fmt: skip


class QualisysConverter(Converter):
    name = "qualisys"
    description = "Qualisys QTM .tsv 3D export (NO_OF_FRAMES/FREQUENCY/MARKER_NAMES header; mm) -> /markers"
    extensions = (".tsv",)
    example = "imulog convert walk_3d.tsv -o walk.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 3)
        return 0.95 if lines and lines[0].startswith("NO_OF_FRAMES\t") else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_qualisys(Path(path))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """The export in pieces of about 16 MB of text (see :func:`iter_qualisys`)."""
        return iter_qualisys(Path(path), piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = QualisysConverter()
