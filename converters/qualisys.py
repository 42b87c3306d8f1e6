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

Memory: one piece on purpose: a QTM export is one lab capture of markers.
"""

from __future__ import annotations

import re
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._common import check_increasing, head_lines, is_number, text_head_lines, to_ns
from imulog.converters._lab import read_table, trial_start
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
    path = Path(path)
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
    data = path.read_bytes().replace(b"\tNULL", b"\t").replace(b"\tnull", b"\t")
    values = read_table(path, delimiter="\t", skip_lines=skip, names=names, data=data)
    first_line = skip + 1
    if len(values) < n_frames:
        raise ConversionError(
            path,
            f"file ends after {len(values)} of NO_OF_FRAMES {n_frames} frames (cut off?)",
            line=first_line + len(values) - 1,
        )
    if "Time" in index and np.isfinite(values[:, index["Time"]]).all():
        t_ns = to_ns(values[:, index["Time"]], 1e9)
        time_source = "Time column (s)"
    elif "Frame" in index and np.isfinite(values[:, index["Frame"]]).all():
        t_ns = np.round((values[:, index["Frame"]] - 1) * (1e9 / freq)).astype(np.int64)
        time_source = f"(Frame - 1) / {freq:g} Hz"
    else:
        t_ns = np.round(np.arange(len(values)) * (1e9 / freq)).astype(np.int64)
        time_source = f"row index / {freq:g} Hz"
    check_increasing(path, t_ns, first_line)
    pos = np.stack([values[:, c] for c in cols], axis=1) / 1000.0  # mm -> m
    zeros = np.all(pos == 0.0, axis=2)
    pos[zeros] = np.nan
    rec = Recording(sources=[str(path)])
    rec.markers.append(MarkerStream("qualisys", t_ns, markers, pos, meta={"units": "m", "source": path.name}))
    meta: dict[str, Any] = {
        "format": "qualisys-tsv",
        "model": "Qualisys QTM",
        "rate_hz": freq,
        "units_in_file": "mm",
        "time": time_source,
        "header": {k: "\t".join(v) for k, v in info.items() if k != "MARKER_NAMES"},
        "missing_as_zero_samples": int(zeros.sum()),
        "source": path.name,
    }
    if "TRAJECTORY_TYPES" in info:
        meta["trajectory_types"] = dict(zip(markers, info["TRAJECTORY_TYPES"], strict=False))
    rec.metadata["imulog.device.qualisys"] = meta
    stamp = parse_time_stamp("\t".join(info.get("TIME_STAMP", [])))
    if stamp is not None:
        rec.metadata["imulog.trial"] = trial_start(stamp, f"{path.name}: TIME_STAMP (QTM PC local time)")
    return rec


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


CONVERTER = QualisysConverter()
