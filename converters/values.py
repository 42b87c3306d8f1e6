"""The one check of the values every reader stores (issue 26), run on each converted recording (pure numpy).

``imulog.converters.convert_file`` (and the piece-by-piece ``imulog convert`` of large files) call
:func:`check_recording` once on what a converter returns, so every reader, built-in or a lab's own, gets it:

* non-finite (``inf``) or absurd values become gaps (NaN) with one warning per channel counting them: beyond twice
  the sensor's declared range (``acc_range_g``/``accel_range_g``, ``gyr_range_dps``/``gyro_range_dps`` in the
  stream's meta) or, without one, beyond :data:`LIMITS` (1e6 g, 1e6 deg/s, 1 T, 1e4 degC, 1e6 m, 1e30 for
  other columns). NaN is already a gap and is not counted. A channel whose every value this check removed is
  unusable: ConversionError naming it. An IMU without any sample is an error too.
* quaternions (``qw,qx,qy,qz`` columns, pose orientations): normalised when their norm is within
  :data:`QUAT_TOLERANCE` of 1 (kept as written within :data:`QUAT_AS_WRITTEN`, the printing precision of
  exports), gaps (counted) beyond it; an error when none is left.
* a declared rate (``rate_hz`` in the stream's meta) that differs from the time stamps' median rate by more than
  1 %: reported, and the time stamps' rate replaces it (the declared one is kept as ``declared_rate_hz``).
* marker labels and column names longer than :data:`MAX_LABEL_CHARS` are cut (their start and a hash of the
  whole); a topic longer than :data:`MAX_TOPIC_CHARS` (readers sanitise names to 64) is an error.
* the recording's start (``imulog.trial`` ``start_time``) outside 1970-2100, or time stamps that do not increase
  (the model's rule; a rate of 1e-300 Hz gave every sample the same time): ConversionError.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording
from imulog.numeric import step_rate_hz

G0 = 9.80665
LIMITS = {
    "acc": 1e6 * G0,  # m/s^2
    "gyr": math.radians(1e6),  # rad/s
    "mag": 1e6,  # uT (1 T)
    "temperature": 1e4,  # degC
    "position": 1e6,  # m
    "other": 1e30,  # any other column (counts, volts, ...): only literal overflow values
}
RANGE_MARGIN = 2.0  # values beyond twice the declared range cannot come from the sensor
QUAT_TOLERANCE = 1e-3
QUAT_AS_WRITTEN = 1e-6  # within this of unit norm a quaternion is stored exactly as the file has it
RATE_TOLERANCE = 0.01
MAX_RATE_SAMPLES = 50_000
BLOCK_ROWS = 1 << 18  # rows checked at a time
MAX_LABEL_CHARS = 64  # marker labels and column names taken from files (a 300k-character label costs GBs)
MAX_TOPIC_CHARS = 200  # readers build topics from sanitize_name (64 characters); longer is a reader's bug


def cap_label(text: str) -> str:
    """``text`` when at most :data:`MAX_LABEL_CHARS` characters, else its start and a short hash of the whole."""
    if len(text) <= MAX_LABEL_CHARS:
        return text
    return f"{text[: MAX_LABEL_CHARS - 9]}~{hashlib.sha1(text.encode('utf-8', 'replace')).hexdigest()[:8]}"


def _names(rec: Recording, path: Any) -> None:
    """Topics of sane length; marker labels and column names capped (same start, a hash of the whole)."""
    for stream in rec.streams():
        if len(stream.topic) > MAX_TOPIC_CHARS:
            raise ConversionError(
                path, f"topic {stream.topic[:60]}... ({len(stream.topic)} characters): a name in the file is too long"
            )
    for m in rec.markers:
        if any(len(x) > MAX_LABEL_CHARS for x in m.labels):
            m.labels = [cap_label(x) for x in m.labels]
    for sig in rec.signals:
        if any(len(x) > MAX_LABEL_CHARS for x in sig.columns):
            sig.columns = [cap_label(x) for x in sig.columns]
    for a in rec.analogs:
        if any(len(x) > MAX_LABEL_CHARS for x in a.channel_names):
            a.channel_names = [cap_label(x) for x in a.channel_names]


@dataclass
class ValueReport:
    """What the check changed, accumulated over the pieces of one recording (keys: ``topic`` or ``topic column``)."""

    gaps: dict[str, int] = field(default_factory=dict)  # values made gaps (out of range or non-finite)
    quats: dict[str, int] = field(default_factory=dict)  # quaternion samples refused (norm off by > tolerance)
    kept: dict[str, int] = field(default_factory=dict)  # finite values left per checked channel
    rates: dict[str, str] = field(default_factory=dict)  # topic -> the rate warning
    samples: dict[str, int] = field(default_factory=dict)  # IMU topic -> samples seen
    last_t: dict[str, int] = field(default_factory=dict)  # topic -> last time stamp (ns) of the pieces so far

    def warnings(self) -> list[str]:
        out = [
            f"{key}: {n} value(s) not finite or beyond the sensor's range stored as gaps (NaN)"
            for key, n in self.gaps.items()
            if n
        ]
        out += [
            f"{key}: {n} quaternion sample(s) whose norm is not 1 (off by more than {QUAT_TOLERANCE:g}) stored as "
            "gaps (NaN)"
            for key, n in self.quats.items()
            if n
        ]
        return out + list(self.rates.values())

    def unusable(self) -> list[str]:
        """Channels the check emptied: it removed values and none is left."""
        removed = {k for k, n in self.gaps.items() if n} | {k for k, n in self.quats.items() if n}
        return [k for k in sorted(removed) if self.kept.get(k, 0) == 0]


def _declared(meta: dict[str, Any], *keys: str) -> float | None:
    for k in keys:
        v = meta.get(k)
        try:
            f = float(v)
        except (TypeError, ValueError):
            continue
        if f > 0 and math.isfinite(f):
            return f
    return None


def _writable(a: np.ndarray) -> np.ndarray:
    return a if a.flags.writeable else a.copy()


def _mask(a: np.ndarray | None, limit: float, key: str, report: ValueReport) -> np.ndarray | None:
    """``a`` with non-finite (not NaN) and ``|x| > limit`` values set to NaN; counts into ``report``."""
    if a is None or a.size == 0:
        return a
    n = kept = 0
    for lo in range(0, len(a), BLOCK_ROWS):  # in blocks: the temporaries stay small whatever the recording
        block = a[lo : lo + BLOCK_ROWS]
        with np.errstate(invalid="ignore"):
            bad = np.abs(block) > limit  # inf included; NaN compares False
        m = int(np.count_nonzero(bad))
        if m:
            if not a.flags.writeable:
                a = a.copy()
                block = a[lo : lo + BLOCK_ROWS]
            block[bad] = np.nan
            n += m
        kept += int(np.count_nonzero(np.isfinite(block)))
    report.gaps[key] = report.gaps.get(key, 0) + n
    report.kept[key] = report.kept.get(key, 0) + kept
    return a


def _quaternions(q: np.ndarray, key: str, report: ValueReport) -> np.ndarray:
    """Unit quaternions: normalised within the tolerance, NaN rows beyond it (counted)."""
    if q.size == 0:
        return q
    with np.errstate(invalid="ignore", over="ignore"):
        norm = np.sqrt(np.einsum("ij,ij->i", q, q))
        finite = np.isfinite(norm)
        near = finite & (np.abs(norm - 1.0) <= QUAT_TOLERANCE)
        refused = ~near & ~np.isnan(q).any(axis=1)  # NaN rows are gaps already; any other row off unit norm
    off = near & (np.abs(norm - 1.0) > QUAT_AS_WRITTEN)  # printed precision (7 digits) is kept as written
    if off.any() or refused.any():
        q = _writable(q)
        q[off] = q[off] / norm[off, None]
        q[refused] = np.nan
    report.quats[key] = report.quats.get(key, 0) + int(np.count_nonzero(refused))
    report.kept[key] = report.kept.get(key, 0) + int(np.count_nonzero(near))
    return q


def _median_rate(t_ns: np.ndarray) -> float | None:
    if len(t_ns) < 3:
        return None
    step = max(1, (len(t_ns) - 1) // MAX_RATE_SAMPLES)
    return step_rate_hz(t_ns[1:][::step] - t_ns[:-1][::step])


def _rate(stream: Any, rec: Recording, report: ValueReport) -> None:
    """A declared ``rate_hz`` off the time stamps' rate (:func:`imulog.numeric.step_rate_hz`) by more than 1 %: the time stamps win, reported."""
    meta = getattr(stream, "meta", None)
    if not isinstance(meta, dict) or stream.topic in report.rates:
        return
    declared = _declared(meta, "rate_hz")
    payload = _median_rate(stream.t_ns) if declared else None
    if declared is None or payload is None or abs(payload - declared) <= RATE_TOLERANCE * payload:
        return
    report.rates[stream.topic] = (
        f"{stream.topic}: declared rate {declared:g} Hz differs from the time stamps' {payload:.6g} Hz by more than "
        f"{RATE_TOLERANCE:.0%}; the time stamps' rate is used"
    )
    meta["declared_rate_hz"], meta["rate_hz"] = declared, round(payload, 6)
    device = rec.metadata.get(f"imulog.device.{getattr(stream, 'name', '')}")
    if isinstance(device, dict) and device.get("rate_hz") == declared:
        device["declared_rate_hz"], device["rate_hz"] = declared, round(payload, 6)


def _times(stream: Any, report: ValueReport, path: Any) -> None:
    """Time stamps strictly increasing (the model's rule), across the pieces of a recording too."""
    t = stream.t_ns
    if len(t) == 0:
        return
    last = report.last_t.get(stream.topic)
    if last is not None and t[0] <= last:
        raise ConversionError(path, f"{stream.topic}: time stamps go back between two pieces of the file")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if len(bad):
        raise ConversionError(
            path,
            f"{stream.topic}: time stamps do not increase at sample {int(bad[0]) + 1} (a damaged time column, "
            "rate or start time)",
        )
    report.last_t[stream.topic] = int(t[-1])


def _intervals(ev: Any, path: Any) -> None:
    """Event times that are numbers (a NaN or inf cast to int64 becomes its smallest value) and end >= start."""
    start, end = np.asarray(ev.start_ns), np.asarray(ev.end_ns)
    if start.size == 0:
        return
    sentinel = np.iinfo(np.int64).min
    bad = (start == sentinel) | (end == sentinel) | (end < start)
    if bad.any():
        i = int(np.argmax(bad))
        raise ConversionError(
            path, f"{ev.topic}: event {i} has no valid time (empty, non-finite or ending before it starts)"
        )


def _imu(s: ImuStream, report: ValueReport) -> None:
    acc_g = _declared(s.meta, "acc_range_g", "accel_range_g")
    gyr_dps = _declared(s.meta, "gyr_range_dps", "gyro_range_dps")
    acc_limit = RANGE_MARGIN * acc_g * G0 if acc_g else LIMITS["acc"]
    gyr_limit = math.radians(RANGE_MARGIN * gyr_dps) if gyr_dps else LIMITS["gyr"]
    s.acc = _mask(s.acc, acc_limit, f"{s.topic} acc", report)
    s.gyr = _mask(s.gyr, gyr_limit, f"{s.topic} gyr", report)
    s.mag = _mask(s.mag, LIMITS["mag"], f"{s.topic} mag", report)
    s.temperature = _mask(s.temperature, LIMITS["temperature"], f"{s.topic} temperature", report)


def _columns(values: np.ndarray, names: list[str], topic: str, report: ValueReport) -> np.ndarray:
    quat = [i for i, c in enumerate(names) if c in ("qw", "qx", "qy", "qz")]
    if len(quat) == 4 and [names[i] for i in quat] == ["qw", "qx", "qy", "qz"]:
        values = _writable(values)
        values[:, quat] = _quaternions(np.ascontiguousarray(values[:, quat]), f"{topic} orientation", report)
    for i, c in enumerate(names):
        if i in quat and len(quat) == 4:
            continue
        col = _mask(np.ascontiguousarray(values[:, i]), LIMITS["other"], f"{topic} {c}", report)
        if col is not values[:, i]:
            values = _writable(values)
            values[:, i] = col
    return values


def check_start(rec: Recording, path: Any = None) -> None:
    """``imulog.trial`` ``start_time`` in 1970-2100, else ConversionError naming its source."""
    trial = rec.metadata.get("imulog.trial", {})
    text = trial.get("start_time") if isinstance(trial, dict) else None
    if not isinstance(text, str):
        return
    try:
        year = datetime.fromisoformat(text.replace("Z", "+00:00")).year
    except ValueError:
        return
    if not 1970 <= year < 2100:
        source = trial.get("start_time_source", "the file's start time")
        raise ConversionError(path, f"start time {text} ({source}) is outside 1970-2100: the file's clock is damaged")


def check_recording(
    rec: Recording, path: Any = None, *, report: ValueReport | None = None, final: bool = True
) -> ValueReport:
    """Apply the checks to ``rec`` in place; its warnings gain one line per channel changed.

    ``report`` accumulates over the pieces of one recording; ``final`` False (a piece) leaves the warnings and the
    unusable-channel errors to the call with ``final`` True."""
    report = report if report is not None else ValueReport()
    check_start(rec, path)
    _names(rec, path)
    for stream in rec.streams():
        if getattr(stream, "t_ns", None) is not None:
            _times(stream, report, path)
    for ev in rec.events:
        _intervals(ev, path)
    for s in rec.imus:
        report.samples[s.topic] = report.samples.get(s.topic, 0) + len(s)
        _imu(s, report)
        _rate(s, rec, report)
    for m in rec.markers:
        pos = _mask(m.pos, LIMITS["position"], f"{m.topic} position", report)
        if pos is not m.pos:
            m.pos = pos
            m.valid = m.valid & np.isfinite(pos).all(axis=2)
        _rate(m, rec, report)
    for p in rec.poses:
        p.position = _mask(p.position, LIMITS["position"], f"{p.topic} position", report)
        if p.orientation is not None:
            p.orientation = _quaternions(p.orientation, f"{p.topic} orientation", report)
        _rate(p, rec, report)
    for a in rec.analogs:
        a.values = _columns(a.values, a.channel_names, a.topic, report)
        _rate(a, rec, report)
    for sig in rec.signals:
        sig.values = _columns(sig.values, sig.columns, sig.topic, report)
        _rate(sig, rec, report)
    if final:
        finish(rec, report, path)
    return report


def finish(rec: Recording, report: ValueReport, path: Any = None) -> None:
    """The end of a recording: ConversionError for an unusable channel, else the warnings added to ``rec``."""
    none = [t for t, n in report.samples.items() if n == 0]
    if none:
        raise ConversionError(path, f"{none[0]}: no samples (the file holds no usable time stamps for this sensor)")
    empty = report.unusable()
    if empty:
        more = f" (and {len(empty) - 1} more)" if len(empty) > 1 else ""
        raise ConversionError(
            path,
            f"{empty[0]}{more}: every value is non-finite, beyond the sensor's range or (quaternions) not of unit "
            "norm: the channel is unusable; check the export settings or the file",
        )
    rec.warnings.extend(w for w in report.warnings() if w not in rec.warnings)
