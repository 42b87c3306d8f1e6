"""Xsens MT Manager text exports (one file per sensor; several files of one recording = one trial, one stream each).

Layout (new headers; old ones have ``// Start Time``, ``// Update Rate``, ... and no ``DeviceId``)::

    // General information:
    //  MT Manager version: 2022.2.0
    // Device information:
    //  DeviceId: 00B42D4B
    //  ProductCode: MTW2-3A7G6
    // Device settings:
    //  Filter Profile: human(46.1)
    // Coordinate system: ENU
    PacketCounter<TAB>SampleTimeFine<TAB>...<TAB>Acc_X<TAB>...<TAB>Gyr_X<TAB>...<TAB>Mag_X<TAB>...<TAB>Quat_q0...

Delimiters: tab, semicolon, comma or single spaces (a space export marks an empty field by one more space, so runs
are never collapsed). ``NaN`` and empty cells are gaps (NaN). Units: ``Acc_*`` m/s^2, ``Gyr_*`` rad/s,
``Mag_*`` arbitrary units normalised to the calibration field (kept as a signal, not uT), ``Temperature`` degC.
The device's orientation (``Quat_q0..3`` with q0 = w, else ``Mat[r][c]`` read by name, else Roll/Pitch/Yaw) goes
to ``/orientation/<name>``; ``UTC_*`` columns date the trial.

Time: ``SampleTimeFine`` (10 kHz ticks, unsigned 32 bit, unwrapped) when every row has it; otherwise the
``PacketCounter`` (16 bit, wraps from 65535 to 0, unwrapped; lost packets leave gaps) divided by the update rate
(100 Hz, said out loud, when the file gives none and ``--rate`` is not set). The serial is the header's
``DeviceId``, else the last 8 hex digits of ``MT_<master>_<trial>-000_<DeviceId>.txt``; the stream is named
``mt_<serial>`` unless ``options.extra["names"]`` maps the serial to a name.

Memory: in pieces of about 16 MiB of text (:func:`iter_xsens`; the whole file is the one-piece case), after a first
pass over the pieces (:mod:`imulog.converters.xsens_scan`) that settles what only the whole file tells: the time
base, the rate, the columns with values, the gap count and the UTC start, which the first piece declares.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._binary import concat_chunks
from imulog.converters._common import (
    check_increasing,
    head_lines,
    is_number,
    sanitize_name,
    split_row,
    text_head_lines,
)
from imulog.converters._lab import ORIENTATION_TOPIC, orientation_stream, trial_start
from imulog.converters._pieces import PIECE_BYTES
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError
from imulog.converters.xsens_scan import summarize

from imulog.model import PIECES_RECORD, ImuStream, Recording, SignalStream
from imulog.process import quaternion

TICKS_PER_S = 10_000  # SampleTimeFine resolution
DEFAULT_RATE_HZ = 100.0  # used (and recorded as assumed) when neither the header nor SampleTimeFine times a file
SIGNAL_UNITS = {  # by the column name's stem before "_" or "[": Quat_q0, Mat[1][1], Roll
    "quat": "1",
    "mat": "1",
    "roll": "deg",
    "pitch": "deg",
    "yaw": "deg",
    "freeacc": "m/s^2",
    "mag": "a.u.",
    "pressure": "Pa",
}


def unwrap_counter(values: np.ndarray, modulus: int) -> tuple[np.ndarray, int | None, str]:
    """Unwrap a wrapping counter; returns (unwrapped int64, index of first bad step or None, problem)."""
    c = values.astype(np.int64)
    d = np.diff(c)
    d = np.where(d < 0, d + modulus, d)
    bad = np.nonzero((d <= 0) | (d > modulus // 2))[0]
    if len(bad):
        i = int(bad[0])
        problem = "duplicated" if c[i + 1] == c[i] else "goes backwards or jumps more than half its range"
        return c, i + 1, problem
    return np.concatenate([[c[0]], c[0] + np.cumsum(d)]), None, ""


def _check_counter(path: Path, values: np.ndarray, modulus: int, first_line: int, column: str) -> None:
    bad = ~((values >= 0) & (values < modulus) & (values == np.round(values)))
    if bad.any():
        i = int(np.argmax(bad))
        raise ConversionError(
            path, f"{values[i]:g} is not a counter value in 0..{modulus - 1}", line=first_line + i, column=column
        )


def _header_info(lines: list[str]) -> tuple[dict[str, str], int]:
    info: dict[str, str] = {}
    n = 0
    for line in lines:
        if not line.lstrip().startswith("//"):
            break
        n += 1
        m = re.match(r"^\s*//\s*([^:]+?)\s*:\s*(.*?)\s*$", line)
        if m and m.group(2):
            info[m.group(1).strip()] = m.group(2)
    return info, n


def _delimiter(header_line: str) -> str:
    """Tab, semicolon, comma or (literal, never collapsed) space: the first one the column header uses."""
    for d in ("\t", ";", ","):
        if d in header_line:
            return d
    return " "


_FILE_SERIAL = re.compile(r"[_-]([0-9A-Fa-f]{8})$")
_FILE_KEY = re.compile(r"^(.*?)(?:-\d{3})?[_-][0-9A-Fa-f]{8}$")


def serial_from_name(path: Path) -> str:
    """DeviceId from an MT Manager file name ``MT_<master>_<trial>-000_<DeviceId>.txt`` (the last 8 hex digits)."""
    m = _FILE_SERIAL.search(Path(path).stem)
    return m.group(1).upper() if m else ""


def orientation_wxyz(values: np.ndarray, seen: dict[str, int]) -> tuple[np.ndarray | None, str]:
    """The sensor's orientation (sensor to global, w first) from Quat_q0..q3 (q0 = w), else the rotation matrix
    ``Mat[r][c]`` (exported column-major, read by name), else Roll/Pitch/Yaw (deg, Rz(yaw) Ry(pitch) Rx(roll))."""
    quat = [f"Quat_q{i}" for i in range(4)]
    if all(c in seen for c in quat):
        q = values[:, [seen[c] for c in quat]]
        return q, "Quat_q0..q3 (q0 = w)"
    mat = [f"Mat[{r}][{c}]" for r in (1, 2, 3) for c in (1, 2, 3)]
    if all(c in seen for c in mat):
        r = values[:, [seen[c] for c in mat]].reshape(-1, 3, 3)
        q = np.full((len(r), 4), np.nan)
        ok = np.isfinite(r).all(axis=(1, 2))
        if ok.any():
            q[ok] = quaternion.from_rotation_matrix(r[ok])
        return q, "Mat[r][c] (rotation matrix sensor to global, by element name)"
    euler = ["Roll", "Pitch", "Yaw"]
    if all(c in seen for c in euler):
        rad = np.radians(values[:, [seen[c] for c in euler]])
        half = rad / 2
        cr, cp, cy = np.cos(half).T
        sr, sp, sy = np.sin(half).T
        q = np.stack(
            [
                cy * cp * cr + sy * sp * sr,
                cy * cp * sr - sy * sp * cr,
                cy * sp * cr + sy * cp * sr,
                sy * cp * cr - cy * sp * sr,
            ],
            axis=1,
        )
        return q, "Roll/Pitch/Yaw (deg, Rz(yaw) Ry(pitch) Rx(roll))"
    return None, ""


_UTC = ["UTC_Year", "UTC_Month", "UTC_Day", "UTC_Hour", "UTC_Minute", "UTC_Second"]


def utc_start(values: np.ndarray, seen: dict[str, int], t_ns: np.ndarray) -> datetime | None:
    """The UTC time of the first sample from the UTC_* columns (first row with a valid, fully resolved UTC time,
    minus its offset on the device clock); None when the columns are absent or empty."""
    if not all(c in seen for c in _UTC):
        return None
    cols = values[:, [seen[c] for c in _UTC]]
    ok = np.isfinite(cols).all(axis=1)
    if "UTC_Valid" in seen:
        flags = values[:, seen["UTC_Valid"]]
        ok &= np.isfinite(flags) & ((np.nan_to_num(flags).astype(np.int64) & 0x04) != 0)
    rows = np.flatnonzero(ok)
    for i in rows[:10]:
        y, mo, d, h, mi, sec = (int(v) for v in cols[i])
        nano = values[i, seen["UTC_Nano"]] if "UTC_Nano" in seen and np.isfinite(values[i, seen["UTC_Nano"]]) else 0
        try:
            when = datetime(y, mo, d, h, mi, sec, tzinfo=UTC) + timedelta(microseconds=float(nano) / 1000)
        except ValueError:
            continue
        return when - timedelta(microseconds=int(t_ns[i] - t_ns[0]) / 1000)
    return None


def read_xsens(path: Path, *, names: dict[str, str] | None = None, rate_hz: float | None = None) -> Recording:
    """The whole export: :func:`iter_xsens` as one piece."""
    return concat_chunks(iter_xsens(path, names=names, rate_hz=rate_hz, piece_bytes=None))


def _layout(path: Path) -> tuple[dict[str, str], int, str, list[str], dict[str, int], list[int]]:
    """(header info, comment lines, delimiter, column names, column index by name, text columns) of an export."""
    lines = head_lines(path)
    info, n_comment = _header_info(lines)
    if n_comment >= len(lines):
        raise ConversionError(path, "no column header after the // lines", line=n_comment)
    header_line = lines[n_comment]
    delimiter = _delimiter(header_line)
    cols = header_line.split(delimiter) if delimiter != " " else header_line.strip().split(" ")
    cols = [c.strip().strip('"').strip() for c in cols]
    while cols and cols[-1] == "":
        cols.pop()
    if "PacketCounter" not in cols and "SampleTimeFine" not in cols:
        raise ConversionError(path, "no PacketCounter or SampleTimeFine column", line=n_comment + 1)
    seen: dict[str, int] = {}
    for i, c in enumerate(cols):
        if c == "":
            raise ConversionError(path, f"empty column name (column {i + 1})", line=n_comment + 1)
        if c in seen:
            raise ConversionError(path, f"duplicated column {c!r}", line=n_comment + 1)
        seen[c] = i
    first = split_row(lines[n_comment + 1], delimiter) if n_comment + 1 < len(lines) and delimiter != " " else []
    text_cols = [
        i for i, c in enumerate(cols) if c not in IMU_COLS and i < len(first) and first[i] and not is_number(first[i])
    ]
    return info, n_comment, delimiter, cols, seen, text_cols


IMU_COLS = {f"{q}_{a}" for q in ("Acc", "Gyr") for a in "XYZ"}


def iter_xsens(
    path: Path,
    *,
    names: dict[str, str] | None = None,
    rate_hz: float | None = None,
    piece_bytes: int | None = PIECE_BYTES,
) -> Iterator[Recording]:
    """The export in pieces of about ``piece_bytes`` of text (None: one piece). A first pass over the pieces
    (:func:`~imulog.converters.xsens_scan.summarize`) settles the time base, rate, channels, gap count and start
    time, so every piece has the whole file's streams and meta; the second converts and checks them."""
    from imulog.converters._pieces import iter_table

    path = Path(path)
    info, n_comment, delimiter, cols, seen, text_cols = _layout(path)
    time_col = "PacketCounter" if "PacketCounter" in seen else "SampleTimeFine"
    table = dict(delimiter=delimiter, skip_lines=n_comment + 1, names=cols, required=[seen[time_col]])
    notes: list[str] = []  # a cut final row dropped
    cached = None
    if piece_bytes is None:  # one piece: parsed once, for both passes
        cached = [v for v, _ in iter_table(path, **table, skip_columns=text_cols, piece_bytes=None, warnings=notes)]

    def pieces(warnings: list[str]) -> Iterator[tuple[np.ndarray, int]]:
        if cached is not None:
            return iter([(cached[0], n_comment + 2)])
        return iter_table(path, **table, skip_columns=text_cols, piece_bytes=piece_bytes, warnings=warnings)

    first_line = n_comment + 2
    for q in ("Acc", "Gyr"):
        present = [f"{q}_{a}" in seen for a in "XYZ"]
        if any(present) and not all(present):
            missing = [f"{q}_{a}" for a in "XYZ" if f"{q}_{a}" not in seen]
            raise ConversionError(path, f"missing column(s) {', '.join(missing)}", line=n_comment + 1)
    imu_idx = [seen[f"{q}_{a}"] for q in ("Acc", "Gyr") for a in "XYZ" if f"{q}_Z" in seen]
    summary = summarize((v for v, _ in pieces([])), seen, len(cols), imu_idx)
    if summary.rows == 0:
        raise ConversionError(path, "no data rows after the header", line=first_line)
    plan = _plan(path, (info, n_comment, delimiter, cols, seen, text_cols), summary, names, rate_hz)
    last_t: int | None = None
    stf, pc = _Carry(2**32, "SampleTimeFine"), _Carry(65536, "PacketCounter")
    it = pieces(notes)
    piece = next(it)
    k = 0
    while piece is not None:
        values, line = piece
        piece = next(it, None)
        if plan["stf"]:
            t_ns = stf.unwrap(path, values[:, seen["SampleTimeFine"]], line) * (1_000_000_000 // TICKS_PER_S)
        else:
            t_ns = np.round(pc.unwrap(path, values[:, seen["PacketCounter"]], line) * (1e9 / plan["rate"]))
            t_ns = t_ns.astype(np.int64)
        check_increasing(path, t_ns, line, before=last_t)
        if len(t_ns):
            last_t = int(t_ns[-1])
        rec = _piece(path, plan, seen, values, t_ns)
        if k == 0:
            rec.metadata[PIECES_RECORD] = plan["declared"]
        if piece is None:
            rec.warnings = [*notes, *plan["assumed"]]
        k += 1
        yield rec


class _Carry:
    """A wrapping counter column (SampleTimeFine, PacketCounter) checked and unwrapped across pieces."""

    def __init__(self, modulus: int, column: str) -> None:
        self.modulus, self.column = modulus, column
        self.prev_raw: float | None = None
        self.prev: int | None = None

    def unwrap(self, path: Path, raw: np.ndarray, first_line: int) -> np.ndarray:
        _check_counter(path, raw, self.modulus, first_line, self.column)
        full = raw if self.prev_raw is None else np.concatenate([[self.prev_raw], raw])
        ticks, bad, problem = unwrap_counter(full, self.modulus)
        if bad is not None:
            line = first_line + bad - (0 if self.prev_raw is None else 1)
            raise ConversionError(path, f"{self.column} {problem}", line=line, column=self.column)
        if self.prev is not None:
            ticks = ticks[1:] - ticks[0] + self.prev
        if len(ticks):
            self.prev_raw, self.prev = float(raw[-1]), int(ticks[-1])
        return ticks


def _plan(
    path: Path,
    layout: tuple[dict[str, str], int, str, list[str], dict[str, int], list[int]],
    summary: Any,
    names: dict[str, str] | None,
    rate_hz: float | None,
) -> dict[str, Any]:
    """The recording's time base, rate, name, channels, meta and start, from the first pass; ``declared``: what
    the first piece declares (every stream's meta; spans are its samples' own, every stream starts in it)."""
    info, n_comment, delimiter, cols, seen, text_cols = layout
    rate = rate_hz
    assumed: list[str] = []
    m = re.search(r"([0-9]+(?:\.[0-9]+)?)", info.get("Update Rate", info.get("Sample rate", "")))
    if rate is None and m:
        rate = float(m.group(1))
    stf = "SampleTimeFine" in seen and summary.stf_finite
    if stf:
        time_source = "SampleTimeFine (10 kHz ticks, unwrapped at 2^32)"
    else:
        if "PacketCounter" not in seen:
            raise ConversionError(
                path, "SampleTimeFine has empty cells and there is no PacketCounter", column="SampleTimeFine"
            )
        if not rate:
            rate = DEFAULT_RATE_HZ
            assumed.append(
                f"{path.name}: no '// Update Rate' line and no SampleTimeFine: assumed {DEFAULT_RATE_HZ:g} Hz "
                "for the PacketCounter; pass --rate HZ if the recording used another rate"
            )
        time_source = f"PacketCounter / {rate:g} Hz (unwrapped at 65535)"
    serial = info.get("DeviceId") or info.get("Device ID") or serial_from_name(path)
    serial = serial.split()[0].upper() if serial else ""
    names = {k.upper(): v for k, v in (names or {}).items()}
    name = sanitize_name(names.get(serial, f"mt_{serial}" if serial else "xsens"))
    keys = [k for q, k in (("Acc", "acc"), ("Gyr", "gyr")) if f"{q}_X" in seen]
    temperature = "Temperature" in seen and bool(summary.any_finite[seen["Temperature"]])
    if not keys and not temperature:
        raise ConversionError(path, "no Acc_X/Y/Z or Gyr_X/Y/Z columns", line=n_comment + 1)
    step = summary.median_step_ns() if stf and not rate else None
    meta: dict[str, Any] = {
        "format": "xsens",
        "model": info.get("ProductCode", info.get("Product Code", "Xsens MT")),
        "serial": serial,
        "rate_hz": float(rate) if rate else (1e9 / step if step and step > 0 else None),
        "units": {"acc": "m/s^2", "gyr": "rad/s", "mag": "a.u. (normalised to the calibration field)"},
        "time": time_source,
        "source": path.name,
        "header": info,
        "delimiter": {"\t": "tab", ";": "semicolon", ",": "comma", " ": "space"}[delimiter],
    }
    if assumed:
        meta["assumed"] = assumed
    for key in ("Filter Profile", "Firmware Version", "Firmware revision", "Start Time", "Option Flags"):
        if key in info:
            meta[key.lower().replace(" ", "_")] = info[key]
    if "Coordinate system" in info:
        meta["coordinate_system"] = info["Coordinate system"]
    master = re.match(r"^MT_([0-9A-Fa-f]{8})_", path.name)
    if master and master.group(1).upper() != serial:
        meta["master"] = master.group(1).upper()  # the Awinda station / master of this sensor (file name)
    if keys and summary.gaps:
        meta["samples_with_gaps"] = summary.gaps
    imu_meta = dict(meta)
    probe = np.zeros((0, len(cols)))
    q, q_source = orientation_wxyz(probe, seen)
    if q is not None:
        meta["orientation"] = {"topic": ORIENTATION_TOPIC.format(name=name), "from": q_source}
    skip = IMU_COLS | {"PacketCounter", "SampleTimeFine"} | ({"Temperature"} if temperature else set())
    extra = [(c, i) for c, i in seen.items() if c not in skip and i not in text_cols and summary.any_finite[i]]
    records: dict[str, dict[str, Any]] = {f"imulog.device.{name}": meta}
    start = _utc_start(summary, stf, rate)
    if start is not None:
        records["imulog.trial"] = trial_start(start, f"{path.name}: UTC_* columns")
    return {
        "stf": stf,
        "rate": rate,
        "assumed": assumed,
        "name": name,
        "keys": keys,
        "temperature": temperature,
        "imu_meta": imu_meta,
        "records": records,
        "extra": extra,
        "declared": {"meta": {f"/imu/{name}": imu_meta}},
    }


def _utc_start(summary: Any, stf: bool, rate: float | None) -> datetime | None:
    """:func:`utc_start` from the first pass's candidate rows (their times relative to the first row's)."""
    for cols, nano, tick, count in summary.utc_rows:
        y, mo, d, h, mi, sec = (int(v) for v in cols)
        try:
            when = datetime(y, mo, d, h, mi, sec, tzinfo=UTC) + timedelta(microseconds=float(nano) / 1000)
        except ValueError:
            continue
        if stf:
            rel = (tick - summary.first_ticks) * (1_000_000_000 // TICKS_PER_S)
        else:
            t = np.round(np.array([summary.first_counts, count], dtype=np.int64) * (1e9 / rate)).astype(np.int64)
            rel = int(t[1] - t[0])
        return when - timedelta(microseconds=int(rel) / 1000)
    return None


def _piece(path: Path, plan: dict[str, Any], seen: dict[str, int], values: np.ndarray, t_ns: np.ndarray) -> Recording:
    """The streams of one piece's rows, with the whole recording's channels and records."""
    name = plan["name"]
    streams: dict[str, np.ndarray] = {k: values[:, [seen[f"{k.title()}_{a}"] for a in "XYZ"]] for k in plan["keys"]}
    if plan["temperature"]:
        streams["temperature"] = values[:, seen["Temperature"]]
    rec = Recording(sources=[str(path)])
    rec.imus.append(ImuStream(name=name, t_ns=t_ns, meta=dict(plan["imu_meta"]), **streams))
    q, _ = orientation_wxyz(values, seen)
    if q is not None:
        rec.signals.append(orientation_stream(name, t_ns, q))
    rec.metadata.update({k: dict(v) for k, v in plan["records"].items()})
    extra = plan["extra"]
    if extra:
        units = [SIGNAL_UNITS.get(re.split(r"[_\[]", c)[0].lower(), "") for c, _ in extra]
        rec.signals.insert(
            0,
            SignalStream(
                topic=f"/signals/{name}",
                t_ns=t_ns,
                columns=[c for c, _ in extra],
                units=units,
                values=values[:, [i for _, i in extra]],
            ),
        )
    return rec


class XsensConverter(Converter):
    name = "xsens"
    description = "Xsens MT Manager text export (// header; tab, comma, semicolon or space; one file per sensor)"
    extensions = (".txt", ".csv")
    example = "imulog convert ../shared/data/devices/xsens_mtmanager/ -o xsens/"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 60)
        if not lines:
            return 0.0
        if lines[0].startswith(("PacketCounter\t", "PacketCounter,", "PacketCounter;", "PacketCounter ")):
            return 0.8  # exported without the // header lines
        if not lines[0].lstrip().startswith("//"):
            return 0.0
        for line in lines:
            if not line.lstrip().startswith("//"):
                return 0.9 if ("PacketCounter" in line or "SampleTimeFine" in line) else 0.0
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        return read_xsens(Path(path), names=options.extra.get("names"), rate_hz=options.rate_hz)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        from imulog.converters import _pieces

        options = options or ConvertOptions()
        names, rate = options.extra.get("names"), options.rate_hz
        return iter_xsens(Path(path), names=names, rate_hz=rate, piece_bytes=_pieces.PIECE_BYTES)

    def recording_key(self, path: Path) -> str | None:
        """``MT_012005D6_031-000_00B421AF.txt`` -> ``MT_012005D6_031``: the per-sensor files of one recording."""
        m = _FILE_KEY.match(Path(path).stem)
        return m.group(1) if m and m.group(1) else None


CONVERTER = XsensConverter()
