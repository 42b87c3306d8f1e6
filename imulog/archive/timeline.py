"""One MCAP time axis per trial: where each channel's messages sit in log time (ns since the Unix epoch).

The payload keeps every sample's own clock (``t_ns``); only the MCAP ``log_time`` of a message is placed on
the trial's axis, so that any MCAP tool (Foxglove, Rerun's loader) shows IMU and Vicon data together:

* the axis starts at the trial's absolute start, ``imulog.trial["start_time"]`` (ISO-8601; a time without a
  UTC offset, i.e. device local time, is placed as if it were UTC); without one at :data:`DEFAULT_EPOCH`;
* device-clock channels (``/imu/*`` and what is computed from them): ``start + (t - t0_device)``, with
  ``t0_device`` the first sample of the trial's IMUs;
* reference-clock channels (markers, analog, Vicon outputs): ``start + (t - t0_reference)`` from their own
  first sample until the trial is aligned; after ``imulog process align``, channels written from then on
  (derived reference-clock channels and the viewer channels) go through the alignment's clock mapping
  (:func:`imulog.process.alignment.reference_to_device`): ``start + (to_device(t) - t0_device)``;
* when the IMU and reference spans overlap (one shared clock, e.g. BROAD), both use the earlier first sample.

The choice is recorded in the ``imulog.timeline`` metadata record and, per channel, as the ``log_time``
channel metadata (``{"epoch_ns", "origin_ns", "scale"}``: ``log_time = epoch_ns + round((t - origin_ns) *
scale)``), which the reader uses to turn a ``t_ns`` range into a log-time range. Files written before this
record existed have log time = ``t_ns`` (clamped at 0) and keep it when derived channels are appended.
"""

from __future__ import annotations

import datetime as _dt
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from imulog._lazy import LazyModule

np = LazyModule("numpy", __name__)  # imported on first use: imulog info never needs numpy

DEFAULT_EPOCH = "2000-01-01T00:00:00+00:00"  # axis start when the trial's start time is unknown
_MAX = 2**64 - 1
TIMELINE_RECORD = "imulog.timeline"
#: derived topic families on the device clock of the IMU named last in the topic (as imulog.archive.clocks)
DEVICE_DERIVED = ("orientation", "acc_global", "static", "orientation_static", "calibrated", "metrics")
#: derived topic families on the reference clock
REFERENCE_DERIVED = ("reference", "vicon", "kinematics", "viewer")
#: derived kind -> metadata record whose ``clock`` says which clock the step wrote
STEP_CLOCK_RECORDS = {"phases": "imulog.timing", "movements": "imulog.timing", "trajectory": "imulog.trajectory"}


class TimelineError(ValueError):
    """A start time that is not ISO-8601."""


@dataclass(frozen=True)
class LogMap:
    """``log_time = epoch_ns + round((t - origin_ns) * scale)``, clamped to MCAP's unsigned 64-bit range."""

    epoch_ns: int = 0
    origin_ns: int = 0
    scale: float = 1.0

    def __call__(self, t_ns: np.ndarray | Sequence[int]) -> np.ndarray:
        """Log times (uint64 ns) of payload times ``t_ns`` (int64 ns)."""
        t = np.asarray(t_ns, dtype=np.int64)
        if self.scale == 1.0 and (not t.size or not _overflows(t, self.origin_ns)):
            rel = t - np.int64(self.origin_ns)  # exact integer arithmetic
            rel = np.clip(rel, -self.epoch_ns, np.iinfo(np.int64).max - self.epoch_ns)
            return (rel + np.int64(self.epoch_ns)).astype(np.uint64)
        out = np.round((t.astype(np.float64) - float(self.origin_ns)) * self.scale) + float(self.epoch_ns)
        return np.clip(out, 0, float(_MAX)).astype(np.uint64)

    def one(self, t_ns: int) -> int:
        return int(self(np.array([t_ns], dtype=np.int64))[0])

    def to_meta(self) -> str:
        return json.dumps({"epoch_ns": self.epoch_ns, "origin_ns": self.origin_ns, "scale": self.scale})

    @classmethod
    def from_meta(cls, meta: Mapping[str, str]) -> LogMap:
        """The channel's map from its ``log_time`` metadata; identity (old files) when absent."""
        raw = meta.get("log_time")
        if not raw:
            return IDENTITY
        try:
            d = json.loads(raw)
            return cls(int(d["epoch_ns"]), int(d["origin_ns"]), float(d.get("scale", 1.0)))
        except (ValueError, KeyError, TypeError):
            return IDENTITY


IDENTITY = LogMap()


def _overflows(t: np.ndarray, origin: int) -> bool:
    lo, hi = int(t.min()), int(t.max())
    return not (-(2**62) < lo - origin < 2**62 and -(2**62) < hi - origin < 2**62)


def parse_start_time(value: Any) -> tuple[int, str]:
    """ISO-8601 start time -> (ns since the Unix epoch, time zone: "UTC", "+HH:MM" or "unknown ...")."""
    text = str(value).strip()
    try:
        when = _dt.datetime.fromisoformat(text.replace("Z", "+00:00") if text.endswith("Z") else text)
    except ValueError:
        raise TimelineError(f"imulog.trial start_time {text!r} is not an ISO-8601 time") from None
    if when.tzinfo is None:
        zone = "unknown (device local time)"
        when = when.replace(tzinfo=_dt.UTC)
    else:
        off = when.utcoffset() or _dt.timedelta(0)
        minutes = int(off.total_seconds() // 60)
        zone = (
            "UTC" if minutes == 0 else f"{'+' if minutes > 0 else '-'}{abs(minutes) // 60:02d}:{abs(minutes) % 60:02d}"
        )
    epoch = _dt.datetime(1970, 1, 1, tzinfo=_dt.UTC)
    delta = when - epoch
    return (delta.days * 86_400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000, zone


def _span(streams: Sequence[Any]) -> tuple[int, int] | None:
    lo, hi = [], []
    for s in streams:
        t = getattr(s, "t_ns", None)
        if t is None:
            t, t_end = getattr(s, "start_ns", None), getattr(s, "end_ns", None)
            if t is None or not len(t):
                continue
            lo.append(int(t.min()))
            hi.append(int(t_end.max()))
        elif len(t):
            lo.append(int(t.min()))
            hi.append(int(t.max()))
    return (min(lo), max(hi)) if lo else None


def timeline_record(trial: Mapping[str, Any] | None, streams: Sequence[Any]) -> dict[str, Any]:
    """The ``imulog.timeline`` record for a trial being converted (``trial``: its ``imulog.trial`` record)."""
    start = (trial or {}).get("start_time")
    if start not in (None, ""):
        epoch_ns, zone = parse_start_time(start)
        source, epoch_text = "imulog.trial start_time", str(start)
    else:
        epoch_ns, _ = parse_start_time(DEFAULT_EPOCH)
        zone, source, epoch_text = "UTC", "fixed epoch (the trial's start time is unknown)", DEFAULT_EPOCH
    device = _span([s for s in streams if channel_clock(s.topic) == "device"])
    reference = _span([s for s in streams if channel_clock(s.topic) == "reference"])
    shared = device is not None and reference is not None and device[0] <= reference[1] and reference[0] <= device[1]
    if shared:
        origin = min(device[0], reference[0])
        device, reference = (origin, device[1]), (origin, reference[1])
    return {
        "epoch": epoch_text,
        "epoch_ns": epoch_ns,
        "time_zone": zone,
        "source": source,
        "device_origin_ns": device[0] if device else None,
        "reference_origin_ns": reference[0] if reference else None,
        "clocks": "shared" if shared else "separate",
        "version": 1,
    }


def channel_clock(
    topic: str,
    channel_meta: Mapping[str, Any] | None = None,
    step_records: Mapping[str, Mapping[str, Any]] | None = None,
    imu_names: set[str] | None = None,
) -> str:
    """``"device"`` or ``"reference"``: the clock of a channel, by the rules of :mod:`imulog.archive.clocks`."""
    clock = (channel_meta or {}).get("clock")
    if clock:
        return "reference" if str(clock) in ("reference", "ref", "vicon") else "device"
    parts = topic.strip("/").split("/")
    if len(parts) == 2 and parts[0] == "imu":
        return "device"
    if len(parts) < 3 or parts[0] != "derived" or parts[1] in REFERENCE_DERIVED:
        return "reference"
    if parts[1] in STEP_CLOCK_RECORDS and len(parts) == 3:
        step_clock = ((step_records or {}).get(STEP_CLOCK_RECORDS[parts[1]]) or {}).get("clock")
        if parts[1] == "trajectory":
            return "device" if step_clock == "device" else "reference"
        return "reference" if step_clock == "reference" else "device"
    if imu_names is not None and parts[-1] in imu_names:
        return "device"
    return "device" if parts[1] in DEVICE_DERIVED else "reference"


class TrialAxis:
    """Log-time maps for the channels of one trial, from its ``imulog.timeline`` and ``imulog.alignment``."""

    def __init__(self, metadata: Mapping[str, Mapping[str, Any]], imu_names: set[str] | None = None) -> None:
        self.timeline = dict(metadata.get(TIMELINE_RECORD) or {})
        self.alignment = dict(metadata.get("imulog.alignment") or {}) or None
        self.step_records = {k: dict(metadata[k]) for k in set(STEP_CLOCK_RECORDS.values()) if k in metadata}
        self.imu_names = imu_names

    @property
    def known(self) -> bool:
        return bool(self.timeline)

    def clock_of(self, topic: str, channel_meta: Mapping[str, Any] | None = None) -> str:
        """``"reference"``, or the name of the IMU whose device clock ``topic`` is on."""
        if channel_clock(topic, channel_meta, self.step_records, self.imu_names) == "reference":
            return "reference"
        clock = (channel_meta or {}).get("clock")
        if clock:
            return str(clock).rsplit("/", 1)[-1]
        parts = topic.strip("/").split("/")
        if parts[1:2] == ["trajectory"]:
            return str(self.step_records.get("imulog.trajectory", {}).get("imu") or "").rsplit("/", 1)[-1] or "device"
        return parts[-1]

    def map_for(self, topic: str, channel_meta: Mapping[str, Any] | None = None) -> LogMap:
        if not self.timeline:
            return IDENTITY  # a file from before imulog.timeline: keep log time = t_ns
        epoch = int(self.timeline["epoch_ns"])
        dev, ref = self.timeline.get("device_origin_ns"), self.timeline.get("reference_origin_ns")
        if channel_clock(topic, channel_meta, self.step_records, self.imu_names) == "device":
            return LogMap(epoch, int(dev if dev is not None else ref or 0))
        if self.alignment is not None and dev is not None:
            from imulog.process.alignment import device_to_reference, reference_to_device

            origin = int(device_to_reference(np.int64(dev), self.alignment))
            span = 10**12
            scale = float(int(reference_to_device(np.int64(origin + span), self.alignment)) - dev) / span
            return LogMap(epoch, origin, 1.0 if abs(scale - 1.0) < 1e-12 else scale)
        return LogMap(epoch, int(ref if ref is not None else dev or 0))

    def describe(self) -> str:
        """One line for ``imulog info``."""
        if not self.timeline:
            return "log time = sample time (file written before imulog.timeline)"
        if self.timeline.get("clocks") == "shared":
            how = "IMU and reference share one clock and one origin"
        elif self.alignment:
            how = "IMU clock from its first sample; reference channels written after align follow the alignment"
        else:
            how = "not aligned: IMU and reference clocks each from their own first sample"
        return f"starts {self.timeline.get('epoch')} ({self.timeline.get('source')}); {how}"
