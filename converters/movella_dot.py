"""Movella (Xsens) DOT CSV: the DOT app's export and the DOT SDK's real-time log.

App export (Movella DOT app / Xsens DOT Server ``Export``)::

    sep=,
    DeviceTag:,bei
    FirmwareVersion:,1.6.0
    AppVersion:,2021.0
    StartTime: ,2021-08-30_17:05:05_000 GMT+8
    (c) Xsens Technologies B. V. 2005-2021
                                                                  (blank line)
    PacketCounter,SampleTimeFine,Euler_X,Euler_Y,Euler_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z

The SDK's real-time log (the DOT PC SDK examples, ``xdpcHandler``) has no banner: the names row is the first line.
Columns, as in the Movella DOT user manual (any subset): ``PacketCounter``, ``SampleTimeFine`` (device clock,
microseconds, an unsigned 32-bit counter that wraps every 4295 s), ``Euler_X/Y/Z`` (roll, pitch, yaw, deg),
``Quat_W/X/Y/Z``, ``FreeAcc_X/Y/Z`` (m/s^2, gravity removed, global frame), ``Acc_X/Y/Z`` (m/s^2), ``Gyr_X/Y/Z``
(deg/s), ``Mag_X/Y/Z`` (a.u., normalised), ``dq_W/X/Y/Z`` and ``dv[1..3]``/``dv_X..Z`` (strap-down integration
increments per sample, m/s), ``Status``.

Mapping: acc/gyr -> ``/imu/<tag>`` (SI); quaternion (else Euler) -> ``/orientation/<tag>``; the rest
(free acceleration, dq, dv, magnetometer a.u., counters) -> ``/signals/<tag>``. Time: ``SampleTimeFine``
unwrapped (a drop of more than half the range is one wrap), from the first sample. The banner's ``StartTime``
(local time with its ``GMT+h`` zone) dates the trial; the real-time log has no start time. ``<tag>`` is the
banner's ``DeviceTag``, else the file name's first part.

Memory: in pieces of text (:func:`iter_movella_dot`); the whole file is the one-piece case.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import TableSpec, estimate_rate_hz, sanitize_name, text_head_lines
from imulog.converters._lab import orientation_stream, trial_start
from imulog.converters._pieces import iter_numeric
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.delimited_time import StepCounts
from imulog.converters.errors import ConversionError
from imulog.converters.xsens import orientation_wxyz

from imulog.model import ImuStream, Recording, SignalStream

WRAP = 1 << 32  # SampleTimeFine counts microseconds in an unsigned 32-bit register
FIRST = ("PacketCounter", "SampleTimeFine")
_START = re.compile(r"(\d{4})-(\d{2})-(\d{2})_(\d{2}):(\d{2}):(\d{2})_(\d{3})(?:\s*GMT([+-]\d{1,2})(?::?(\d{2}))?)?")
DOT_ONLY = {"Euler_X", "Quat_W", "dq_W", "dv_X"}
_DOT_NAME = re.compile(r"^[^_]+_[0-9A-Fa-f]{12}_\d{8}_\d{6}$")
UNITS = {"FreeAcc": "m/s^2", "Mag": "a.u.", "dq": "1", "dv": "m/s", "Euler": "deg", "Quat": "1", "PacketCounter": "1"}


def unwrap_sample_time_fine(raw: np.ndarray) -> np.ndarray:
    """SampleTimeFine (us, uint32, wrapping) -> int64 ns from the first sample; a backwards step of more than half
    the range is a wrap (the counter restarts at 0), a smaller one stays (reported by the caller)."""
    return SampleTimeUnwrap()(raw)


class SampleTimeUnwrap:
    """:func:`unwrap_sample_time_fine` piece by piece: call it on consecutive pieces of the column."""

    def __init__(self) -> None:
        self.first: int | None = None  # the recording's first raw value, us
        self.last: int | None = None  # the previous piece's last raw value
        self.wraps = 0

    def __call__(self, raw: np.ndarray) -> np.ndarray:
        raw = np.asarray(raw, dtype=np.int64)
        if len(raw) == 0:
            return raw
        if self.first is None:
            self.first = self.last = int(raw[0])
        d = np.diff(np.concatenate([[self.last], raw]))
        wraps = self.wraps + np.cumsum(d < -(WRAP // 2))
        self.wraps, self.last = int(wraps[-1]), int(raw[-1])
        return (raw - self.first + wraps * WRAP) * 1000


def parse_start(text: str) -> datetime | None:
    """``2021-08-30_17:05:05_000 GMT+8`` -> aware datetime (naive when no ``GMT`` zone)."""
    m = _START.search(text)
    if not m:
        return None
    y, mo, d, h, mi, s, ms = (int(g) for g in m.groups()[:7])
    tz = None
    if m.group(8) is not None:
        hours = int(m.group(8))
        minutes = int(m.group(9) or 0) * (1 if hours >= 0 else -1)
        tz = timezone(timedelta(hours=hours, minutes=minutes))
    return datetime(y, mo, d, h, mi, s, ms * 1000, tzinfo=tz)


def find_header(lines: list[str]) -> tuple[int, dict[str, str]] | None:
    """(index of the names row, banner fields) when ``lines`` are a DOT CSV."""
    banner: dict[str, str] = {}
    for i, line in enumerate(lines[:20]):
        cells = [c.strip() for c in line.split(",")]
        if cells[:2] == list(FIRST) or (cells and cells[0] == "PacketCounter" and "SampleTimeFine" in cells):
            return i, banner
        if len(cells) >= 2 and cells[0].endswith(":"):
            banner[cells[0].rstrip(":").strip()] = cells[1]
    return None


def read_movella_dot(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file: :func:`iter_movella_dot` as one piece."""
    (rec,) = iter_movella_dot(path, options, piece_bytes=None)
    return rec


def iter_movella_dot(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = None
) -> Iterator[Recording]:
    """The recording in pieces of about ``piece_bytes`` of text (None: one piece), read by
    :func:`~imulog.converters._pieces.iter_numeric`; SampleTimeFine unwrapped across pieces, the rate the median
    step over every piece."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(64 * 1024)
    lines = text_head_lines(head, 25) or []
    found = find_header(lines)
    if found is None:
        raise ConversionError(path, "not a Movella DOT CSV (no 'PacketCounter,SampleTimeFine,...' names row)")
    row, banner = found
    names = [c.strip() for c in lines[row].split(",")]
    while names and not names[-1]:
        names.pop()
    if len(set(names)) != len(names):
        raise ConversionError(path, "repeated column name in the names row", line=row + 1)
    spec = TableSpec(path=path, delimiter=",", skip_lines=row + 1, names=names, ignore=set())
    seen = {n: i for i, n in enumerate(names)}
    tag = banner.get("DeviceTag") or path.stem.split("_")[0]
    name = sanitize_name(tag)
    unwrap, steps, before = SampleTimeUnwrap(), StepCounts(), None
    for piece in iter_numeric(spec, piece_bytes):
        values = piece.values
        if before is None and len(values) == 0:
            raise ConversionError(path, "no samples after the names row", line=row + 2)
        t_ns = unwrap(values[:, seen["SampleTimeFine"]])
        d = np.diff(t_ns if before is None else np.concatenate([[before], t_ns]))
        if len(d) and (d <= 0).any():
            i = int(np.nonzero(d <= 0)[0][0]) + (1 if before is None else 0)
            raise ConversionError(
                path,
                "SampleTimeFine does not increase (and is no 32-bit wrap)",
                line=piece.first_line + i,
                column="SampleTimeFine",
            )
        steps.add(d)
        before = int(t_ns[-1]) if len(t_ns) else before
        rate = steps.rate_hz() if steps.exact else estimate_rate_hz(t_ns)  # the last piece's: the whole file's
        yield _recording(path, name, tag, banner, names, seen, values, t_ns, rate, piece.warnings, row)


def _recording(
    path: Path,
    name: str,
    tag: str,
    banner: dict[str, str],
    names: list[str],
    seen: dict[str, int],
    values: np.ndarray,
    t_ns: np.ndarray,
    rate: float | None,
    warnings: list[str],
    row: int,
) -> Recording:
    """The IMU, orientation and other columns of one piece's ``values``."""

    def trio(prefix: str) -> np.ndarray | None:
        cols = [f"{prefix}_{a}" for a in "XYZ"]
        return values[:, [seen[c] for c in cols]] if all(c in seen for c in cols) else None

    acc, gyr = trio("Acc"), trio("Gyr")
    used = {f"{p}_{a}" for p in ("Acc", "Gyr") for a in "XYZ"} if acc is not None or gyr is not None else set()
    q, q_from = None, ""
    quat = [f"Quat_{a}" for a in "WXYZ"]
    if all(c in seen for c in quat):
        q, q_from = values[:, [seen[c] for c in quat]], "Quat_W..Z"
    elif all(f"Euler_{a}" in seen for a in "XYZ"):
        alias = {"Roll": seen["Euler_X"], "Pitch": seen["Euler_Y"], "Yaw": seen["Euler_Z"]}
        q, q_from = orientation_wxyz(values, alias)
        q_from = "Euler_X/Y/Z = roll/pitch/yaw (deg, Rz(yaw) Ry(pitch) Rx(roll))"
    meta = {
        "format": "movella-dot-csv",
        "layout": "app export" if banner else "SDK real-time log (no banner)",
        "model": "Movella DOT",
        "device_tag": tag,
        "rate_hz": round(rate, 3) if rate else None,
        "units": {"acc": "m/s^2", "gyr": "rad/s (from deg/s)"},
        "time_base": "SampleTimeFine (device us, unwrapped at 2^32) from the first sample",
        "source": path.name,
    }
    for k in ("FirmwareVersion", "AppVersion"):
        if k in banner:
            meta[k] = banner[k]
    rec = Recording(sources=[str(path)], warnings=list(warnings))
    if acc is not None or gyr is not None:
        rec.imus.append(
            ImuStream(
                name=name,
                t_ns=t_ns,
                acc=acc,
                gyr=None if gyr is None else np.radians(gyr),
                meta=dict(meta),
            )
        )
    if q is not None:
        rec.signals.append(orientation_stream(name, t_ns, q))
        meta["orientation"] = {"topic": f"/orientation/{name}", "from": q_from}
    rest = [c for c in names if c not in used and c not in FIRST[1:]]
    if rest:
        units = [next((u for p, u in UNITS.items() if c.startswith(p)), "") for c in rest]
        rec.signals.append(
            SignalStream(
                topic=f"/signals/{name}",
                t_ns=t_ns,
                columns=[sanitize_name(c) for c in rest],
                units=units,
                values=values[:, [seen[c] for c in rest]],
            )
        )
    if not rec.imus and q is None and not rest:
        raise ConversionError(path, "no data columns besides the counters", line=row + 1)
    rec.metadata[f"imulog.device.{name}"] = meta
    start = parse_start(banner.get("StartTime", ""))
    if start is not None:
        rec.metadata["imulog.trial"] = trial_start(start, "DOT export banner StartTime")
    return rec


class MovellaDotConverter(Converter):
    name = "movella-dot"
    description = "Movella/Xsens DOT CSV (app export with sep=/DeviceTag banner, or SDK real-time log)"
    extensions = (".csv",)
    example = "imulog convert ../shared/data/devices/movella_dot_csv/bei_D4CA6EF17860_20210830_170505.csv -o dot.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 25)
        if not lines:
            return 0.0
        found = find_header(lines)
        if found is None:
            return 0.0
        row, banner = found
        if banner:
            return 0.95
        # no banner: Xsens MT Manager files also start with PacketCounter,SampleTimeFine (in 10 kHz ticks); only
        # DOT-only names (Euler_X, Quat_W, dq_W, dv_X) or a DOT file name (<tag>_<MAC>_<date>_<time>) tell them apart
        names = {c.strip() for c in lines[row].split(",")}
        if names & DOT_ONLY or _DOT_NAME.match(Path(path).stem):
            return 0.85
        return 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_movella_dot(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MB of text (see :func:`iter_movella_dot`)."""
        return iter_movella_dot(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = MovellaDotConverter()
