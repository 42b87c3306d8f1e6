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

Memory: in pieces of about 16 MB of text (:func:`iter_trc`), the whole-file ``convert`` being the one-piece case.
What only the whole file shows (the widest row, whether the ``Time`` column is usable in every row, the row count,
markers never seen) comes from first passes (field counts, then the two clock columns) or with the last piece.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import LENGTH_TO_M, check_increasing, head_lines, text_head_lines
from imulog.converters._pieces import PIECE_BYTES, iter_table, text_pieces
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
    """The whole file: :func:`iter_trc` as one piece."""
    (rec,) = iter_trc(path, options, piece_bytes=None)
    return rec


def iter_trc(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """The file in pieces of about ``piece_bytes`` of text (None: one piece), rows read by
    :func:`~imulog.converters._pieces.iter_table`. What the whole file decides comes from first passes: the widest
    row (rows shorter than the header are padded) and whether the ``Time`` column is usable everywhere (else every
    time is ``(Frame# - first) / DataRate``). The warnings (the time fallback, a header count that disagrees, markers
    never seen) come with the last piece."""
    path = Path(path)
    lay = _layout(path)
    delim, cols, skip, labels, info = lay["delim"], lay["cols"], lay["skip"], lay["labels"], lay["info"]
    widest = 0
    for piece, _, _, _ in text_pieces(path, skip, piece_bytes or max(1, path.stat().st_size)):
        widest = max(widest, max(line.rstrip(b"\r").count(delim.encode()) + 1 for line in piece.split(b"\n")))
    use = min(len(cols), max(widest, 2))  # every row short (trailing markers never recorded): pad them
    # ragged (short rows are padded), which read_table never checks for a cut final row
    table: dict[str, Any] = dict(delimiter=delim, skip_lines=skip, names=cols[:use], ragged=True, warnings=None)
    try:
        rate = float(info.get("DataRate", "nan"))
    except ValueError:
        rate = float("nan")
    cached = next(iter_table(path, **table, piece_bytes=None)) if piece_bytes is None else None

    def pieces(skip_columns: range) -> Iterator[tuple[np.ndarray, int]]:
        """The rows: one piece parsed once for both passes, or the pieces (the first pass skips the markers)."""
        if cached is not None:
            return iter([cached])
        return iter_table(path, **table, piece_bytes=piece_bytes, skip_columns=skip_columns)

    time_ok, frames_ok, first_frame, n = True, True, None, 0
    for values, _ in pieces(range(2, use)):
        n += len(values)
        time_ok = time_ok and bool(np.isfinite(values[:, 1]).all())
        frames_ok = frames_ok and bool(np.isfinite(values[:, 0]).all())
        if first_frame is None and len(values):
            first_frame = float(values[0, 0])
    warnings: list[str] = []
    if not time_ok:
        if not (rate > 0 and frames_ok):
            raise ConversionError(path, "the Time column has empty cells and DataRate or Frame# is unusable")
        warnings.append(f"{path.name}: Time column unusable; time = (Frame# - first) / DataRate")
    m = len(labels)
    for key, actual in (("NumFrames", n), ("NumMarkers", m)):
        declared = info.get(key, "")
        if declared.isdigit() and int(declared) != actual:
            warnings.append(f"{path.name}: header {key}={declared} but the file holds {actual}; read what is there")
    meta = {
        "format": "opensim-trc",
        "rate_hz": rate if rate > 0 else None,
        "units": lay["unit"],
        "header": info,
        "path_file_type": lay["path_file_type"],
        "time": "Time column (s) as written",
        "source": path.name,
    }
    scale = LENGTH_TO_M[lay["unit"].lower()]
    res = {"resolution": {"pos": {"scale": scale}}}  # the text's decimals times the unit factor
    seen = np.zeros(m, dtype=bool)
    before: int | None = None
    rows = pieces(range(0))
    nxt = next(rows, None)
    k = 0
    while nxt is not None:
        part, line = nxt
        nxt = next(rows, None)
        values = np.full((len(part), len(cols)), np.nan)
        values[:, :use] = part
        t_s = values[:, 1] if time_ok else (values[:, 0] - first_frame) / rate
        t_ns = np.round(t_s * 1e9).astype(np.int64)
        check_increasing(path, t_ns, line, "Time", before=before)
        if len(t_ns):
            before = int(t_ns[-1])
        pos = values[:, 2:].reshape(len(values), m, 3) * scale
        valid = np.isfinite(pos).all(axis=2)
        seen |= valid.any(axis=0)
        rec = Recording(sources=[str(path)])
        rec.markers.append(
            MarkerStream(name="trc", t_ns=t_ns, labels=labels, pos=pos, valid=valid, meta={**meta, **res})
        )
        if k == 0:
            rec.metadata["imulog.device.trc"] = dict(meta)
        if nxt is None:
            missing = [labels[j] for j in range(m) if not seen[j]]
            if missing:
                shown = ", ".join(missing[:5]) + (" ..." if len(missing) > 5 else "")
                warnings.append(f"{path.name}: {len(missing)} of {m} markers have no valid sample ({shown})")
            rec.warnings.extend(warnings)
        k += 1
        yield rec


def _layout(path: Path) -> dict[str, Any]:
    """The 5-line header: delimiter, keys, marker labels, unit, column names and where the rows start."""
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
    return dict(
        delim=delim, info=info, labels=labels, unit=unit, skip=skip, cols=cols,
        path_file_type=_split(lines[0], delim)[1:3],
    )  # fmt: skip


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

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """The file in pieces of about 16 MB of text (see :func:`iter_trc`)."""
        return iter_trc(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = OpenSimTrcConverter()
