"""Helpers shared by the binary wearable readers (Axivity, ActiGraph): civil dates, ISO start times, chunk assembly.

The readers decode their files in bounded batches behind ``iter_chunks(path) -> Iterator[Recording]``; every chunk
holds the same streams (same names, topics, columns) on one time origin, so :func:`concat_chunks` can assemble
them into one :class:`imulog.model.Recording` (and a streaming writer can consume them one by one).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Iterator
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np

from imulog.model import (
    PIECES_RECORD,
    AnalogStream,
    ImuStream,
    Intervals,
    MarkerStream,
    PoseStream,
    Recording,
    SignalStream,
)

NS_PER_S = 1_000_000_000
UNKNOWN_ZONE = "unknown (device local time)"


def days_from_civil(year: np.ndarray, month: np.ndarray, day: np.ndarray) -> np.ndarray:
    """Days since 1970-01-01 of proleptic Gregorian dates (vectorised; H. Hinnant's algorithm), int64."""
    y = np.asarray(year, dtype=np.int64) - (np.asarray(month) <= 2)
    m = np.asarray(month, dtype=np.int64)
    d = np.asarray(day, dtype=np.int64)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    doy = (153 * (m + np.where(m > 2, -3, 9)) + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


def iso_from_epoch_ns(epoch_ns: int, utc_offset_s: int | None = None) -> str:
    """ISO-8601 of ``epoch_ns`` (ns since 1970 on the clock's own wall time): milliseconds when the time is a whole
    millisecond, else microseconds (rounded), so the trial's first sample keeps its sub-millisecond time (a .cwa
    block starts at a 1/65536 s fraction).

    ``utc_offset_s`` None gives a naive local time (``2020-02-12T09:03:38.000``); otherwise the wall time is
    written with its offset (``2019-02-14T08:58:00.000-05:00``).
    """
    wall = datetime(1970, 1, 1) + timedelta(microseconds=(int(epoch_ns) + 500) // 1000)
    spec = "milliseconds" if wall.microsecond % 1000 == 0 else "microseconds"
    if utc_offset_s is None:
        return wall.isoformat(timespec=spec)
    return wall.replace(tzinfo=UTC).isoformat(timespec=spec).replace("+00:00", format_offset(utc_offset_s))


def format_offset(utc_offset_s: int) -> str:
    """``-18000`` -> ``-05:00``; 0 -> ``+00:00``."""
    sign = "-" if utc_offset_s < 0 else "+"
    minutes = abs(int(utc_offset_s)) // 60
    return f"{sign}{minutes // 60:02d}:{minutes % 60:02d}"


def time_zone_label(utc_offset_s: int | None) -> str:
    """The ``imulog.trial`` ``time_zone`` value: ``UTC``, ``+HH:MM``/``-HH:MM`` or the unknown-zone label."""
    if utc_offset_s is None:
        return UNKNOWN_ZONE
    return "UTC" if utc_offset_s == 0 else format_offset(utc_offset_s)


INLINE_FILL = 1 << 16  # NaN samples a gap may add to its own piece; longer gaps become pieces of their own
FILL_PIECE = 1 << 20  # samples per NaN piece of a long gap


def with_fills(
    t: np.ndarray,
    values: dict[str, np.ndarray | None],
    positions: np.ndarray,
    fill_t0: np.ndarray,
    fill_n: np.ndarray,
    step_ns: float,
    *,
    inline: int | None = None,
    piece: int | None = None,
) -> Iterator[tuple[np.ndarray, dict[str, np.ndarray | None]]]:
    """Samples ``(t, values)`` with runs of NaN samples inserted, in time order, in bounded pieces.

    Before sample ``positions[j]`` come ``fill_n[j]`` NaN samples at ``fill_t0[j] + round(k * step_ns)`` (the
    caller makes them fit between the samples around them). A run of more than ``inline`` samples (default
    ``INLINE_FILL``) is yielded as pieces of ``piece`` (``FILL_PIECE``) samples of its own, so memory stays
    bounded whatever the gap; ``values`` entries that are None stay None.
    """
    inline = INLINE_FILL if inline is None else inline
    piece = FILL_PIECE if piece is None else piece
    keys = [k for k, v in values.items() if v is not None]
    nones = {k: None for k, v in values.items() if v is None}
    pending_t: list[np.ndarray] = []
    pending_v: dict[str, list[np.ndarray]] = {k: [] for k in keys}

    def nan_block(n: int) -> dict[str, np.ndarray]:
        return {k: np.full((n, *values[k].shape[1:]), np.nan) for k in keys}  # type: ignore[union-attr]

    def flush() -> tuple[np.ndarray, dict[str, np.ndarray | None]] | None:
        if not pending_t:
            return None
        out = np.concatenate(pending_t), {**{k: np.concatenate(pending_v[k]) for k in keys}, **nones}
        pending_t.clear()
        for v in pending_v.values():
            v.clear()
        return out

    cursor = 0
    for j in range(len(positions)):
        n = int(fill_n[j])
        if n <= 0:
            continue
        stop = int(positions[j])
        pending_t.append(t[cursor:stop])
        for k in keys:
            pending_v[k].append(values[k][cursor:stop])  # type: ignore[index]
        cursor = stop
        t0 = int(fill_t0[j])

        def times(a: int, m: int, t0: int = t0) -> np.ndarray:
            return t0 + np.round(np.arange(a, a + m, dtype=np.float64) * step_ns).astype(np.int64)

        if n <= inline:
            pending_t.append(times(0, n))
            for k, block in nan_block(n).items():
                pending_v[k].append(block)
            continue
        done = flush()
        if done is not None:
            yield done
        for a in range(0, n, piece):
            m = min(piece, n - a)
            yield times(a, m), {**nan_block(m), **nones}
    pending_t.append(t[cursor:])
    for k in keys:
        pending_v[k].append(values[k][cursor:])  # type: ignore[index]
    done = flush()
    if done is not None:
        yield done


def _cat(parts: list[np.ndarray | None]) -> np.ndarray | None:
    if any(p is None for p in parts):
        return None
    return np.concatenate(parts)  # type: ignore[arg-type]


def concat_chunks(chunks: Iterable[Recording]) -> Recording:
    """One Recording from the chunks of one file: every kind of stream joined by name/topic; metadata records and
    each stream's ``meta`` are the first chunk's updated by every later one (a reader learns e.g. the rate as it goes).

    A stream missing from some chunks is joined from the chunks that have it. Raises ValueError when no chunk.
    """
    chunks = list(chunks)
    if not chunks:
        raise ValueError("no chunks")
    first = chunks[0]
    out = Recording(
        metadata={k: dict(v) for k, v in first.metadata.items()},
        sources=list(first.sources),
        warnings=[w for c in chunks for w in c.warnings],
    )
    for later in chunks[1:]:
        for key, value in later.metadata.items():
            out.metadata[key] = {**out.metadata.get(key, {}), **value}
    out.metadata.pop(PIECES_RECORD, None)  # what the pieces declared for the streaming writer: not a record
    imus: dict[str, list[ImuStream]] = {}
    signals: dict[str, list[SignalStream]] = {}
    events: dict[str, list[Intervals]] = {}
    markers: dict[str, list[MarkerStream]] = {}
    analogs: dict[str, list[AnalogStream]] = {}
    poses: dict[str, list[PoseStream]] = {}
    for c in chunks:
        for s in c.analogs:
            analogs.setdefault(s.name, []).append(s)
        for s in c.poses:
            poses.setdefault(s.topic, []).append(s)
        for s in c.markers:
            markers.setdefault(s.name, []).append(s)
        for s in c.imus:
            imus.setdefault(s.name, []).append(s)
        for s in c.signals:
            signals.setdefault(s.topic, []).append(s)
        for s in c.events:
            events.setdefault(s.topic, []).append(s)
    for kind, groups in ((out.imus, imus), (out.signals, signals), (out.markers, markers)):
        kind.extend(_join(parts) for parts in groups.values())
    for parts in events.values():
        out.events.append(
            Intervals(
                topic=parts[0].topic,
                start_ns=np.concatenate([p.start_ns for p in parts]),
                end_ns=np.concatenate([p.end_ns for p in parts]),
                labels=[label for p in parts for label in p.labels],
                task_index=np.concatenate([p.task_index for p in parts]),
            )
        )
    for kind, groups in ((out.analogs, analogs), (out.poses, poses)):
        kind.extend(_join(parts) for parts in groups.values())
    return out


def _join(parts: list[Any]) -> Any:
    """One sample stream (IMU, signal, marker, analog, pose) from its consecutive parts: every array field joined
    (None when a part lacks it), ``meta`` merged (:func:`_meta`), names, labels, units and the rest the first's."""
    p0 = parts[0]
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(p0):
        v = getattr(p0, f.name)
        if f.name == "meta":
            fields[f.name] = _meta(parts)
        elif isinstance(v, np.ndarray) or v is None:
            fields[f.name] = _cat([getattr(p, f.name) for p in parts])
        else:
            fields[f.name] = type(v)(v) if isinstance(v, (list, dict)) else v
    return type(p0)(**fields)


def _meta(parts: list[Any]) -> dict[str, Any]:
    """A joined stream's ``meta``: the first part's, updated by each later part's."""
    out: dict[str, Any] = {}
    for p in parts:
        out.update(p.meta)
    return out
