"""An XDF recording as consecutive pieces on one time axis (``imulog.converters.xdf.iter_chunks``).

Pass 1 (:func:`~imulog.converters.xdf_read.scan`) reads headers, clock offsets, footers and sample counts, so every
stream's clock lines are fitted before a sample is decoded. Pass 2 (pieces only) decodes the stamps and maps them,
giving each stream's first and last synchronised time and its clock segments: the first piece declares them
(:data:`imulog.model.PIECES_RECORD`), since XDF interleaves its streams and a stream whose chunks come later may
start earlier. Pass 3 decodes samples chunk by chunk and gives a piece whenever about ``piece_bytes`` of values are
gathered. One piece (``piece_bytes=None``) skips pass 2. Memory: one piece, the clock offsets and one chunk.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters.xdf_read import FileScan, StreamScan, iter_samples, scan

from imulog.model import PIECES_RECORD, ImuStream, MarkerStream, Recording, SignalStream


def _names(fs: FileScan) -> dict[int, str]:
    """Topic-safe stream names (:func:`imulog.converters.xdf._stream_names`)."""
    from imulog.converters.xdf_map import _first, _stream_names

    return _stream_names([{"stream_id": sid, "name": _first(s.info, "name")} for sid, s in fs.streams.items()])


def _to_ns(t_s: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(t_s, dtype=np.float64) * 1e9).astype(np.int64)


def _spans(path: Path, fs: FileScan) -> tuple[dict[int, list[int] | None], dict[int, int]]:
    """Pass 2: every stream's first and last synchronised stamp (ns) and the clock segments its samples use."""
    clocks = {sid: s.clock() for sid, s in fs.streams.items()}
    first: dict[int, int] = {}
    last: dict[int, int] = {}
    for sid, stamps, _ in iter_samples(path, fs, stamps_only=True):
        t = _to_ns(clocks[sid].map(stamps))
        if len(t):
            first.setdefault(sid, int(t[0]))
            last[sid] = int(t[-1])
    spans = {sid: ([first[sid], last[sid]] if sid in first else None) for sid in fs.streams}
    return spans, {sid: len(c.used) for sid, c in clocks.items()}


class _Gathered:
    """One stream's samples since the last piece, and what is checked across pieces."""

    def __init__(self, s: StreamScan) -> None:
        self.scan = s
        self.t: list[np.ndarray] = []
        self.values: list[Any] = []
        self.bytes = 0
        self.before: int | None = None  # the previous piece's last stamp
        self.seen = 0

    def add(self, t_ns: np.ndarray, values: Any) -> None:
        self.t.append(t_ns)
        self.values.append(values)
        self.bytes += len(t_ns) * (8 + 8 * self.scan.nchns)

    def take(self) -> tuple[np.ndarray, Any]:
        t = np.concatenate(self.t) if self.t else np.zeros(0, np.int64)
        if self.scan.fmt == "string":
            values: Any = [row for part in self.values for row in part]
        else:
            values = np.concatenate(self.values) if self.values else np.zeros((0, self.scan.nchns))
        self.t, self.values, self.bytes = [], [], 0
        return t, values


def iter_pieces(path: Path, piece_bytes: int | None) -> Iterator[Recording]:
    """The pieces of an XDF file whose chunk structure and Samples layouts were checked (see module docstring)."""
    from imulog.converters.xdf_map import _check_increasing, header_start_time, stream_layout, stream_piece

    fs = scan(path)
    names = _names(fs)
    layouts = {sid: stream_layout(s.info) for sid, s in fs.streams.items()}
    trial = header_start_time(fs.header)
    declared = None
    metas: dict[int, dict] = {}
    if piece_bytes is not None:
        spans, segments = _spans(path, fs)
        metas = {sid: _meta(path, s, names[sid], segments[sid]) for sid, s in fs.streams.items()}
        declared = _declaration(names, layouts, metas, spans)
    clocks = {sid: s.clock() for sid, s in fs.streams.items()}
    gathered = {sid: _Gathered(s) for sid, s in fs.streams.items()}
    first = True

    def piece(sids: list[int]) -> Recording:
        rec = Recording(sources=[str(path)])
        for sid in sids:
            g = gathered[sid]
            t, values = g.take()
            meta = metas.get(sid) or _meta(path, g.scan, names[sid], len(clocks[sid].used))
            rec.metadata[f"imulog.device.{names[sid]}"] = meta
            _check_increasing(path, t, meta, g.before, g.seen)
            if len(t):
                g.before, g.seen = int(t[-1]), g.seen + len(t)
            for s in stream_piece(names[sid], layouts[sid], t, values, meta):
                kinds = {ImuStream: rec.imus, MarkerStream: rec.markers, SignalStream: rec.signals}
                kinds.get(type(s), rec.events).append(s)
        if trial:
            rec.metadata["imulog.trial"] = dict(trial)
        return rec

    pending = 0
    for sid, stamps, values in iter_samples(path, fs):
        gathered[sid].add(_to_ns(clocks[sid].map(stamps)), values)
        pending += len(stamps) * (8 + 8 * fs.streams[sid].nchns)
        if piece_bytes is not None and pending >= piece_bytes:
            rec = piece(sorted(fs.streams) if first else [sid for sid, g in gathered.items() if g.t])
            if first and declared is not None:
                rec.metadata[PIECES_RECORD] = declared
            first, pending = False, 0
            yield rec
    rec = piece(sorted(fs.streams) if first else [sid for sid, g in gathered.items() if g.t])
    if first and declared is not None:
        rec.metadata[PIECES_RECORD] = declared
    if first or rec.streams():
        yield rec


def _meta(path: Path, s: StreamScan, name: str, segments: int) -> dict:
    from imulog.converters.xdf_map import device_meta

    info = {**s.info, "stream_id": [str(s.sid)]}
    return device_meta(path, info, name, s.keep, s.footer, segments)


def _declaration(
    names: dict[int, str], layouts: dict[int, Any], metas: dict[int, dict], spans: dict[int, list[int] | None]
) -> dict[str, Any]:
    """``{"spans": {topic: [first, last] or None}, "meta": {topic: stream meta}}`` of every stream's channels."""
    from imulog.converters.xdf_map import stream_piece

    out: dict[str, Any] = {"spans": {}, "meta": {}}
    for sid, name in sorted(names.items()):
        empty = np.zeros(0, np.int64)
        series: Any = [] if layouts[sid][0] == "events" else np.zeros((0, int(metas[sid]["channel_count"])))
        for s in stream_piece(name, layouts[sid], empty, series, metas[sid]):
            out["spans"][s.topic] = spans[sid]
            if hasattr(s, "meta"):
                out["meta"][s.topic] = dict(s.meta)
    return out
