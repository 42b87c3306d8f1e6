"""The recording loop: pull every inlet, apply LSL clock offsets, write pieces, flush every second.

Time: each sample's LSL time stamp (the source's clock) plus the inlet's latest ``time_correction`` (measured when
the stream is opened and then all along, liblsl updating it in the background) gives its time on the recorder's
LSL clock, ``t_ns`` of every channel (as XDF files converted with their ClockOffset chunks). The raw stamps and the
offset applied to each are kept in ``/signals/<stream>_lsl_clock`` (columns ``lsl_timestamp``, ``time_correction``,
s), every offset measured in the ``imulog.record`` summary. A sample whose corrected time does not increase is
dropped (counted as ``rejected``); on a stream with a nominal rate a step over 1.5 sample periods is a gap, its
missing samples counted as ``dropped``. The trial's ``start_time`` is the wall-clock time of the first sample.
"""

from __future__ import annotations

import datetime as _dt
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imulog.live.lsl import LslError, describe, pylsl
from imulog.live.mapping import chunk_to_recording, header_info, stream_names
from imulog.live.writer import SUMMARY_RECORD, LiveTrialWriter
from imulog.model import Recording, SignalStream

PULL_S = 0.02  # sleep between pulls when nothing arrived
WRITE_S = 0.2  # buffered samples are written at least this often
FLUSH_S = 0.5  # chunks closed, written and fsynced at least this often (a kill loses at most this much)
START_WAIT_S = 2.0  # the first piece waits this long for every regular stream's first sample (sets the time axis)


@dataclass
class LiveStream:
    """One inlet being recorded and what it has delivered."""

    inlet: Any
    name: str
    xml: str
    info: dict[str, Any]
    srate: float
    listing: str
    samples: int = 0
    gaps: int = 0
    dropped: int = 0
    rejected: int = 0
    last_s: float | None = None
    first_s: float | None = None
    offset_s: float = 0.0
    offsets: list[tuple[float, float]] = field(default_factory=list)  # (recorder LSL time, offset) when it changed
    stamps: list[float] = field(default_factory=list)
    values: list[Any] = field(default_factory=list)
    raw_offsets: list[float] = field(default_factory=list)  # the offset added to each buffered stamp

    def summary(self) -> dict[str, Any]:
        offs = [o for _, o in self.offsets]
        return {
            "samples": self.samples,
            "gaps": self.gaps,
            "dropped": self.dropped,
            "rejected": self.rejected,
            "nominal_srate_hz": self.srate,
            "first_lsl_s": self.first_s,
            "last_lsl_s": self.last_s,
            "time_correction_s": [[round(t, 6), o] for t, o in self.offsets],
            "time_correction_range_s": [min(offs), max(offs)] if offs else [],
        }


def open_streams(infos: list[Any], open_timeout_s: float = 10.0) -> list[LiveStream]:
    """An inlet per resolved stream, its full header (with ``desc``) and a first clock-offset measurement."""
    lsl = pylsl()
    names = stream_names([i.name() for i in infos])
    out = []
    for k, (info, name) in enumerate(zip(infos, names, strict=True)):
        inlet = lsl.StreamInlet(info, max_buflen=360, recover=True)
        try:
            full = inlet.info(timeout=open_timeout_s)
            inlet.open_stream(timeout=open_timeout_s)
            offset = inlet.time_correction(timeout=open_timeout_s)
        except Exception as exc:  # noqa: BLE001 - pylsl raises TimeoutError / LostError / RuntimeError
            raise LslError(f"LSL stream {info.name()!r}: cannot open it ({type(exc).__name__}: {exc})") from None
        xml = full.as_xml()
        stream = LiveStream(inlet, name, xml, header_info(xml, k + 1), full.nominal_srate(), describe(full))
        stream.offset_s = offset
        stream.offsets.append((lsl.local_clock(), offset))
        out.append(stream)
    return out


def _iso(wall_s: float) -> str:
    return _dt.datetime.fromtimestamp(wall_s, tz=_dt.UTC).isoformat(timespec="microseconds")


class Recorder:
    """Records ``streams`` into ``writer`` until ``stop`` is set (or ``duration_s`` passed since the first sample).

    ``on_piece(recording)``, when given, sees every written piece (the live view). ``on_first_flush()``, when given, is called
    once, after the first samples are written and fsynced (from then on a kill leaves a ``.part`` salvage recovers).
    """

    def __init__(
        self,
        streams: list[LiveStream],
        writer: LiveTrialWriter,
        *,
        stop: threading.Event | None = None,
        duration_s: float | None = None,
        on_piece: Callable[[Recording], None] | None = None,
        on_first_flush: Callable[[], None] | None = None,
        flush_s: float = FLUSH_S,
    ) -> None:
        self.streams = streams
        self.writer = writer
        self.stop = stop or threading.Event()
        self.duration_s = duration_s
        self.on_piece = on_piece
        self.on_first_flush = on_first_flush
        self.flush_s = flush_s
        self.lsl = pylsl()
        self.started_s: float | None = None  # recorder LSL time of the first written sample

    # ------------------------------------------------------------------ loop
    def run(self) -> None:
        opened = self.lsl.local_clock()
        last_write = last_flush = last_offsets = opened
        while True:
            stopping = self.stop.is_set()
            got = self._pull_all()
            now = self.lsl.local_clock()
            if now - last_offsets >= 1.0:
                self._measure_offsets(now)
                last_offsets = now
            if self.duration_s is not None and self.started_s is not None:
                stopping = stopping or now - self.started_s >= self.duration_s
            if now - last_write >= WRITE_S or stopping:
                if self.writer.started or self._ready(now - opened) or stopping:
                    self._write(limit_s=self.started_s + self.duration_s if self._limited() else None)
                last_write = now
            first_flush = self.writer.started and self.on_first_flush is not None
            if self.writer.started and (now - last_flush >= self.flush_s or stopping or first_flush):
                self.writer.flush()
                last_flush = now
                if first_flush:
                    self.on_first_flush()
                    self.on_first_flush = None
            if stopping:
                return
            if not got:
                self.stop.wait(PULL_S)

    def _limited(self) -> bool:
        return self.duration_s is not None and self.started_s is not None

    def _ready(self, waited_s: float) -> bool:
        """The first piece: once every stream with a nominal rate has sent a sample (or START_WAIT_S passed)."""
        regular = [s for s in self.streams if s.srate > 0]
        have = [s for s in self.streams if s.stamps]
        return bool(have) and (all(s.stamps for s in regular) or waited_s >= START_WAIT_S)

    def _pull_all(self) -> bool:
        got = False
        for s in self.streams:
            try:
                values, stamps = s.inlet.pull_chunk(timeout=0.0, max_samples=8192)
            except Exception as exc:  # noqa: BLE001 - LostError cannot happen with recover=True; anything else ends
                raise LslError(f"LSL stream {s.name!r}: {type(exc).__name__}: {exc}") from None
            if stamps:
                got = True
                s.stamps.extend(float(t) + s.offset_s for t in stamps)
                s.values.extend(values)
                s.raw_offsets.extend([s.offset_s] * len(stamps))
        return got

    def _measure_offsets(self, now: float) -> None:
        for s in self.streams:
            try:
                offset = s.inlet.time_correction(timeout=0.0)
            except Exception:  # noqa: BLE001 - no new estimate yet (TimeoutError): keep the last
                continue
            if offset != s.offset_s:
                s.offset_s = offset
                s.offsets.append((now, offset))

    # ------------------------------------------------------------------ writing
    def _write(self, limit_s: float | None = None) -> None:
        pieces = []
        for s in self.streams:
            piece = self._take(s, limit_s)
            if piece is not None:
                pieces.append(piece)
        if not pieces:
            return
        if not self.writer.started:
            first = min(float(p.metadata["_first_s"]["t"]) for p in pieces)
            self.started_s = first
            wall = time.time() - (self.lsl.local_clock() - first)
            self.writer.add_records({"imulog.trial": {"start_time": _iso(wall), "time_zone": "UTC"}})
        merged = Recording()
        for p in pieces:
            p.metadata.pop("_first_s")
            merged = merged.merge(p)
        self.writer.write(merged)
        if self.on_piece is not None:
            self.on_piece(merged)

    def _take(self, s: LiveStream, limit_s: float | None) -> Recording | None:
        """The buffered samples of ``s`` as channels (and its clock channel); None when there are none to write."""
        if not s.stamps:
            return None
        t = np.asarray(s.stamps, dtype=np.float64)
        offsets = np.asarray(s.raw_offsets, dtype=np.float64)
        values = s.values
        s.stamps, s.values, s.raw_offsets = [], [], []
        if limit_s is not None:  # --duration: what arrives after the end is not part of the trial
            t = t[t <= limit_s]
        keep = np.ones(len(t), dtype=bool)
        prev = s.last_s
        for i, ti in enumerate(t):  # strictly increasing corrected times (a new offset may step back)
            if prev is not None and ti <= prev:
                keep[i] = False
            else:
                prev = ti
        s.rejected += int(np.count_nonzero(~keep))
        if not keep.any():
            return None
        idx = np.flatnonzero(keep)
        t, offsets = t[idx], offsets[idx]
        values = [values[i] for i in idx]
        if s.srate > 0:
            steps = np.diff(np.concatenate([[s.last_s], t]) if s.last_s is not None else t)
            big = steps > 1.5 / s.srate
            s.gaps += int(np.count_nonzero(big))
            s.dropped += int(np.sum(np.maximum(np.round(steps[big] * s.srate) - 1, 0)))
        if s.first_s is None:
            s.first_s = float(t[0])
        s.last_s = float(t[-1])
        s.samples += len(t)
        rec = chunk_to_recording(s.info, s.name, t, values, source=f"lsl:{s.name}")
        device = rec.metadata.get(f"imulog.device.{s.name}", {})
        device.update(
            format="lsl",
            source=f"lsl stream {s.listing}",
            time_base="ns of the recorder's LSL clock, the stream's time_correction applied",
        )
        device.pop("samples", None)
        rec.metadata[f"imulog.lsl.{s.name}"] = {"xml": s.xml}
        rec.signals.append(
            SignalStream(
                topic=f"/signals/{s.name}_lsl_clock",
                t_ns=np.round(t * 1e9).astype(np.int64),
                columns=["lsl_timestamp", "time_correction"],
                units=["s", "s"],
                values=np.column_stack([t - offsets, offsets]),
            )
        )
        rec.metadata["_first_s"] = {"t": float(t[0])}
        return rec

    def summary_record(self) -> dict[str, Any]:
        return {
            "recorder": "imulog record (Lab Streaming Layer)",
            "liblsl_version": int(self.lsl.library_version()),
            "streams": {s.name: s.summary() for s in self.streams},
        }

    def finish(self) -> None:
        """The summary record for the end of the file."""
        self.writer.metadata[SUMMARY_RECORD] = self.summary_record()
        for s in self.streams:
            s.inlet.close_stream()


def summary_lines(streams: list[LiveStream]) -> list[str]:
    """The summary printed when a recording stops: streams, samples, gaps, dropped and rejected samples."""
    firsts = [s.first_s for s in streams if s.first_s is not None]
    lasts = [s.last_s for s in streams if s.last_s is not None]
    span = f", {max(lasts) - min(firsts):.1f} s recorded" if firsts else ", nothing recorded"
    lines = [f"{len(streams)} stream(s){span}"]
    for s in streams:
        lines.append(
            f"  {s.name}: {s.samples} samples, {s.gaps} gap(s), {s.dropped} dropped, {s.rejected} rejected"
            f" (time_correction {s.offset_s * 1e3:+.3f} ms)"
        )
    return lines
