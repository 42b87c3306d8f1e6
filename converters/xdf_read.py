"""XDF read chunk by chunk: a first pass over the headers, clock offsets and footers, then the samples in pieces.

XDF interleaves the chunks of its streams. :func:`scan` walks the file once and keeps what is small: the file
header, every stream's header, ClockOffset measurements, footer and sample count (the count at the start of each
Samples chunk). With those the clock lines are known (:class:`~imulog.converters.xdf_clock.StreamClock`) before any
sample is decoded; :func:`iter_samples` then decodes the Samples chunks in file order, stamps delta-compressed
samples as pyxdf does (the previous stamp plus 1 / nominal rate, added one sample at a time) and gives each
stream's raw stamps and values chunk by chunk. Memory is one chunk plus what the caller gathers.
"""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters.errors import ConversionError

DTYPES = {"int8": "<i1", "int16": "<i2", "int32": "<i4", "int64": "<i8", "float32": "<f4", "double64": "<f8"}


def xml_dict(element: ET.Element) -> dict[str, Any]:
    """An attribute-less XML element in pyxdf's ``_xml2dict`` layout: ``{tag: {child: [values]} or text}``.

    Plain dicts where pyxdf has defaultdicts (equal to them): a missing key raises instead of appearing as ``[]``,
    so readers ask with ``.get``. The XDF reader and the live capture's stream headers (:mod:`imulog.live.mapping`)
    both parse with it."""
    children: dict[str, list[Any]] = {}
    for child in element:
        for k, v in xml_dict(child).items():
            children.setdefault(k, []).append(v)
    return {element.tag: children or element.text}


def _parse_xml(path: Path, data: bytes, what: str, index: int, at: int) -> dict[str, Any]:
    try:
        return xml_dict(ET.fromstring(data.decode("utf-8", "replace")))
    except ET.ParseError:
        raise ConversionError(path, f"chunk {index} (byte {at}): {what} is not valid XML") from None


@dataclass
class StreamScan:
    """What the first pass learnt about one stream."""

    sid: int
    info: dict[str, Any]
    fmt: str
    nchns: int
    srate: float
    clock_times: list[float] = field(default_factory=list)
    clock_values: list[float] = field(default_factory=list)
    footer: dict[str, Any] | None = None
    count: int = 0  # samples in all its Samples chunks

    @property
    def keep(self) -> int:
        """Samples kept: all, unless the pylsl#67 bug left extra samples and a corrupted last clock offset (pyxdf
        ``_truncate_corrupted_offsets``: both are dropped)."""
        from imulog.converters.xdf_clock import corrupted_last_offset

        info = (self.footer or {}).get("info") or {}
        counts = info.get("sample_count") if isinstance(info, dict) else None
        if not counts or counts[0] is None:
            return self.count
        footer_count = int(counts[0])
        if self.count <= footer_count or not corrupted_last_offset(self.clock_times, self.clock_values):
            return self.count
        return footer_count

    def clock(self) -> Any:
        """The stream's :class:`~imulog.converters.xdf_clock.StreamClock` (the corrupted last offset dropped)."""
        from imulog.converters.xdf_clock import StreamClock

        n = len(self.clock_times) - (1 if self.keep < self.count else 0)
        return StreamClock(self.clock_times[:n], self.clock_values[:n])


@dataclass
class FileScan:
    header: dict[str, Any]
    streams: dict[int, StreamScan]  # in the order of their headers


def _varlen(data: bytes | memoryview, pos: int) -> tuple[int, int]:
    width = data[pos]
    if width not in (1, 4, 8) or pos + 1 + width > len(data):
        raise ValueError(f"bad length field at content byte {pos}")
    return int.from_bytes(data[pos + 1 : pos + 1 + width], "little"), pos + 1 + width


def scan(path: Path) -> FileScan:
    """The first pass: file header, stream headers, clock offsets, footers and sample counts (chunk structure and
    Samples layouts are checked by :func:`imulog.converters.xdf.locate_damaged_samples` before)."""
    from imulog.converters.xdf_chunks import iter_chunk_headers

    header: dict[str, Any] = {}
    streams: dict[int, StreamScan] = {}
    with open(path, "rb") as f:
        for index, at, tag, start, length in iter_chunk_headers(path):
            if tag == 1:
                f.seek(start)
                header = _parse_xml(path, f.read(length), "the file header", index, at)
                continue
            if tag not in (2, 3, 4, 6):
                continue
            f.seek(start)
            head = f.read(min(length, 13))
            if len(head) < 4:
                raise ConversionError(path, f"chunk {index} (byte {at}): no stream id")
            sid = int.from_bytes(head[:4], "little")
            if tag == 2:
                f.seek(start + 4)
                hdr = _parse_xml(path, f.read(length - 4), "the stream header", index, at)
                info = hdr.get("info") if isinstance(hdr.get("info"), dict) else {}
                try:
                    fmt = str(info["channel_format"][0])
                    nchns = int(info["channel_count"][0])
                    srate = float(info["nominal_srate"][0])
                except (KeyError, IndexError, TypeError, ValueError):
                    raise ConversionError(
                        path, f"chunk {index} (byte {at}): stream header without channel_format, count or rate"
                    ) from None
                if fmt != "string" and fmt not in DTYPES:
                    raise ConversionError(path, f"chunk {index} (byte {at}): unknown channel_format {fmt!r}")
                streams[sid] = StreamScan(sid, info, fmt, nchns, srate)
                continue
            s = streams.get(sid)
            if s is None:
                raise ConversionError(path, f"chunk {index} (byte {at}): stream {sid} has no header before it")
            if tag == 3:
                try:
                    s.count += _varlen(head, 4)[0]
                except (ValueError, IndexError):
                    raise ConversionError(path, f"chunk {index} (byte {at}): bad sample count") from None
            elif tag == 4:
                if length != 20:
                    raise ConversionError(path, f"chunk {index} (byte {at}): ClockOffset of {length} bytes, not 20")
                f.seek(start + 4)
                t, v = struct.unpack("<dd", f.read(16))
                s.clock_times.append(t)
                s.clock_values.append(v)
            else:
                f.seek(start + 4)
                s.footer = _parse_xml(path, f.read(length - 4), "the stream footer", index, at)
    return FileScan(header, streams)


def _decode(content: bytes, s: StreamScan, last: float, stamps_only: bool = False) -> tuple[np.ndarray, Any, float]:
    """(raw stamps, values, last stamp) of one Samples chunk's content after the stream id (``stamps_only``: the
    values of fully stamped chunks are not decoded, None)."""
    count, pos = _varlen(content, 0)
    tdiff = 1.0 / s.srate if s.srate > 0 else 0.0
    if s.fmt != "string":
        dtype = np.dtype(DTYPES[s.fmt])
        width = dtype.itemsize * s.nchns
        stride = 9 + width
        buf = np.frombuffer(content, dtype=np.uint8, offset=pos)
        if len(buf) == count * stride and (count == 0 or bool(np.all(buf[::stride] == 8))):
            rows = buf.reshape(count, stride)
            stamps = np.ascontiguousarray(rows[:, 1:9]).view("<f8").reshape(count).astype(np.float64)
            last = float(stamps[-1]) if count else last
            if stamps_only:
                return stamps, None, last
            values = np.ascontiguousarray(rows[:, 9:]).view(dtype).reshape(count, s.nchns)
            return stamps, values.astype(dtype.newbyteorder("=")), last
    stamps = np.zeros(count)
    values: Any = (
        [] if s.fmt == "string" else np.zeros((count, s.nchns), dtype=np.dtype(DTYPES[s.fmt]).newbyteorder("="))
    )
    for k in range(count):
        if content[pos] != 0:
            stamps[k] = struct.unpack_from("<d", content, pos + 1)[0]
            pos += 9
        else:
            stamps[k] = last + tdiff
            pos += 1
        last = stamps[k]
        if s.fmt == "string":
            row = []
            for _ in range(s.nchns):
                n, pos = _varlen(content, pos)
                row.append(bytes(content[pos : pos + n]).decode(errors="replace"))
                pos += n
            values.append(row)
        else:
            width = values.dtype.itemsize * s.nchns
            values[k] = np.frombuffer(content, dtype=DTYPES[s.fmt], count=s.nchns, offset=pos)
            pos += width
    return stamps, values, last


def iter_samples(path: Path, fs: FileScan, stamps_only: bool = False) -> Iterator[tuple[int, np.ndarray, Any]]:
    """(stream id, raw stamps in s, values) of every Samples chunk in file order, the samples a stream keeps only
    (:attr:`StreamScan.keep`); values are (n, channels) arrays of the stream's format, or lists of string rows."""
    from imulog.converters.xdf_chunks import iter_chunk_headers

    last: dict[int, float] = dict.fromkeys(fs.streams, 0.0)
    seen: dict[int, int] = dict.fromkeys(fs.streams, 0)
    with open(path, "rb") as f:
        for index, at, tag, start, length in iter_chunk_headers(path):
            if tag != 3:
                continue
            f.seek(start)
            content = f.read(length)
            sid = int.from_bytes(content[:4], "little")
            s = fs.streams[sid]
            try:
                stamps, values, last[sid] = _decode(content[4:], s, last[sid], stamps_only)
            except (ValueError, IndexError, struct.error) as e:
                raise ConversionError(
                    path, f"chunk {index} (byte {at}): damaged Samples chunk of stream {sid}: {e}"
                ) from None
            room = s.keep - seen[sid]
            if room <= 0:
                continue
            if len(stamps) > room:
                stamps, values = stamps[:room], (None if values is None else values[:room])
            seen[sid] += len(stamps)
            yield sid, stamps, values
