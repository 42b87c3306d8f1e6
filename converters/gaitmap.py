"""The gaitmap example data set (github mad-lab-fau/gaitmap): foot IMUs + foot markers, as a dataset format.

Files (convert the folder to get one trial with all three):
* ``imu_sample.csv``: two header rows (``sensor,left_sensor,right_sensor,...`` over ``axis,acc_x,acc_x,...``), the
  first column is the sample index; 204.8 Hz, acc m/s^2, gyr deg/s (the data set's conventions: the headers carry
  no units). One IMU stream per sensor (``/imu/left_sensor``, ``/imu/right_sensor``).
* ``mocap_sample.csv``: two header rows (marker names over ``x,y,z``), first column the frame index; 100 Hz, mm.
  Markers ``/markers/mocap``.
* ``stride_borders_sample.csv``: ``s_id,foot,start,end`` in IMU samples -> Intervals ``/events/strides``
  (label = foot, task_index = s_id).
Both recordings start together (t = 0 at index 0); they are synchronised over the 38.7 s.

Memory: every file in pieces of about 16 MiB of text (``iter_chunks``; the IMU and mocap rows from
:func:`imulog.converters._pieces.iter_numeric`, the stride rows, whose ``foot`` cell is text, parsed line by line from
the pieces of the same cutter, :func:`imulog.converters._pieces.text_pieces`); the whole-file readers are the
one-piece case.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import TableSpec, check_increasing, head_lines, split_row, text_head_lines
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.delimited import iter_delimited, read_delimited
from imulog.converters.errors import ConversionError

from imulog.model import Intervals, MarkerStream, Recording

IMU_RATE_HZ = 204.8
MOCAP_RATE_HZ = 100.0
IMU_UNITS = {"acc": "m/s^2", "gyr": "deg/s"}


def _kind(lines: list[str]) -> str | None:
    if len(lines) < 2:
        return None
    a, b = lines[0].strip(), lines[1].strip()
    if a.startswith("sensor,") and b.startswith("axis,"):
        return "imu"
    if a.startswith(",") and b.lower().startswith(",x,y,z"):
        return "mocap"
    if a.startswith("s_id,foot,start,end"):
        return "strides"
    return None


def _mocap_layout(path: Path) -> tuple[list[str], list[str]]:
    """(marker labels, column names) from the two header rows of ``mocap_sample.csv``."""
    lines = head_lines(path)
    if len(lines) < 3:
        raise ConversionError(path, "expected two header rows and data")
    markers_row, axes_row = split_row(lines[0], ","), split_row(lines[1], ",")
    if len(markers_row) != len(axes_row) or (len(markers_row) - 1) % 3:
        raise ConversionError(path, "header rows must have 1 + 3 per marker fields", line=2)
    labels = []
    for j in range(1, len(markers_row), 3):
        trio = markers_row[j : j + 3]
        if len(set(trio)) != 1 or not trio[0] or [a.lower() for a in axes_row[j : j + 3]] != ["x", "y", "z"]:
            raise ConversionError(path, f"marker columns {j + 1}..{j + 3} must be one name over x,y,z", line=1)
        labels.append(trio[0])
    if len(set(labels)) != len(labels):
        raise ConversionError(path, "duplicated marker name", line=1)
    return labels, ["index"] + [f"{m}/{a}" for m in labels for a in "xyz"]


def iter_mocap(
    path: Path, rate_hz: float = MOCAP_RATE_HZ, name: str = "mocap", piece_bytes: int | None = _pieces.PIECE_BYTES
) -> Iterator[Recording]:
    """``mocap_sample.csv`` in pieces of about ``piece_bytes`` of text (:func:`imulog.converters._pieces.iter_numeric`;
    None: one piece): markers in m on the frame index / ``rate_hz`` clock."""
    path = Path(path)
    labels, names = _mocap_layout(path)
    spec = TableSpec(path=path, delimiter=",", skip_lines=2, names=names, optional=set(range(1, len(names))))
    meta = {
        "format": "gaitmap",
        "model": "gaitmap example mocap",
        "rate_hz": rate_hz,
        "marker_units": "mm",
        "source": path.name,
    }
    before = None
    for part in _pieces.iter_numeric(spec, piece_bytes):
        values = part.values
        idx = values[:, 0]
        check_increasing(path, idx, part.first_line, "index", before=before)
        before = float(idx[-1]) if len(idx) else before
        t_ns = np.round(idx * (1e9 / rate_hz)).astype(np.int64)
        pos = values[:, 1:].reshape(len(values), len(labels), 3) * 1e-3
        rec = Recording(sources=[str(path)], warnings=list(part.warnings))
        rec.markers.append(MarkerStream(name=name, t_ns=t_ns, labels=list(labels), pos=pos, meta=dict(meta)))
        rec.metadata[f"imulog.device.{name}"] = dict(meta)
        yield rec


def read_mocap(path: Path, rate_hz: float = MOCAP_RATE_HZ, name: str = "mocap") -> Recording:
    """``mocap_sample.csv`` whole: :func:`iter_mocap` in one piece."""
    (rec,) = iter_mocap(path, rate_hz, name, piece_bytes=None)
    return rec


def read_strides(path: Path, imu_rate_hz: float = IMU_RATE_HZ) -> Recording:
    """``stride_borders_sample.csv`` whole: :func:`iter_strides` in one piece."""
    (rec,) = iter_strides(path, imu_rate_hz, piece_bytes=None)
    return rec


def iter_strides(
    path: Path, imu_rate_hz: float = IMU_RATE_HZ, piece_bytes: int | None = _pieces.PIECE_BYTES
) -> Iterator[Recording]:
    """``stride_borders_sample.csv`` (``s_id,foot,start,end`` in IMU samples) in pieces of about ``piece_bytes`` of
    text cut after whole rows by the text cutter (:func:`imulog.converters._pieces.text_pieces`; None: one piece):
    Intervals ``/events/strides`` (label = foot sensor, task_index = s_id). Blank lines are skipped; a row that is
    short, not numeric or ends before it starts is an error naming its line, whatever the piece size."""
    path = Path(path)
    lines = head_lines(path)
    header = split_row(lines[0], ",")
    need = ["s_id", "foot", "start", "end"]
    if header[:4] != need:
        raise ConversionError(path, f"expected header starting {','.join(need)}", line=1)
    with open(path, "rb") as f:
        if not f.readline().endswith(b"\n"):
            raise ConversionError(path, "no strides")
    size = max(1, path.stat().st_size)
    scale = 1e9 / imu_rate_hz
    found = 0
    for piece, lines_before, _, last in _pieces.text_pieces(path, 1, piece_bytes or size):
        ids, feet, start, end = [], [], [], []
        for lineno, raw in enumerate(piece.split(b"\n"), start=lines_before + 1):
            line = raw.decode("latin-1").rstrip("\r")
            if not line.strip():
                continue
            cells = split_row(line, ",")
            if len(cells) < 4:
                raise ConversionError(path, f"truncated line: {len(cells)} fields, expected {len(header)}", line=lineno)
            try:
                i, s, e = int(cells[0]), float(cells[2]), float(cells[3])
            except ValueError:
                raise ConversionError(path, "s_id, start and end must be numbers", line=lineno) from None
            if not (np.isfinite(s) and np.isfinite(e)) or e < s:
                raise ConversionError(path, f"stride ends before it starts ({s:g} > {e:g})", line=lineno)
            ids.append(i)
            feet.append(cells[1])
            start.append(s)
            end.append(e)
        found += len(ids)
        if last and not found:
            raise ConversionError(path, "no strides")
        if not ids and not last:
            continue
        ev = Intervals(
            topic="/events/strides",
            start_ns=np.round(np.array(start, dtype=np.float64) * scale).astype(np.int64),
            end_ns=np.round(np.array(end, dtype=np.float64) * scale).astype(np.int64),
            labels=[f"{foot}_sensor" for foot in feet],
            task_index=np.array(ids, dtype=np.int64),
        )
        yield Recording(events=[ev], sources=[str(path)])


def _imu_options(rate_hz: float) -> dict[str, Any]:
    """How :func:`~imulog.converters.delimited.iter_delimited` reads the gaitmap IMU file (no time column)."""
    return {
        "rate_hz": rate_hz,
        "default_units": IMU_UNITS,
        "device_meta": {"model": "gaitmap example foot IMU"},
        "fmt": "gaitmap",
    }


class GaitmapConverter(Converter):
    name = "gaitmap"
    description = "gaitmap example data set: imu_sample.csv (204.8 Hz), mocap_sample.csv (100 Hz, mm), stride borders"
    extensions = (".csv",)
    example = "imulog convert gaitmap_foot/ -o out/"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 3)
        return 0.95 if lines and _kind(lines) else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        path = Path(path)
        kind = _kind(head_lines(path, max_lines=3))
        imu_rate = float(options.rate_hz or options.extra.get("imu_rate_hz", IMU_RATE_HZ))
        if kind == "imu":
            return read_delimited(path, **_imu_options(imu_rate))
        if kind == "mocap":
            return read_mocap(path, float(options.extra.get("mocap_rate_hz", MOCAP_RATE_HZ)))
        if kind == "strides":
            return read_strides(path, imu_rate)
        raise ConversionError(path, "not a gaitmap example file (imu_sample, mocap_sample or stride_borders)", line=1)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """The IMU file (:func:`~imulog.converters.delimited.iter_delimited`), the mocap file (:func:`iter_mocap`)
        and the stride file (:func:`iter_strides`) in pieces of text."""
        options = options or ConvertOptions()
        path = Path(path)
        kind = _kind(head_lines(path, max_lines=3))
        if kind == "imu":
            imu_rate = float(options.rate_hz or options.extra.get("imu_rate_hz", IMU_RATE_HZ))
            return iter_delimited(path, **_imu_options(imu_rate), piece_bytes=_pieces.PIECE_BYTES)
        if kind == "mocap":
            rate = float(options.extra.get("mocap_rate_hz", MOCAP_RATE_HZ))
            return iter_mocap(path, rate, piece_bytes=_pieces.PIECE_BYTES)
        if kind == "strides":
            imu_rate = float(options.rate_hz or options.extra.get("imu_rate_hz", IMU_RATE_HZ))
            return iter_strides(path, imu_rate, piece_bytes=_pieces.PIECE_BYTES)
        return iter([self.convert(path, options)])


CONVERTER = GaitmapConverter()
