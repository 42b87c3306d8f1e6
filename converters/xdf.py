"""XDF recordings (Lab Streaming Layer, LabRecorder), read chunk by chunk by imulog (pyxdf is the reference).

Every stream becomes channels of its own, named from the stream's ``name`` (topic-safe; the stream id is appended
when two streams share a name):

* numeric streams -> ``/signals/<stream>`` with the declared channel labels and units (``desc/channels/channel``;
  ``ch0``.. and no unit when the header declares none). When the channel labels or types name an accelerometer /
  gyroscope / magnetometer (``AccX``, ``acc_x``, ``Gyro Z`` or type ``Accelerometer``...) with a unit imulog knows,
  those three-axis groups become ``/imu/<stream>`` in SI units and the remaining channels stay in the signal stream;
  without units they stay signals (no unit is guessed). A stream of type ``MoCap``/``Mocap`` whose channels are
  ``<marker>_X/_Y/_Z`` in m, cm or mm becomes ``/markers/<stream>`` (NaN = occluded).
* string streams (markers) -> ``/events/<stream>``: one instantaneous interval (start == end) per sample, the
  label being the string (channels joined with ``|``).
* empty streams are kept as empty channels.

Time: each stream's time stamps on the recording host's LSL clock after applying the stream's ClockOffset
measurements exactly as pyxdf's ``load_xdf(synchronize_clocks=True, handle_clock_resets=True,
dejitter_timestamps=False)`` does (:mod:`imulog.converters.xdf_clock`: host clock resets as separate clock
segments, a robust line per segment, the pylsl#67 corrupted last offset dropped); stamps are not dejittered (raw
data keeps what was recorded). ``t_ns`` = LSL seconds x 1e9. The file header's ``datetime`` (when LabRecorder
started) is the trial's ``start_time``. XDF has no checksums: the chunk structure (magic, chunk lengths, tags) and
every Samples chunk's layout (time-stamp flags, string lengths, samples filling the chunk exactly) are verified
before parsing, so truncated files and damaged chunks are reported with their chunk index; a flipped bit inside a
sample value cannot be detected by any reader.

Memory: in pieces (:func:`iter_chunks`, :mod:`imulog.converters.xdf_pieces`): a first pass keeps headers, clock
offsets, footers and counts (a few bytes per chunk), a second the synchronised first and last stamp of every
stream (declared by the first piece: a stream whose chunks come later may start earlier), then samples are decoded
chunk by chunk, about 16 MiB of values a piece; the whole file is the one-piece case.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._binary import concat_chunks, format_offset
from imulog.converters._common import sanitize_name, unit_factor
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Intervals, MarkerStream, Recording, SignalStream

MAGIC = b"XDF:"
CHUNK_TAGS = {1: "FileHeader", 2: "StreamHeader", 3: "Samples", 4: "ClockOffset", 5: "Boundary", 6: "StreamFooter"}
_AXIS = r"[ _\-.:]?([xyz])"
IMU_LABELS = {
    "acc": re.compile(r"^(?:acc|accel|accelerometer|acceleration)" + _AXIS + "$", re.I),
    "gyr": re.compile(r"^(?:gyr|gyro|gyroscope|angularvelocity|angular_velocity)" + _AXIS + "$", re.I),
    "mag": re.compile(r"^(?:mag|magn|magnetometer|magneticfield)" + _AXIS + "$", re.I),
}
IMU_TYPES = {"accelerometer": "acc", "acc": "acc", "gyroscope": "gyr", "gyro": "gyr", "magnetometer": "mag"}
LENGTH_UNITS = {"m": 1.0, "meters": 1.0, "cm": 0.01, "mm": 0.001, "millimeters": 0.001}


# --------------------------------------------------------------------------------------------- chunk structure
def _varlen(f, path: Path, index: int, at: int) -> int | None:
    n = f.read(1)
    if not n:
        return None
    size = {1: 1, 4: 4, 8: 8}.get(n[0])
    if size is None:
        raise ConversionError(path, f"chunk {index} (byte {at}): bad chunk length width {n[0]} (damaged chunk header)")
    data = f.read(size)
    if len(data) < size:
        raise ConversionError(path, f"chunk {index} (byte {at}): truncated chunk header")
    return int.from_bytes(data, "little")


def iter_chunk_headers(path: Path) -> Iterator[tuple[int, int, int, int, int]]:
    """(index, byte of the chunk, tag, byte of its content after the tag, content length) of every chunk.

    ConversionError naming the chunk for a missing magic, a bad length or tag, or a chunk cut by the file's end.
    """
    size = path.stat().st_size
    with open(path, "rb") as f:
        if f.read(4) != MAGIC:
            raise ConversionError(path, "not an XDF file (no 'XDF:' magic)")
        index = 0
        while True:
            at = f.tell()
            length = _varlen(f, path, index, at)
            if length is None:
                break
            start = f.tell()
            if length < 2 or start + length > size:
                what = "truncated" if start + length > size and length >= 2 else "bad length"
                raise ConversionError(
                    path, f"chunk {index} (byte {at}): {what} ({length} bytes declared, {size - start} left)"
                )
            tag = int.from_bytes(f.read(2), "little")
            if tag not in CHUNK_TAGS:
                raise ConversionError(
                    path, f"chunk {index} (byte {at}): unknown chunk tag {tag} (damaged chunk header)"
                )
            if index == 0 and tag != 1:
                raise ConversionError(path, "chunk 0 is not the FileHeader")
            yield index, at, tag, start + 2, length - 2
            f.seek(start + length)
            index += 1


def scan_chunks(path: Path) -> dict[str, int]:
    """Walk the chunk headers (lengths and tags, seeking over contents): counts per chunk type."""
    counts: dict[str, int] = {}
    for _, _, tag, _, _ in iter_chunk_headers(path):
        counts[CHUNK_TAGS[tag]] = counts.get(CHUNK_TAGS[tag], 0) + 1
    if not counts:
        raise ConversionError(path, "no chunks after the 'XDF:' magic")
    return counts


VALUE_BYTES = {"int8": 1, "int16": 2, "int32": 4, "int64": 8, "float32": 4, "double64": 8}


def _samples_problem(data: bytes, fmt: str, n_ch: int) -> str | None:
    """Why a Samples chunk's content (after the stream id) does not hold whole samples, or None."""
    mv = memoryview(data)

    def varlen(pos: int) -> tuple[int, int]:
        width = mv[pos] if pos < len(mv) else 0
        if width not in (1, 4, 8) or pos + 1 + width > len(mv):
            raise ValueError(f"bad length field at content byte {pos}")
        return int.from_bytes(mv[pos + 1 : pos + 1 + width], "little"), pos + 1 + width

    try:
        count, pos = varlen(0)
        if fmt != "string":  # fast path: every sample stamped (LabRecorder's usual layout), checked vectorised
            stride = 9 + VALUE_BYTES.get(fmt, 4) * n_ch
            if pos + count * stride == len(mv):
                flags = np.frombuffer(data, dtype=np.uint8)[pos : pos + count * stride : stride]
                if np.all(flags == 8):
                    return None
        for k in range(count):
            if pos >= len(mv) or mv[pos] not in (0, 8):
                return f"sample {k}: bad time stamp flag"
            pos += 1 + mv[pos]
            if fmt == "string":
                for _ in range(n_ch):
                    n, pos = varlen(pos)
                    pos += n
            else:
                pos += VALUE_BYTES.get(fmt, 4) * n_ch
            if pos > len(mv):
                return f"sample {k} of {count} runs past the chunk's end"
    except ValueError as e:
        return str(e)
    return None if pos == len(mv) else f"{len(mv) - pos} bytes left after {count} samples"


def locate_damaged_samples(path: Path) -> None:
    """Raise ConversionError naming the first Samples chunk whose samples do not fit its length (returns if none).

    pyxdf reads past such damage silently (misaligned values) or skips it with a log message, so every file is
    checked; numeric chunks whose samples all carry a time stamp are checked vectorised, others sample by sample.
    """
    import xml.etree.ElementTree as ET

    formats: dict[int, tuple[str, int]] = {}
    with open(path, "rb") as f:
        for index, at, tag, start, length in iter_chunk_headers(path):
            if tag not in (2, 3) or length < 4:
                continue
            f.seek(start)
            content = f.read(length)
            sid = int.from_bytes(content[:4], "little")
            if tag == 2:
                try:
                    root = ET.fromstring(content[4:].decode("utf-8", "replace"))
                    formats[sid] = (
                        root.findtext("channel_format", "float32"),
                        int(root.findtext("channel_count", "1")),
                    )
                except (ET.ParseError, ValueError):
                    raise ConversionError(path, f"chunk {index} (byte {at}): stream header is not valid XML") from None
                continue
            if sid not in formats:
                raise ConversionError(path, f"chunk {index} (byte {at}): samples of stream {sid} before its header")
            problem = _samples_problem(content[4:], *formats[sid])
            if problem:
                raise ConversionError(
                    path, f"chunk {index} (byte {at}): damaged Samples chunk of stream {sid}: {problem}"
                )


# --------------------------------------------------------------------------------------------- stream mapping
def _first(d: Any, key: str, default: Any = None) -> Any:
    if not isinstance(d, dict):
        return default
    v = d.get(key)
    if isinstance(v, list):
        return v[0] if v else default
    return v if v is not None else default


def channel_info(info: dict, n: int) -> tuple[list[str], list[str], list[str]]:
    """(labels, units, types) of a stream's channels from ``desc/channels/channel`` (``ch<i>`` / "" when absent)."""
    labels, units, types = [f"ch{i}" for i in range(n)], [""] * n, [""] * n
    desc = _first(info, "desc")
    channels = _first(desc, "channels")
    entries = channels.get("channel", []) if isinstance(channels, dict) else []
    for i, ch in enumerate(entries[:n]):
        labels[i] = str(_first(ch, "label", labels[i]) or labels[i]).strip()
        units[i] = str(_first(ch, "unit", "") or "").strip()
        types[i] = str(_first(ch, "type", "") or "").strip()
    return labels, units, types


def _imu_groups(labels: list[str], units: list[str], types: list[str]) -> dict[str, tuple[list[int], float, str]]:
    """quantity -> (x, y, z channel indices, factor to SI, unit as declared) for complete groups with known units."""
    found: dict[str, dict[str, int]] = {}
    for i, (label, ctype) in enumerate(zip(labels, types, strict=True)):
        for q, rx in IMU_LABELS.items():
            m = rx.match(label.replace(" ", ""))
            if m:
                found.setdefault(q, {})[m.group(1).lower()] = i
                break
        else:
            q = IMU_TYPES.get(ctype.lower())
            m = re.search(r"([xyz])$", label, re.I)
            if q and m:
                found.setdefault(q, {})[m.group(1).lower()] = i
    out = {}
    for q, axes in found.items():
        if set(axes) != {"x", "y", "z"}:
            continue
        idx = [axes["x"], axes["y"], axes["z"]]
        declared = {units[i] for i in idx}
        if len(declared) != 1:
            continue
        unit = declared.pop()
        factor = unit_factor(q, unit) if unit else None
        if factor is not None:
            out[q] = (idx, factor, unit)
    return out


def _marker_groups(labels: list[str], units: list[str]) -> tuple[list[str], list[list[int]], float] | None:
    if len(labels) % 3 or not labels:
        return None
    names, groups = [], []
    for j in range(0, len(labels), 3):
        trio = labels[j : j + 3]
        m = [re.match(r"^(.*?)[ _\-.:]?([xyz])$", lab, re.I) for lab in trio]
        if not all(m) or [x.group(2).lower() for x in m] != ["x", "y", "z"] or len({x.group(1) for x in m}) != 1:
            return None
        names.append(m[0].group(1) or f"marker{j // 3}")
        groups.append(list(range(j, j + 3)))
    declared = {u.lower() for u in units}
    if len(declared) != 1 or declared.pop() not in LENGTH_UNITS or len(set(names)) != len(names):
        return None
    return names, groups, LENGTH_UNITS[units[0].lower()]


def stream_meta(path: Path, info: dict, name: str, n_samples: int, footer: dict | None, segments: int) -> dict:
    """The ``imulog.device.<name>`` record of a stream: its header, sample count, footer count, clock segments."""
    meta: dict[str, Any] = {
        "format": "xdf",
        "stream_name": str(_first(info, "name", name)),
        "stream_type": str(_first(info, "type", "") or ""),
        "stream_id": int(_first(info, "stream_id", 0) or 0),
        "channel_format": str(_first(info, "channel_format", "float32")),
        "channel_count": int(float(_first(info, "channel_count", 1) or 1)),
        "nominal_srate_hz": float(_first(info, "nominal_srate", 0) or 0),
        "samples": int(n_samples),
        "time_base": "ns of the recording host's LSL clock, stream clock offsets applied",
        "source": path.name,
    }
    for key in ("source_id", "hostname", "created_at", "uid"):
        v = _first(info, key)
        if v:
            meta[key] = str(v)
    manufacturer = _first(_first(info, "desc"), "manufacturer")
    if manufacturer:
        meta["manufacturer"] = str(manufacturer)
    footer_info = (footer or {}).get("info") or {}
    if footer_info:
        meta["footer_sample_count"] = int(float(_first(footer_info, "sample_count", 0) or 0))
    meta["clock_segments"] = segments  # > 1: the host clock was reset during the recording
    return meta


def stream_layout(info: dict) -> tuple[str, Any]:
    """How a stream's channels map to imulog streams: ("events", None), ("markers", (names, groups, scale)) or
    ("numeric", (IMU groups, the remaining channel indices, their column names, units))."""
    fmt = str(_first(info, "channel_format", "float32"))
    if fmt == "string":
        return "events", None
    n_ch = int(float(_first(info, "channel_count", 1) or 1))
    labels, units, types = channel_info(info, n_ch)
    if str(_first(info, "type", "") or "").lower() in ("mocap", "motion capture"):
        markers = _marker_groups(labels, units)
        if markers is not None:
            return "markers", markers
    groups = _imu_groups(labels, units, types)
    if "acc" not in groups and "gyr" not in groups:
        groups = {}
    used = {i for idx, _, _ in groups.values() for i in idx}
    rest = [i for i in range(n_ch) if i not in used]
    cols = [labels[i] for i in rest]
    if len(set(cols)) != len(cols):
        cols = [f"{c}_{i}" for c, i in zip(cols, rest, strict=True)]
    return "numeric", (groups, rest, cols, [units[i] for i in rest])


def stream_piece(name: str, layout: tuple[str, Any], t_ns: np.ndarray, series: Any, meta: dict) -> list[Any]:
    """The imulog streams of some samples of one stream (``series``: (n, channels) numbers or string rows);
    ``meta`` is the device record (the IMU stream carries it with the declared IMU units, markers without)."""
    kind, how = layout
    if kind == "events":
        labels = ["|".join(str(v) for v in row) if isinstance(row, list | tuple) else str(row) for row in series]
        return [Intervals(topic=f"/events/{name}", start_ns=t_ns, end_ns=t_ns.copy(), labels=labels)]
    n_ch = int(meta["channel_count"])
    values = np.asarray(series, dtype=np.float64).reshape(len(t_ns), n_ch)
    if kind == "markers":
        marker_names, groups, scale = how
        pos = np.stack([values[:, g] for g in groups], axis=1) * scale
        shown = {k: v for k, v in meta.items() if k != "marker_units"}
        return [MarkerStream(name=name, t_ns=t_ns, labels=marker_names, pos=pos, meta=shown)]
    groups, rest, cols, units = how
    out: list[Any] = []
    if groups:
        parts = {q: values[:, idx] * factor for q, (idx, factor, _) in groups.items()}
        out.append(
            ImuStream(
                name=name, t_ns=t_ns, acc=parts.get("acc"), gyr=parts.get("gyr"), mag=parts.get("mag"), meta=dict(meta)
            )
        )
    if rest or not groups:
        out.append(SignalStream(topic=f"/signals/{name}", t_ns=t_ns, columns=cols, units=units, values=values[:, rest]))
    return out


def device_meta(path: Path, info: dict, name: str, n: int, footer: dict | None, segments: int) -> dict:
    """:func:`stream_meta` plus what the layout adds: the declared IMU units or the markers' unit."""
    meta = stream_meta(path, info, name, n, footer, segments)
    kind, how = stream_layout(info)
    if kind == "markers":
        meta["marker_units"] = channel_info(info, int(meta["channel_count"]))[1][0]
    elif kind == "numeric" and how[0]:
        meta["imu_units_declared"] = {q: u for q, (_, _, u) in how[0].items()}
    return meta


def _check_increasing(path: Path, t_ns: np.ndarray, meta: dict, before: int | None, offset: int) -> None:
    """Stamps must increase (also from the previous piece's last, ``before``); the sample is named by its index."""
    full = t_ns if before is None else np.concatenate([[before], t_ns])
    bad = np.flatnonzero(np.diff(full) <= 0)
    if len(bad):
        i = int(bad[0]) + 1 + offset - (0 if before is None else 1)
        raise ConversionError(
            path, f"stream {meta['stream_id']} ({meta['stream_name']!r}): sample {i} time stamp does not increase"
        )


def stream_to_recording(path: Path, stream: dict, name: str) -> Recording:
    """One stream in pyxdf's layout (``info``, ``time_stamps`` s, ``time_series``, optional ``footer``) -> a
    Recording with its channel(s) and an ``imulog.device.<name>`` record (the live capture's mapping)."""
    info = stream["info"]
    t_ns = np.round(np.asarray(stream["time_stamps"], dtype=np.float64) * 1e9).astype(np.int64)
    segments = len(info.get("clock_segments") or [])
    meta = device_meta(path, info, name, len(t_ns), stream.get("footer"), segments)
    rec = Recording(sources=[str(path)])
    rec.metadata[f"imulog.device.{name}"] = meta
    _check_increasing(path, t_ns, meta, None, 0)
    for s in stream_piece(name, stream_layout(info), t_ns, stream["time_series"], meta):
        {ImuStream: rec.imus, MarkerStream: rec.markers, SignalStream: rec.signals, Intervals: rec.events}[
            type(s)
        ].append(s)
    return rec


def header_start_time(header: dict) -> dict[str, str]:
    """``imulog.trial`` start fields from the FileHeader ``datetime`` (``2025-01-31T00:21:17+0000``), else {}."""
    text = _first(header.get("info", {}), "datetime")
    if not text:
        return {}
    try:
        when = datetime.fromisoformat(str(text).strip())
    except ValueError:
        return {}
    if when.tzinfo is None:
        return {"start_time": when.isoformat(timespec="milliseconds"), "time_zone": "unknown (device local time)"}
    offset = int(when.utcoffset().total_seconds())  # type: ignore[union-attr]
    zone = "UTC" if offset == 0 else format_offset(offset)
    return {"start_time": when.isoformat(timespec="milliseconds"), "time_zone": zone}


def _stream_names(infos: list[dict]) -> dict[int, str]:
    names = {int(i["stream_id"]): sanitize_name(str(i.get("name") or "stream")) for i in infos}
    taken = list(names.values())
    return {sid: (n if taken.count(n) == 1 else f"{n}_{sid}") for sid, n in names.items()}


#: bytes of sample values gathered before a piece is given (``iter_chunks``); None: the whole file as one piece
PIECE_BYTES = 16 << 20


def iter_chunks(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """The recording in pieces of about ``piece_bytes`` of samples, read chunk by chunk in file order (None: one
    piece). The first piece holds every stream (empty where none of its samples came yet) and declares every
    stream's span and meta (:data:`imulog.model.PIECES_RECORD`) from two passes before it: headers, clock offsets,
    footers and counts (:func:`~imulog.converters.xdf_read.scan`), then the synchronised stamps."""
    from imulog.converters.xdf_pieces import iter_pieces

    path = Path(path)
    scan_chunks(path)
    locate_damaged_samples(path)
    return iter_pieces(path, piece_bytes)


def read_xdf(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file: :func:`iter_chunks` in one piece."""
    return concat_chunks(iter_chunks(path, options, piece_bytes=None))


class XdfConverter(Converter):
    name = "xdf"
    description = (
        "XDF (Lab Streaming Layer / LabRecorder): every stream with its units, clock offsets applied (as pyxdf)"
    )
    extensions = (".xdf",)
    example = "imulog convert ../shared/data/devices/xdf/clock_resets.xdf -o lsl.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        return 0.99 if head[:4] == MAGIC else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_xdf(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        return iter_chunks(Path(path), options)


CONVERTER = XdfConverter()
