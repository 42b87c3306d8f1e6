"""OptiTrack Motive CSV exports (format 1.21 to 1.23+): rigid bodies as poses, markers with occlusions as gaps.

Layout::

    Format Version,1.21,Take Name,...,Capture Frame Rate,120.000000,Export Frame Rate,120.000000,
        Capture Start Time,2016-01-05 03.49.50.755 PM,...,Rotation Type,Quaternion,Length Units,Meters,...
    <blank>
    ,,Rigid Body,...,Rigid Body Marker,...,Marker,...          (1.23: ,Type,Rigid Body,...)
    ,,Rigid Body 1,...,Rigid Body 1_1,...,Unlabeled:108,...     (1.23: ,Name,...)
    ,,"CF5107FC...",...                                          (1.23: ,ID,...)
    ,,Rotation,Rotation,Rotation,Rotation,Position,...,Error Per Marker,...
    Frame,Time,X,Y,Z,W,X,Y,Z,,...                                (1.23: Frame,Time (Seconds),...)

* a rigid body's ``Rotation`` X,Y,Z,W (quaternion, **scalar last**) and ``Position`` -> ``/poses/<rigid body>``
  (w,x,y,z; m), its ``Error Per Marker``/``Mean Marker Error`` -> ``/signals/<rigid body>``;
* ``Marker`` columns (labelled, unlabelled and the rigid bodies' measured markers) -> ``/markers/motive``;
  ``Rigid Body Marker`` columns (where the model puts each marker) -> ``/markers/motive_rigid_body_markers`` and
  their ``Marker Quality`` -> ``/signals/motive_marker_quality``; empty cells (occlusions) are gaps (invalid);
* lengths in ``Length Units`` (Meters, Centimeters, Millimeters) -> m; the ``Time`` column (s) is the clock;
* ``Capture Start Time`` (local time of the capture PC, no zone) -> ``imulog.trial`` ``start_time``.

Memory: in pieces of about 16 MB of text (:func:`iter_motive`, rows by ``_pieces.iter_table``), the whole-file
``convert`` being the one-piece case: the header says every stream, unit and the start, so the first piece needs to
declare nothing; memory is bounded by a piece, whatever the take's length.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import check_increasing, head_lines, sanitize_name, text_head_lines, to_ns
from imulog.converters._lab import trial_start
from imulog.converters._pieces import PIECE_BYTES, hand_over, iter_table
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import MarkerStream, PoseStream, Recording, SignalStream

LENGTH = {"meters": 1.0, "meter": 1.0, "m": 1.0, "centimeters": 0.01, "cm": 0.01, "millimeters": 0.001, "mm": 0.001}
_LABELS = {"type", "name", "id"}


def parse_start_time(text: str) -> datetime | None:
    """``2016-01-05 03.49.50.755 PM`` (Motive's format: dots in the time, 12-hour clock) -> naive datetime."""
    text = text.strip()
    for fmt in ("%Y-%m-%d %I.%M.%S.%f %p", "%Y-%m-%d %I.%M.%S %p", "%Y-%m-%d %H.%M.%S.%f", "%Y-%m-%d %H:%M:%S.%f"):
        try:
            return datetime.strptime(text, fmt)
        except ValueError:
            continue
    return None


def _info(first: list[str]) -> dict[str, str]:
    return {first[i].strip(): first[i + 1].strip() for i in range(0, len(first) - 1, 2) if first[i].strip()}


def read_motive(path: Path) -> Recording:
    """The whole take: :func:`iter_motive` as one piece."""
    (rec,) = iter_motive(path, piece_bytes=None)
    return rec


def iter_motive(path: Path, piece_bytes: int | None = PIECE_BYTES) -> Iterator[Recording]:
    """The take in pieces of about ``piece_bytes`` of text (None: one piece), rows read by
    :func:`~imulog.converters._pieces.iter_table`. The header says everything the pieces share (streams, units,
    rate, start time); the ``Time`` column is converted relative to the file's first time, as in one piece."""
    path = Path(path)
    layout = _layout(path)
    before: int | None = None
    origin: float | None = None
    time_name = layout["axes"][1].strip()
    notes: list[str] = []
    rows = iter_table(
        path,
        delimiter=",",
        skip_lines=layout["skip"],
        names=layout["col_names"],
        required=[0, 1],
        piece_bytes=piece_bytes,
        warnings=notes,
    )
    for k, (values, first_line) in enumerate(rows):
        if origin is None and len(values):
            origin = float(values[0, 1])
        try:
            t_ns = to_ns(values[:, 1], 1e9, origin=origin)
        except ValueError as e:
            raise ConversionError(path, str(e), column=layout["axes"][1]) from None
        check_increasing(path, t_ns, first_line, time_name, before=before)
        if len(t_ns):
            before = int(t_ns[-1])
        rec = _piece(path, layout, values, t_ns)
        if k:  # the records are the first piece's
            rec.metadata.clear()
        yield hand_over(notes, rec)


def _layout(path: Path) -> dict[str, Any]:
    """The header: key/value line, column groups (rigid bodies, markers), names, units; errors name the line."""
    lines = head_lines(path, max_lines=12)
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    info = _info(rows[0])
    if "Format Version" not in info:
        raise ConversionError(path, "first line has no 'Format Version' key", line=1)
    frame_row = next((i for i, r in enumerate(rows) if r and r[0].strip() == "Frame"), None)
    if frame_row is None:
        raise ConversionError(path, "no 'Frame,Time,...' row in the header (cut off?)", line=len(rows))
    label_rows = [r for r in rows[1:frame_row] if any(c.strip() for c in r)]
    if len(label_rows) < 3:
        raise ConversionError(path, "expected type, name, (ID) and property rows above 'Frame'", line=frame_row + 1)
    by_label = {r[1].strip().lower(): r for r in label_rows if len(r) > 1 and r[1].strip().lower() in _LABELS}
    types = by_label.get("type", label_rows[0])
    names = by_label.get("name", label_rows[1])
    props = label_rows[-1]
    axes = rows[frame_row]
    ncols = len(axes)
    if ncols < 2 or not axes[1].strip().lower().startswith("time"):
        raise ConversionError(path, "the second column must be 'Time'", line=frame_row + 1)

    def cell(row: list[str], j: int) -> str:
        return row[j].strip() if j < len(row) else ""

    groups: dict[tuple[str, str, str], dict[str, int]] = {}
    order: list[tuple[str, str, str]] = []
    for j in range(2, ncols):
        key = (cell(types, j), cell(names, j), cell(props, j))
        if not any(key):
            continue
        if key not in groups:
            groups[key] = {}
            order.append(key)
        groups[key][cell(axes, j).upper() or "VALUE"] = j
    col_names = [
        f"{cell(names, j)} {cell(props, j)} {cell(axes, j)}".strip() if j >= 2 else cell(axes, j) for j in range(ncols)
    ]
    unit = info.get("Length Units", "Meters")
    scale = LENGTH.get(unit.lower())
    if scale is None:
        raise ConversionError(path, f"unknown Length Units {unit!r}", line=1)
    rot_type = info.get("Rotation Type", "Quaternion")
    markers: list[tuple[str, list[int]]] = []
    model_markers: list[tuple[str, list[int]]] = []
    quality: list[tuple[str, int]] = []
    bodies: dict[str, dict[str, Any]] = {}
    for key in order:
        kind, name, prop = key
        cols = groups[key]
        xyz = [cols.get(a) for a in "XYZ"]
        if kind in ("Rigid Body", "Bone"):  # Motive 2+ skeleton bones are rigid bodies too
            body = bodies.setdefault(name, {"extra": []})
            if prop == "Rotation":
                if rot_type.lower() != "quaternion":
                    raise ConversionError(
                        path, f"Rotation Type {rot_type}: export again with Rotation Type Quaternion", line=1
                    )
                if any(cols.get(a) is None for a in "XYZW"):
                    raise ConversionError(path, f"rigid body {name!r}: Rotation needs X,Y,Z,W", line=frame_row + 1)
                body["rotation"] = [cols[a] for a in "WXYZ"]  # scalar last in the file -> scalar first
            elif prop == "Position" and None not in xyz:
                body["position"] = xyz
            else:
                body["extra"].extend((f"{prop} {a}".strip() if a != "VALUE" else prop, j) for a, j in cols.items())
        elif kind in ("Rigid Body Marker", "Bone Marker"):
            if prop == "Position" and None not in xyz:
                model_markers.append((name, xyz))
            elif prop == "Marker Quality":
                quality.extend((name, j) for j in cols.values())
        elif kind == "Marker" and prop == "Position" and None not in xyz:
            markers.append((name, xyz))
        else:
            bodies.setdefault(f"{kind} {name}".strip(), {"extra": []})["extra"].extend(
                (f"{prop} {a}", j) for a, j in cols.items()
            )
    for group in (markers, model_markers):
        labels = [n for n, _ in group]
        if len(set(labels)) != len(labels):
            dup = sorted({n for n in labels if labels.count(n) > 1})
            raise ConversionError(path, f"marker name(s) used twice: {', '.join(dup)}", line=frame_row - 2)
    if not (markers or model_markers or quality or any("position" in b or b["extra"] for b in bodies.values())):
        raise ConversionError(path, "no rigid body or marker columns", line=frame_row + 1)
    meta: dict[str, Any] = {
        "format": "motive-csv",
        "model": "OptiTrack Motive",
        "format_version": info.get("Format Version", ""),
        "rate_hz": float(info.get("Export Frame Rate") or info.get("Capture Frame Rate") or 0) or None,
        "length_units": unit,
        "rotation": "Rotation X,Y,Z,W (scalar last) stored as w,x,y,z",
        "coordinate_space": info.get("Coordinate Space", ""),
        "time": f"{axes[1].strip()} column (s)",
        "header": info,
        "source": path.name,
        "rigid_bodies": [n for n, b in bodies.items() if "position" in b],
    }
    records: dict[str, dict[str, Any]] = {"imulog.device.motive": meta}
    start = parse_start_time(info.get("Capture Start Time", ""))
    if start is not None:
        records["imulog.trial"] = trial_start(start, f"{path.name}: Capture Start Time (capture PC local time)")
        records["imulog.trial"]["time_zone"] = "unknown (device local time)"
    skip = frame_row + 1  # csv.reader gives one row per line here (blank lines are empty rows)
    return dict(
        axes=axes, col_names=col_names, skip=skip, scale=scale, bodies=bodies, markers=markers,
        model_markers=model_markers, quality=quality, records=records,
    )  # fmt: skip


def _piece(path: Path, layout: dict[str, Any], values: np.ndarray, t_ns: np.ndarray) -> Recording:
    """One piece's streams (poses, signals, markers; lengths in m) from its rows ``values``."""
    scale = layout["scale"]
    rec = Recording(sources=[str(path)])
    for name, body in layout["bodies"].items():
        topic_name = sanitize_name(name)
        if "position" in body:
            pos = values[:, body["position"]] * scale
            q = values[:, body["rotation"]] if "rotation" in body else None
            rec.poses.append(PoseStream(f"/poses/{topic_name}", t_ns, pos, q, frame_id="world"))
        if body["extra"]:
            units = ["m" if "Error" in c else "" for c, _ in body["extra"]]
            rec.signals.append(
                SignalStream(
                    f"/signals/{topic_name}",
                    t_ns,
                    [c for c, _ in body["extra"]],
                    units,
                    values[:, [j for _, j in body["extra"]]] * np.array([scale if u == "m" else 1.0 for u in units]),
                )
            )
    for stream_name, group in (("motive", layout["markers"]), ("motive_rigid_body_markers", layout["model_markers"])):
        if not group:
            continue
        pos = np.stack([values[:, cols] for _, cols in group], axis=1) * scale
        rec.markers.append(MarkerStream(stream_name, t_ns, [n for n, _ in group], pos, meta={"units": "m"}))
    quality = layout["quality"]
    if quality:
        rec.signals.append(
            SignalStream(
                "/signals/motive_marker_quality",
                t_ns,
                [n for n, _ in quality],
                ["1"] * len(quality),
                values[:, [j for _, j in quality]],
            )
        )
    rec.metadata.update({k: dict(v) for k, v in layout["records"].items()})
    return rec


class MotiveConverter(Converter):
    name = "motive"
    description = "OptiTrack Motive CSV (format 1.21-1.23): rigid bodies -> /poses (quaternion X,Y,Z,W), markers"
    extensions = (".csv",)
    example = "imulog convert ../shared/data/devices/optitrack_motive/sample_optitrack_take.csv -o motive.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 12)
        if not lines or not lines[0].startswith("Format Version,"):
            return 0.0
        return 0.95 if any(x.startswith("Frame,") for x in lines) else 0.6

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_motive(Path(path))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """The take in pieces of about 16 MB of text (see :func:`iter_motive`)."""
        return iter_motive(Path(path), piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = MotiveConverter()
