"""Multi-resolution view of long recordings: min/max envelopes per time bucket, full resolution in a window.

A week of wrist data at 100 Hz is 60 M samples per channel: too many to hold in memory or to put in an ``.rrd``.
For a trial longer than :attr:`OverviewParams.full_resolution_max_s` (or when a window is asked for), each
high-rate channel is read chunk by chunk (:meth:`imulog.archive.TrialReader.iter_blocks`) and reduced to an
envelope: for every time bucket, one row at its first sample holding the per-column minimum and one at its last
sample holding the maximum (the M4 idea: a line through these rows covers exactly the pixels the full signal
would). Inside the window (``--start/--end``, seconds on the viewer's timeline) the samples are kept as they are.
Markers and poses are decimated to the first sample of each bucket; intervals are kept whole.

Memory is bounded by one archive chunk plus the envelope (``2 x buckets`` rows per channel), not by the length of
the recording.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from imulog.archive.clocks import ClockMap, device_imu_of
from imulog.model import AnalogStream, ImuStream, Intervals, MarkerStream, PoseStream, SignalStream, take_samples
from imulog.view.source import TrialData, open_trial, read_trial

IMU_FIELDS = ("acc", "gyr", "mag", "temperature")


@dataclass(frozen=True)
class OverviewParams:
    """When and how long recordings are reduced.

    buckets: envelope buckets over the whole trial for each channel (2 rows each).
    max_intervals: an interval channel with more intervals (thousands of movements at home) is shown as the
        share of each bucket it covers, its intervals only inside the window: no lane of unreadable slivers.
    full_resolution_max_s: trials up to this long (s, on the viewer's timeline) are shown at full resolution.
    start_s / end_s: the window kept at full resolution, seconds on the viewer's timeline (None: open end).
    """

    buckets: int = 10_000
    full_resolution_max_s: float = 2 * 3600.0
    max_intervals: int = 2_000
    start_s: float | None = None
    end_s: float | None = None

    @property
    def has_window(self) -> bool:
        return self.start_s is not None or self.end_s is not None


# ---------------------------------------------------------------- pure numerics
def bucket_envelope(
    t_ns: np.ndarray, values: np.ndarray, bucket_ns: int, origin_ns: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per bucket of ``bucket_ns`` from ``origin_ns``: (bucket ids, first t, last t, column minima, column maxima).

    ``t_ns`` sorted (N,), ``values`` (N, C); NaNs are ignored (a bucket of only NaN gives NaN).
    """
    values = np.asarray(values, dtype=np.float64)
    values = values.reshape(len(t_ns), -1) if values.ndim != 2 else values
    if len(t_ns) == 0:
        empty = np.zeros((0, values.shape[1]))
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), empty, empty
    ids = (np.asarray(t_ns, np.int64) - origin_ns) // bucket_ns
    starts = np.flatnonzero(np.concatenate([[True], ids[1:] != ids[:-1]]))
    ends = np.append(starts[1:], len(t_ns)) - 1
    with np.errstate(invalid="ignore"):
        lo = np.fmin.reduceat(values, starts, axis=0)
        hi = np.fmax.reduceat(values, starts, axis=0)
    return ids[starts], np.asarray(t_ns)[starts], np.asarray(t_ns)[ends], lo, hi


class EnvelopeBuilder:
    """Accumulates :func:`bucket_envelope` over consecutive pieces of one channel (a bucket may span two)."""

    def __init__(self, bucket_ns: int, origin_ns: int = 0) -> None:
        self.bucket_ns = int(max(1, bucket_ns))
        self.origin_ns = int(origin_ns)
        self._parts: list[tuple[np.ndarray, ...]] = []

    def add(self, t_ns: np.ndarray, values: np.ndarray) -> None:
        part = bucket_envelope(t_ns, values, self.bucket_ns, self.origin_ns)
        if not len(part[0]):
            return
        if self._parts and self._parts[-1][0][-1] == part[0][0]:  # the previous piece's last bucket goes on
            _, _, last, lo, hi = self._parts[-1]  # arrays of our own: updated in place
            last[-1] = part[2][0]
            lo[-1] = np.fmin(lo[-1], part[3][0])
            hi[-1] = np.fmax(hi[-1], part[4][0])
            part = tuple(a[1:] for a in part)
        if len(part[0]):
            self._parts.append(part)

    def rows(self) -> tuple[np.ndarray, np.ndarray]:
        """(t_ns (2K,), values (2K, C)): the minimum at each bucket's first sample, the maximum at its last."""
        if not self._parts:
            return np.zeros(0, np.int64), np.zeros((0, 0))
        _, first, last, lo, hi = (np.concatenate(a) for a in zip(*self._parts, strict=True))
        t = np.empty(2 * len(first), np.int64)
        t[0::2], t[1::2] = first, last
        v = np.empty((2 * len(first), lo.shape[1]))
        v[0::2], v[1::2] = lo, hi
        return t, v


def interval_share(start_ns: np.ndarray, end_ns: np.ndarray, edges_ns: np.ndarray) -> np.ndarray:
    """Fraction (0-1) of each bucket ``[edges[k], edges[k+1])`` covered by the intervals ``[start, end)`` (ns).

    Covered time up to x is sum(max(x - start, 0)) - sum(max(x - end, 0)); overlapping intervals are clipped to 1.
    """
    edges = np.asarray(edges_ns, np.int64)
    if len(edges) < 2:
        return np.zeros(0)
    starts = np.sort(np.asarray(start_ns, np.int64))
    ends = np.sort(np.asarray(end_ns, np.int64))
    if len(starts) != len(ends):
        raise ValueError(f"interval_share: {len(starts)} starts but {len(ends)} ends")

    def covered(x: np.ndarray) -> np.ndarray:
        x = x.astype(np.float64)
        prefix_s = np.concatenate([[0.0], np.cumsum(starts, dtype=np.float64)])
        prefix_e = np.concatenate([[0.0], np.cumsum(ends, dtype=np.float64)])
        ks = np.searchsorted(starts, x, side="right")
        ke = np.searchsorted(ends, x, side="right")
        return (ks * x - prefix_s[ks]) - (ke * x - prefix_e[ke])

    c = covered(edges)
    width = np.diff(edges).astype(np.float64)
    return np.clip(np.diff(c) / np.where(width > 0, width, 1.0), 0.0, 1.0)


def reduce_intervals(
    s: Intervals, bucket_ns: int, origin_ns: int, n_buckets: int, window: tuple[int, int] | None
) -> tuple[Intervals, SignalStream]:
    """A long interval channel -> (its intervals overlapping ``window`` only, share of each bucket covered).

    Times on the channel's own clock (ns); the share series has one row at each bucket's start, in percent.
    """
    edges = origin_ns + bucket_ns * np.arange(n_buckets + 2, dtype=np.int64)
    share = interval_share(s.start_ns, s.end_ns, edges) * 100.0
    keep = np.zeros(len(s), bool) if window is None else (s.end_ns >= window[0]) & (s.start_ns < window[1])
    index = np.flatnonzero(keep)
    kept = Intervals(s.topic, s.start_ns[index], s.end_ns[index], [s.labels[i] for i in index], s.task_index[index])
    name = s.topic.rstrip("/").rsplit("/", 2)
    label = "/".join(name[-2:]) if len(name) >= 2 else s.topic
    series = SignalStream(f"{s.topic}/share", edges[:-1], [f"{label} time share"], ["%"], share[:, None])
    return kept, series


def first_per_bucket(t_ns: np.ndarray, bucket_ns: int, origin_ns: int = 0) -> np.ndarray:
    """Indices of the first sample of each bucket (for decimating markers and poses)."""
    ids = (np.asarray(t_ns, np.int64) - origin_ns) // max(1, int(bucket_ns))
    return np.flatnonzero(np.concatenate([[True], ids[1:] != ids[:-1]])) if len(ids) else np.zeros(0, np.int64)


# ---------------------------------------------------------------- stream reduction
def _columns(stream: Any) -> tuple[np.ndarray, list[tuple[str, int]]]:
    """Value columns of a block stream and how to split them back: [(field, width), ...]."""
    if isinstance(stream, ImuStream):
        parts, layout = [], []
        for name in IMU_FIELDS:
            value = getattr(stream, name)
            if value is not None:
                value = np.asarray(value, dtype=np.float64).reshape(len(stream), -1)
                parts.append(value)
                layout.append((name, value.shape[1]))
        return np.hstack(parts) if parts else np.zeros((len(stream), 0)), layout
    return np.asarray(stream.values, dtype=np.float64).reshape(len(stream), -1), [("values", stream.values.shape[1])]


def _rebuild(template: Any, t_ns: np.ndarray, values: np.ndarray, layout: list[tuple[str, int]]) -> Any:
    """A stream like ``template`` holding ``values`` at ``t_ns``."""
    pieces, k = {}, 0
    for name, width in layout:
        pieces[name] = values[:, k : k + width]
        k += width
    if isinstance(template, ImuStream):
        temperature = pieces.get("temperature")
        return ImuStream(
            template.name,
            t_ns,
            acc=pieces.get("acc"),
            gyr=pieces.get("gyr"),
            mag=pieces.get("mag"),
            temperature=None if temperature is None else temperature[:, 0],
            frame_id=template.frame_id,
            meta=dict(template.meta),
        )
    if isinstance(template, AnalogStream):
        return AnalogStream(
            template.name,
            t_ns,
            list(template.channel_names),
            list(template.units),
            pieces["values"],
            dict(template.meta),
        )
    return SignalStream(
        template.topic, t_ns, list(template.columns), list(template.units), pieces["values"], template.frame_id
    )


def _concat(pieces: list[Any]) -> Any:
    """Concatenate same-kind streams (decimated markers or poses) in time order."""
    first = pieces[0]
    t = np.concatenate([p.t_ns for p in pieces])
    if isinstance(first, MarkerStream):
        return MarkerStream(
            first.name,
            t,
            list(first.labels),
            np.concatenate([p.pos for p in pieces]),
            np.concatenate([p.valid for p in pieces]),
            first.frame_id,
            dict(first.meta),
        )
    orientation = None if first.orientation is None else np.concatenate([p.orientation for p in pieces])
    return PoseStream(first.topic, t, np.concatenate([p.position for p in pieces]), orientation, first.frame_id)


def reduce_channel(pieces: Iterable[Any], bucket_ns: int, origin_ns: int, window: tuple[int, int] | None) -> Any | None:
    """One channel's pieces (in time order, on the channel's own clock) -> its overview stream.

    Samples inside ``window`` ([start, end) ns on the channel's clock) are kept; the rest is reduced.
    """
    builder = EnvelopeBuilder(bucket_ns, origin_ns)
    kept: list[tuple[np.ndarray, np.ndarray]] = []
    decimated: list[Any] = []
    template = None
    layout: list[tuple[str, int]] = []
    for piece in pieces:
        if not len(piece):
            continue
        template = template if template is not None else piece
        t = np.asarray(piece.t_ns, np.int64)
        inside = np.zeros(len(t), bool) if window is None else (t >= window[0]) & (t < window[1])
        if isinstance(piece, MarkerStream | PoseStream):
            index = np.union1d(first_per_bucket(t, bucket_ns, origin_ns), np.flatnonzero(inside))
            decimated.append(take_samples(piece, index))
            continue
        values, layout = _columns(piece)
        if (~inside).any():
            builder.add(t[~inside], values[~inside])
        if inside.any():
            kept.append((t[inside], values[inside]))
    if template is None:
        return None
    if isinstance(template, MarkerStream | PoseStream):
        return _concat(decimated)
    t_env, v_env = builder.rows()
    ts = [t_env] + [t for t, _ in kept]
    vs = [v_env.reshape(len(t_env), -1) if len(t_env) else np.zeros((0, sum(w for _, w in layout)))]
    vs += [v for _, v in kept]
    t = np.concatenate(ts)
    v = np.concatenate(vs)
    order = np.argsort(t, kind="stable")
    return _rebuild(template, t[order], v[order], layout)


def _reference_to_channel(clocks: ClockMap, topic: str, t_ref_ns: np.ndarray) -> np.ndarray:
    """Inverse of the channel's (linear) clock map, from two points of it."""
    probe = np.array([0, 10**12], dtype=np.int64)
    ref = clocks.to_reference(topic, probe).astype(np.float64)
    slope = (ref[1] - ref[0]) / 1e12
    return np.round((np.asarray(t_ref_ns, np.float64) - ref[0]) / slope).astype(np.int64)


def trial_span_ns(channels: Iterable[Any], clocks: ClockMap) -> tuple[int, int]:
    """(first, last) sample time of the trial on the viewer's timeline (reference clock)."""
    lo, hi = [], []
    for info in channels:
        if info.message_count == 0:
            continue
        ends = clocks.to_reference(info.topic, np.array([info.start_ns, info.end_ns], np.int64))
        lo.append(int(ends[0]))
        hi.append(int(ends[1]))
    return (min(lo), max(hi)) if lo else (0, 0)


def read_trial_overview(
    path: str | Path, params: OverviewParams | None = None, *, lazy: bool = False
) -> tuple[TrialData, bool]:
    """The trial as the viewer should load it, and whether it was reduced.

    Trials no longer than ``params.full_resolution_max_s`` with no window are read whole (:func:`read_trial`),
    or, when ``lazy``, opened with :func:`open_trial` (each channel read when it is logged).
    """
    from imulog.archive import TrialReader

    p = params or OverviewParams()
    path = Path(path)
    with TrialReader(path) as trial:
        channels = list(trial.channels)
        metadata = {k: dict(v) for k, v in trial.metadata.items()}
        channel_meta = {c.topic: dict(c.metadata or {}) for c in channels}
        imu_names = {c.topic.split("/")[2] for c in channels if c.topic.startswith("/imu/")}
        clocks = ClockMap(metadata, channel_meta, imu_names)
        t0, t1 = trial_span_ns(channels, clocks)
        if (t1 - t0) / 1e9 <= p.full_resolution_max_s and not p.has_window:
            return (open_trial(path) if lazy else read_trial(path)), False
        bucket_ns = max(1, (t1 - t0) // max(1, p.buckets))
        window_ref = None
        if p.has_window:
            window_ref = (
                t0 + int((p.start_s or 0.0) * 1e9),
                t1 + 1 if p.end_s is None else t0 + int(p.end_s * 1e9),
            )
        streams: list[Any] = []
        counts: dict[str, int] = {}
        shown = set(trial.topics())  # imulog channels; the viewer twins are for other tools
        for info in channels:
            topic = info.topic
            if topic not in shown:
                continue
            counts[topic] = int(info.sample_count)
            if info.message_count == 0:
                streams.append(trial.read(topic))
                continue
            origin = int(_reference_to_channel(clocks, topic, np.array([t0]))[0])
            window = None
            if window_ref is not None:
                lo, hi = _reference_to_channel(clocks, topic, np.array(window_ref))
                window = (int(lo), int(hi))
            if info.schema_name == "imulog.IntervalEvent":
                intervals = trial.read(topic)
                if isinstance(intervals, Intervals) and len(intervals) > p.max_intervals:
                    kept, share = reduce_intervals(intervals, bucket_ns, origin, p.buckets, window)
                    imu = device_imu_of(topic, channel_meta.get(topic), imu_names, metadata)
                    channel_meta[share.topic] = {"clock": imu or "reference"}  # the intervals' own clock
                    streams.extend([kept, share])
                else:
                    streams.append(intervals)
                continue
            if info.sample_count <= 4 * p.buckets:
                streams.append(trial.read(topic))
                continue
            reduced = reduce_channel(trial.iter_blocks(topic), bucket_ns, origin, window)
            if reduced is not None:
                streams.append(reduced)
    label = path.stem
    return (
        TrialData(
            label=label,
            streams=streams,
            metadata=metadata,
            channel_meta=channel_meta,
            sample_counts=counts,
            source=path,
        ),
        True,
    )
