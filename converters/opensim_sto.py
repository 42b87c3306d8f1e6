"""OpenSim Storage (``.sto``) files from OpenSense: one orientation stream per ``<body>_imu`` column.

Layout (OpenSim 4.x)::

    <name line, may be empty>            (absent in OpenSim 4.2 files)
    DataRate=100.000000
    DataType=Quaternion
    version=3
    OpenSimVersion=4.1
    endheader
    time<TAB>torso_imu<TAB>pelvis_imu...
    678<TAB>0.51,0.45,-0.66,0.28<TAB>...        each cell w,x,y,z

Time is in seconds as written (it need not start at 0: OpenSense keeps the trial's own times) and is kept as the
clock. Each ``<body>_imu`` column becomes ``/orientation/<body>_imu`` (``qw,qx,qy,qz``, the sensor's orientation in
OpenSim's ground frame). ``DataType=Vec3`` files (e.g. accelerations) become ``/signals/<column>`` with x,y,z.

Scalar storage files (``version=1`` ``.mot`` from inverse kinematics, ``.sto`` from inverse dynamics, static
optimisation or ground reaction forces; no ``DataType`` or ``DataType=double``) become one ``/signals/<name>``
stream (``<name>`` from the first header line, e.g. ``Coordinates`` -> ``/signals/coordinates``; else
``/signals/sto``), values as written. Units by OpenSim's column naming: ``*_moment``/``*_torque*`` N*m,
``*_force``/``*_v[xyz]`` N, ``*_p[xyz]``/``*_tx``/``*_ty``/``*_tz`` m, other coordinates deg when ``inDegrees=yes``
and rad when ``inDegrees=no``, otherwise ``""`` (unknown). Header and data may be tab- or comma-separated (a
storage file re-saved as CSV pads each header line with commas).

Memory: in pieces of about 16 MB of text (:func:`iter_sto`), the whole-file ``convert`` being the one-piece case.
A rate estimated from the times (no ``DataRate``) is refined piece by piece in the device record, the last piece's
being the whole file's; an ``nRows`` warning comes with the last piece.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import check_increasing, head_lines, sanitize_name, text_head_lines, to_ns
from imulog.converters._lab import orientation_stream
from imulog.converters._pieces import PIECE_BYTES, hand_over, iter_table
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.delimited_time import StepCounts
from imulog.converters.errors import ConversionError

from imulog.model import Recording, SignalStream

WIDTH = {"quaternion": 4, "vec3": 3, "double": 1, "": 1}


def _header(path: Path, lines: list[str]) -> tuple[dict[str, str], str, int]:
    """(key=value header, name line, index of the column-names line)."""
    info: dict[str, str] = {}
    name = ""
    for i, line in enumerate(lines):
        text = line.strip().rstrip(",\t").strip()
        if text.lower() == "endheader":
            if i + 1 >= len(lines):
                raise ConversionError(path, "no column names after 'endheader'", line=i + 1)
            return info, name, i + 1
        if "=" in text:
            k, _, v = text.partition("=")
            info[k.strip()] = v.strip()
        elif i == 0:
            name = text
    raise ConversionError(path, "no 'endheader' line: not an OpenSim storage file (or its header is cut off)")


def _in_degrees(info: dict[str, str]) -> bool | None:
    """``inDegrees=yes`` -> True, ``no`` -> False, absent -> None."""
    v = info.get("inDegrees", "").strip().lower()
    return True if v in ("yes", "true", "1") else False if v in ("no", "false", "0") else None


def column_unit(name: str, in_degrees: bool | None) -> str:
    """The unit of a scalar storage column from OpenSim's naming (see the module docstring); "" when unknown."""
    n = name.lower()
    if n.endswith("_moment") or "_torque" in n:
        return "N*m"
    if n.endswith("_force") or re.search(r"_v[xyz]$", n):
        return "N"
    if re.search(r"_(p[xyz]|t[xyz])$", n):
        return "m"
    if in_degrees is None:
        return ""
    return "deg" if in_degrees else "rad"


def read_sto(path: Path) -> Recording:
    """The whole file: :func:`iter_sto` as one piece."""
    (rec,) = iter_sto(path, piece_bytes=None)
    return rec


def _tabs_to_commas(data: bytes) -> bytes:
    return data.replace(b"\t", b",")


def iter_sto(path: Path, piece_bytes: int | None = PIECE_BYTES) -> Iterator[Recording]:
    """The file in pieces of about ``piece_bytes`` of text (None: one piece), rows read by
    :func:`~imulog.converters._pieces.iter_table`. Without a ``DataRate`` the rate is the median step of every time
    so far (:class:`~imulog.converters.delimited_time.StepCounts`), refined piece by piece in the device record: the
    last piece's is the whole file's; an ``nRows`` that disagrees is a warning of the last piece."""
    path = Path(path)
    lines = head_lines(path, max_lines=200)
    info, title, ni = _header(path, lines)
    dtype = info.get("DataType", "").lower()
    width = WIDTH.get(dtype)
    if width is None:
        raise ConversionError(path, f"DataType={info['DataType']} is not supported (Quaternion, Vec3, double)")
    delim = "\t" if width > 1 or "\t" in lines[ni] else ","
    cols = [c.strip() for c in lines[ni].split(delim)]
    while cols and cols[-1] == "":
        cols.pop()
    if not cols or cols[0].lower() != "time":
        raise ConversionError(path, "the first column must be 'time'", line=ni + 1)
    names = ["time"] + [f"{c}[{k}]" for c in cols[1:] for k in range(width)]
    rate = None
    m = re.match(r"^\s*([0-9.]+)", info.get("DataRate", ""))
    if m:
        rate = float(m.group(1))
    meta: dict[str, Any] = {
        "format": "opensim-sto",
        "data_type": info.get("DataType", ""),
        "rate_hz": rate,
        "header": info,
        "time": "time column (s) as written",
        "source": path.name,
    }
    if title:
        meta["name"] = title
    degrees = _in_degrees(info)
    units = [column_unit(c, degrees) for c in cols[1:]]
    if width == 1:
        meta["in_degrees"] = degrees
        meta["units"] = dict(zip(cols[1:], units, strict=True))
    steps = StepCounts()
    origin: float | None = None
    before: int | None = None
    count = 0
    notes: list[str] = []
    rows = iter_table(
        path,
        delimiter=",",
        skip_lines=ni + 1,
        names=names,
        required=[0],
        piece_bytes=piece_bytes,
        warnings=notes,
        transform=_tabs_to_commas if delim == "\t" else None,
    )
    nxt = next(rows, None)
    while nxt is not None:
        values, first_line = nxt
        nxt = next(rows, None)
        if origin is None and len(values):
            origin = float(values[0, 0])
        try:
            t_ns = to_ns(values[:, 0], 1e9, origin=origin)
        except ValueError as e:
            raise ConversionError(path, str(e), column="time") from None
        check_increasing(path, t_ns, first_line, "time", before=before)
        steps.add(np.diff(t_ns if before is None else np.concatenate([[before], t_ns])))
        if len(t_ns):
            before = int(t_ns[-1])
        count += len(t_ns)
        # a cut final row's warning: read with the last piece, which the look-ahead above has already read
        rec = hand_over(notes, Recording(sources=[str(path)]))
        if width == 1:
            topic = f"/signals/{sanitize_name(title).lower()}" if title else "/signals/sto"
            rec.signals.append(SignalStream(topic, t_ns, cols[1:], units, values[:, 1:]))
        for j, c in enumerate(cols[1:]):
            block = values[:, 1 + j * width : 1 + (j + 1) * width]
            name = sanitize_name(c)
            if width == 4:
                rec.signals.append(orientation_stream(name, t_ns, block, frame_id="ground"))
            elif width == 3:
                rec.signals.append(SignalStream(f"/signals/{name}", t_ns, ["x", "y", "z"], ["", "", ""], block))
        estimate = rate or (steps.rate_hz() if steps.exact else None)
        rec.metadata["imulog.device.opensense"] = {**meta, "rate_hz": estimate, "columns": cols[1:]}
        if nxt is None:
            declared = info.get("nRows", "")
            if declared.isdigit() and int(declared) != count:
                rec.warnings.append(
                    f"{path.name}: header nRows={declared} but the file holds {count} rows; read them all"
                )
        yield rec


class OpenSimStoConverter(Converter):
    name = "opensim-sto"
    description = (
        "OpenSim storage (.sto/.mot): quaternion columns -> /orientation/<body>_imu; joint angles, moments, forces "
        "-> /signals/<name> with units"
    )
    extensions = (".sto", ".mot")
    example = (
        "imulog convert ../shared/data/devices/opensense_sto/myComplexTasksTrial_orientations.sto -o orientations.mcap"
    )

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 40)
        if not lines:
            return 0.0
        for i, line in enumerate(lines):
            if line.strip().rstrip(",\t").strip().lower() == "endheader":
                nxt = lines[i + 1] if i + 1 < len(lines) else ""
                return 0.95 if nxt.lower().startswith("time") else 0.5
            if i > 0 and "=" not in line and i > 12:
                break
        # an OpenSim key=value header without its end (cut off): claim it so the converter names the problem
        return 0.5 if any(x.startswith(("DataRate=", "DataType=", "OpenSimVersion=")) for x in lines[:3]) else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_sto(Path(path))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """The file in pieces of about 16 MB of text (see :func:`iter_sto`)."""
        return iter_sto(Path(path), piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = OpenSimStoConverter()
