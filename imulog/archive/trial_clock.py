"""Which clock an export is on, and the trial's time origin and wall-clock start.

Every export puts all of a trial's channels on one clock:

* ``device``: the device clock of one IMU (``imu=``, or the trial's only / aligned IMU); channels
  recorded on the reference (Vicon) clock are mapped back with ``imulog.alignment``;
* ``reference``: the reference (Vicon) clock; IMU-clock channels are mapped with
  :func:`imulog.process.alignment.device_to_reference` (the mapping the viewer uses).

Which clock a channel was written on follows the viewer's rules (:mod:`imulog.archive.clocks`).
Seconds from start (``t[s]``) count from the trial's first raw sample on the chosen clock; the
wall-clock column ``time`` adds them to ``imulog.trial["start_time"]`` (ISO 8601).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np

from imulog.archive.clocks import STEP_CLOCK_RECORDS, alignments_from_metadata, device_imu_of, imu_name
from imulog.process.alignment import device_to_reference, reference_to_device

CLOCKS = ("device", "reference")


class ClockError(ValueError):
    """The requested clock cannot be applied (no alignment, ambiguous IMU...): one line, names the file."""


def seconds_from(t_ns: np.ndarray, origin_ns: int) -> np.ndarray:
    """Seconds (float64) of int64-ns time stamps after ``origin_ns``."""
    return (np.asarray(t_ns, dtype=np.int64) - np.int64(origin_ns)).astype(np.float64) / 1e9


def parse_start_time(value: Any) -> datetime | None:
    """``imulog.trial["start_time"]`` as a datetime (aware when the string has an offset), else None."""
    if not value or not isinstance(value, str):
        return None
    text = value.strip().replace("Z", "+00:00") if value.strip().endswith("Z") else value.strip()
    try:
        return datetime.fromisoformat(text)
    except ValueError:
        return None


def wall_clock_ns(t_ns: np.ndarray, origin_ns: int, start: datetime) -> np.ndarray:
    """int64 ns since the Unix epoch (UTC for aware starts, local wall time for naive ones) of each sample."""
    base = start.replace(tzinfo=None) if start.tzinfo is None else start.astimezone(UTC).replace(tzinfo=None)
    epoch_ns = (base - datetime(1970, 1, 1)) // timedelta(microseconds=1) * 1000
    return np.asarray(t_ns, dtype=np.int64) - np.int64(origin_ns) + np.int64(epoch_ns)


def tz_name(start: datetime | None) -> str | None:
    """Arrow/pandas time zone of a start time: ``UTC``, ``+HH:MM``, or None (naive local time)."""
    if start is None or start.tzinfo is None:
        return None
    off = start.utcoffset() or timedelta(0)
    if off == timedelta(0):
        return "UTC"
    sign = "+" if off >= timedelta(0) else "-"
    minutes = abs(int(off.total_seconds())) // 60
    return f"{sign}{minutes // 60:02d}:{minutes % 60:02d}"


@dataclass
class TrialClock:
    """Maps any channel of one trial onto the chosen clock (int64 ns) and gives its origin."""

    path: str
    clock: str
    imu: str | None
    alignments: dict[str, dict[str, Any]]
    channel_meta: dict[str, dict[str, str]]
    imu_names: set[str]
    step_records: dict[str, dict[str, Any]]
    start_time: datetime | None = None
    time_zone: str | None = None  # Arrow time zone of ``time``: "UTC", "+HH:MM", or None for naive local time
    time_zone_label: str = ""  # imulog.trial["time_zone"] as recorded
    origin_ns: int = 0
    notes: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)  # IMU -> why its alignment failed (a record without a clock)
    recordings: dict[str, str] = field(default_factory=dict)  # IMU -> its recording (device record), when known
    unaligned: dict[str, list[str]] = field(default_factory=dict)  # IMU -> its topics exported unaligned, as recorded

    def source_imu(self, topic: str) -> str | None:
        """IMU whose device clock ``topic`` was written on (None: the reference clock)."""
        return device_imu_of(topic, self.channel_meta.get(topic), self.imu_names, self.step_records)

    def _note(self, text: str) -> None:
        if text not in self.notes:
            self.notes.append(text)

    def times(self, topic: str, t_ns: np.ndarray) -> np.ndarray:
        """``topic``'s time stamps (int64 ns as stored) on this clock."""
        t = np.asarray(t_ns, dtype=np.int64)
        src = self.source_imu(topic)
        if self.clock == "reference":
            if src is None:
                return t
            alignment = self.alignments.get(src)
            if alignment is None and not any(t.startswith(("/markers/", "/poses/")) for t in self.channel_meta):
                raise ClockError(  # nothing to align on: `process align` would only fail in turn
                    f"{self.path}: --clock reference is an optical system's clock and the trial has none (no "
                    f"/markers/* or /poses/* channel): {topic} has only its device clock; export --clock device"
                )
            if alignment is None and src in self.failed:
                raise ClockError(
                    f"{self.path}: {topic} is on the device clock of IMU {src!r}, which could not be aligned "
                    f"({self.failed[src]}): export --clock device, or align it with its markers or body named"
                )
            if alignment is None:
                raise ClockError(
                    f"{self.path}: {topic} is on the device clock of IMU {src!r} and the trial has no "
                    f"imulog.alignment for it: run `{self._align_command(src)}` first (or export --clock device)"
                )
            self._note_shared(topic, src, alignment)
            return device_to_reference(t, alignment)
        if src == self.imu:
            return t
        if src is not None:
            alignment = self.alignments.get(src)
            if alignment is None:  # said once per IMU by export_notes, with the recording it shares, if any
                self.unaligned.setdefault(src, [])
                if topic not in self.unaligned[src]:
                    self.unaligned[src].append(topic)
                return t
            self._note_shared(topic, src, alignment)
            t = device_to_reference(t, alignment)
        target = self.alignments.get(self.imu or "")
        if target is None:
            self._note(
                f"{topic}: on the reference clock and the trial has no alignment; exported as recorded "
                f"(run `imulog process align {self.path}` to put it on the IMU clock)"
            )
            return t
        return reference_to_device(t, target)

    def export_notes(self) -> list[str]:
        """The notes every exporter reports: the clock's notes, then one line per group of IMUs exported unaligned
        (:func:`not_aligned_note`), grouped by the recording they share with the exported device clock's IMU."""
        same, other = [], []
        target = self.recordings.get(self.imu or "")
        for imu in self.unaligned:
            (same if target is not None and self.recordings.get(imu) == target else other).append(imu)
        out = list(self.notes)
        if same:
            out.append(not_aligned_note(same, self.imu, target))
        if other:
            out.append(not_aligned_note(other, self.imu, None))
        return out

    def _note_shared(self, topic: str, imu: str, alignment: dict[str, Any]) -> None:
        """Say so when IMU ``imu`` is on the reference clock through its recording's clock (no cluster or body of its
        own: :func:`imulog.steps.recording_clock.recording_clock_record`), never silently."""
        if alignment.get("clock_of"):
            self._note(
                f"{topic}: IMU {imu!r} has no alignment of its own; mapped with the clock of its recording "
                f"({', '.join(map(str, alignment['clock_of']))})"
            )

    def _align_command(self, imu: str) -> str:
        """The command that aligns ``imu``: the whole setup on markers; on a rigid body's poses (no markers) one IMU
        at a time, so it names the IMU and the pose channel (BODY when there are several to choose from)."""
        poses = [t.split("/", 2)[2] for t in self.channel_meta if t.startswith("/poses/")]
        if not poses or any(t.startswith("/markers/") for t in self.channel_meta):
            return f"imulog process align {self.path}"
        body = poses[0] if len(poses) == 1 else f"BODY (one of {', '.join(poses)})"
        return f"imulog process align {self.path} --imu {imu} --poses {body}"

    def record(self) -> dict[str, str]:
        """The clock's description, as string metadata for exported files."""
        out = {"clock": self.clock, "origin_ns": str(self.origin_ns)}
        if self.imu:
            out["device_imu"] = self.imu
        shared = {n: a["clock_of"] for n, a in sorted(self.alignments.items()) if a.get("clock_of")}
        if shared:  # IMUs on their recording's clock, not aligned on their own
            out["recording_clock"] = "; ".join(f"{n}: clock of {', '.join(map(str, c))}" for n, c in shared.items())
        if self.start_time is not None:
            out["start_time"] = self.start_time.isoformat()
            out["time_zone"] = self.time_zone_label or self.time_zone or "unknown (device local time)"
        return out


def not_aligned_note(imus: list[str], target: str | None, recording: str | None) -> str:
    """The one wording of every export for IMUs ``imus`` exported on the device clock of IMU ``target`` without an
    alignment (their time stamps as recorded): ``recording`` the recording (device record's ``recording``,
    ``master`` or ``source``) they share with ``target``, so its clock is theirs; None when they do not share one
    or it is not known, so their clocks may differ."""
    names = ", ".join(repr(i) for i in imus)
    what = f"IMU {names} is" if len(imus) == 1 else f"IMUs {names} are"
    if recording is not None:
        return f"{what} not aligned: exported as recorded, on the clock of recording {recording!r}, {target!r}'s too"
    return (
        f"{what} not aligned: exported as recorded, on {'its' if len(imus) == 1 else 'their'} own device clock, "
        f"which may differ from {target!r}'s (no shared recording in the device records)"
    )


def recording_of(device: dict[str, Any] | None) -> str | None:
    """The recording an IMU's device record names (``recording``, else ``master``, else ``source``), or None."""
    device = device or {}
    for key in ("recording", "master", "source"):
        if device.get(key):
            return str(device[key])
    return None


def trial_clock(trial, clock: str = "device", imu: str | None = None) -> TrialClock:
    """The :class:`TrialClock` of an open :class:`~imulog.archive.TrialReader`.

    ``clock``: ``device`` or ``reference``; ``imu``: which IMU's device clock (default: the only IMU,
    else the one ``imulog.alignment`` names, else the first).
    """
    if clock not in CLOCKS:
        raise ClockError(f"{trial.path}: clock must be one of {', '.join(CLOCKS)}, not {clock!r}")
    channels = trial.channels
    metadata = trial.metadata
    imu_names = {c.topic.split("/", 2)[2] for c in channels if c.topic.startswith("/imu/") and c.topic.count("/") == 2}
    alignments = alignments_from_metadata(metadata)
    if imu is not None:
        imu = imu_name(imu)
        if imu not in imu_names:
            raise ClockError(f"{trial.path}: no IMU {imu!r} (IMUs: {', '.join(sorted(imu_names)) or 'none'})")
    elif len(imu_names) == 1:
        imu = next(iter(imu_names))
    elif imu_names:
        aligned = sorted(n for n in alignments if n in imu_names)
        imu = aligned[0] if aligned else sorted(imu_names)[0]
    step_records = {n: metadata[n] for n in set(STEP_CLOCK_RECORDS.values()) if n in metadata}
    trial_rec = metadata.get("imulog.trial", {})
    start = parse_start_time(trial_rec.get("start_time"))
    tc = TrialClock(
        path=str(trial.path),
        clock=clock,
        imu=imu,
        alignments=alignments,
        channel_meta={c.topic: c.metadata for c in channels},
        imu_names=imu_names,
        step_records=step_records,
        start_time=start,
        time_zone=tz_name(start) if start is not None else None,
    )
    tc.time_zone_label = str(trial_rec.get("time_zone") or "")
    tc.failed = {
        n: "; ".join(r.get("quality_reasons") or []) or "failed"
        for n, r in alignments_from_metadata(metadata, failed=True).items()
        if n not in alignments
    }
    starts = []
    for c in channels:
        if c.derived or c.start_ns is None:
            continue
        try:
            starts.append(int(tc.times(c.topic, np.array([c.start_ns], dtype=np.int64))[0]))
        except ClockError:
            continue
    tc.notes.clear()
    tc.unaligned.clear()
    tc.recordings = {n: r for n in imu_names if (r := recording_of(metadata.get(f"imulog.device.{n}"))) is not None}
    tc.origin_ns = min(starts) if starts else 0
    return tc
