"""OpenSim / Motion Analysis ``.trc`` marker trajectories.

Layout (Motion Analysis TRC as OpenSim's ``TRCFileAdapter`` reads and writes it), tab-separated in most files,
comma-separated after a spreadsheet round trip::

    PathFileType  4  (X/Y/Z)  <file name>
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  OrigNumFrames
    100       100         652        51          mm     100           1                   652
    Frame#  Time  ASISl  <empty>  <empty>  ASISr ...          (a marker name, then two empty cells)
    <empty> <empty> X1 Y1 Z1 X2 Y2 Z2 ...
    <an optional blank line>
    1       0     733.70 80.98 191.87 ...                        (an empty cell: the marker is missing)

Positions become one marker set ``/markers/trc`` in m (``Units`` mm, cm or m). Time is the ``Time`` column (s) as
written; when it has empty cells the frame number over ``DataRate`` is used (the file is refused when
neither works). Rows shorter than the header (trailing markers missing, as some exporters write) are padded with
missing markers. A ``NumFrames``/``NumMarkers`` that disagrees with the data is a warning; the data wins.

Memory: one piece on purpose: a ``.trc`` is one lab capture of markers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from imulog.converters._common import LENGTH_TO_M, check_increasing, head_lines, text_head_lines
from imulog.converters._lab import read_table
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import MarkerStream, Recording

HEADER_LINES = 5


def _split(line: str, delim: str) -> list[str]:
    return [c.strip() for c in line.rstrip("\r\n").split(delim)]


def _trim(cells: list[str]) -> list[str]:
    while cells and not cells[-1]:
        cells = cells[:-1]
    return cells


def read_trc(path: Path, options: ConvertOptions | None = None) -> Recording:
    path = Path(path)
    lines = head_lines(path, max_lines=8)
    if len(lines) < HEADER_LINES:
        raise ConversionError(path, "file ends inside the 5-line TRC header")
    delim = "\t" if "\t" in lines[0] else ","
    keys, vals = _trim(_split(lines[1], delim)), _split(lines[2], delim)
    info = {k: (vals[i] if i < len(vals) else "") for i, k in enumerate(keys)}
    names = _split(lines[3], delim)
    if len(names) < 2 or names[0].lower() != "frame#" or names[1].lower() != "time":
        raise ConversionError(path, "line 4 must start with 'Frame#' and 'Time'", line=4)
    labels = [c for c in names[2:] if c]
    if not labels:
        raise ConversionError(path, "no marker names", line=4)
    if len(set(labels)) != len(labels):
        dup = next(x for x in labels if labels.count(x) > 1)
        raise ConversionError(path, f"marker {dup!r} named twice", line=4)
    unit = info.get("Units", "").strip() or "mm"
    if unit.lower() not in LENGTH_TO_M:
        raise ConversionError(path, f"unknown Units {unit!r} (mm, cm or m)", line=3)
    skip = HEADER_LINES + (1 if len(lines) > HEADER_LINES and not lines[HEADER_LINES].strip(" \t,\r\n") else 0)
    cols = ["Frame#", "Time"] + [f"{m}.{a}" for m in labels for a in "XYZ"]
    warnings: list[str] = []
    data = path.read_bytes()
    widest = max((line.rstrip(b"\r").count(delim.encode()) + 1 for line in data.splitlines()[skip:]), default=0)
    use = min(len(cols), max(widest, 2))  # every row short (trailing markers never recorded): pad them
    part = read_table(
        path, delimiter=delim, skip_lines=skip, names=cols[:use], data=data, ragged=True, warnings=warnings
    )
    values = np.full((len(part), len(cols)), np.nan)
    values[:, :use] = part
    n, m = len(values), len(labels)
    try:
        rate = float(info.get("DataRate", "nan"))
    except ValueError:
        rate = float("nan")
    t_s = values[:, 1]
    if not np.isfinite(t_s).all():
        frames = values[:, 0]
        if not (rate > 0 and np.isfinite(frames).all()):
            raise ConversionError(path, "the Time column has empty cells and DataRate or Frame# is unusable")
        warnings.append(f"{path.name}: Time column unusable; time = (Frame# - first) / DataRate")
        t_s = (frames - frames[0]) / rate
    t_ns = np.round(t_s * 1e9).astype(np.int64)
    check_increasing(path, t_ns, skip + 1, "Time")
    for key, actual in (("NumFrames", n), ("NumMarkers", m)):
        declared = info.get(key, "")
        if declared.isdigit() and int(declared) != actual:
            warnings.append(f"{path.name}: header {key}={declared} but the file holds {actual}; read what is there")
    pos = values[:, 2:].reshape(n, m, 3) * LENGTH_TO_M[unit.lower()]
    valid = np.isfinite(pos).all(axis=2)
    missing = [labels[j] for j in range(m) if not valid[:, j].any()]
    if missing:
        shown = ", ".join(missing[:5]) + (" ..." if len(missing) > 5 else "")
        warnings.append(f"{path.name}: {len(missing)} of {m} markers have no valid sample ({shown})")
    meta = {
        "format": "opensim-trc",
        "rate_hz": rate if rate > 0 else None,
        "units": unit,
        "header": info,
        "path_file_type": _split(lines[0], delim)[1:3],
        "time": "Time column (s) as written",
        "source": path.name,
    }
    rec = Recording(sources=[str(path)])
    res = {"resolution": {"pos": {"scale": LENGTH_TO_M[unit.lower()]}}}  # the text's decimals times the unit factor
    rec.markers.append(MarkerStream(name="trc", t_ns=t_ns, labels=labels, pos=pos, valid=valid, meta={**meta, **res}))
    rec.metadata["imulog.device.trc"] = meta
    rec.warnings.extend(warnings)
    return rec


class OpenSimTrcConverter(Converter):
    name = "opensim-trc"
    description = "OpenSim / Motion Analysis .trc markers (tab or comma; mm, cm, m) -> /markers/trc in m"
    extensions = (".trc",)
    example = "imulog convert ../shared/data/devices/opensim_trc/markers.trc -o markers.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 5)
        if not lines or not lines[0].startswith("PathFileType"):
            return 0.0
        if len(lines) > 1 and lines[1].replace(",", "\t").split("\t")[0].strip() == "DataRate":
            return 0.97
        return 0.6

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_trc(Path(path), options)


CONVERTER = OpenSimTrcConverter()
