"""The ``imulog.timing`` record of the phases step, built from the phases and per-core counts (no samples).

Per phase rows (start, end, duration, peak angular velocity, ``forced``, the repetition's ``confidence``) up to
:data:`MAX_ROWS` phases, and at any length the summaries: phase durations (median, deciles, histogram), per hour
(and per day beyond a day) the phases, the time moving and the static percentage, the threshold, the boundary
filters' cut-offs and how many merges and splits DynAMoS made.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from imulog.process.repetition_flags import flagged_repetitions
from imulog.process.segmentation.reduce import duration_summary, period_rows

LOW_CONFIDENCE = 0.5  # repetitions below this confidence are listed in imulog.timing["low_confidence_repetitions"]
MAX_ROWS = 10_000  # phases with a row of their own in the record; beyond, the summaries (and the phases channel)


class PeriodCounts:
    """Recorded and static sample counts per hour and per day, on the wall clock when the start time is known."""

    def __init__(self, first_ns: int, start_time: str | None) -> None:
        from imulog.process.metrics.periods import DAY_S, HOUR_S, wall_clock_origin_ns

        self.first_ns = first_ns
        self.periods = {"by_hour": HOUR_S, "by_day": DAY_S}
        self.origins = {k: wall_clock_origin_ns(first_ns, start_time, s) for k, s in self.periods.items()}
        self.sums: dict[str, dict[str, np.ndarray]] = {k: {} for k in self.periods}

    def add(self, t_ns: np.ndarray, known: np.ndarray, static: np.ndarray) -> None:
        """Count the samples at ``t_ns`` (device clock): recorded (``known``) and static among them."""
        for key, period_s in self.periods.items():
            k = ((t_ns - self.origins[key][0]) // int(round(period_s * 1e9))).astype(np.int64)
            for name, w in (("known", known), ("static", static)):
                c = np.bincount(k, weights=w.astype(float))
                old = self.sums[key].get(name, np.zeros(0))
                if len(c) > len(old):
                    old = np.concatenate([old, np.zeros(len(c) - len(old))])
                old[: len(c)] += c
                self.sums[key][name] = old


def phase_rows(phases: Any, t_start: np.ndarray, t_end: np.ndarray, t_first: int, peaks: np.ndarray) -> list[dict]:
    """The rows of :func:`imulog.process.segmentation.pipeline.timing_table` from the phases' times (ns, the
    record's clock; end = time of the last sample) and their peak gyroscope norms (rad/s)."""
    forced = phases.forced if phases.forced is not None else np.zeros(len(phases), dtype=bool)
    confidence = {q["repetition"]: q["confidence"] for q in phases.quality}
    rows = []
    for i, (r, label) in enumerate(zip(phases.repetition, phases.labels, strict=True)):
        s, e = int(t_start[i]), int(t_end[i])
        rows.append(
            {
                "repetition": int(r),
                "label": label,
                "start_ns": s,
                "end_ns": e,
                "start_s": round(float(s - t_first) * 1e-9, 4),
                "end_s": round(float(e - t_first) * 1e-9, 4),
                "duration_s": round(float(e - s) * 1e-9, 4),
                "peak_angular_velocity_rad_s": round(float(peaks[i]), 4),
                "forced": bool(forced[i]) if i < len(forced) else False,
                "confidence": confidence.get(int(r), 1.0),
            }
        )
    return rows


def phase_record(
    phases: Any,
    *,
    imu: str,
    params: Any,
    rate_hz: float,
    aligned: bool,
    n_movements: int,
    static_fraction: float,
    t_start: np.ndarray,
    t_end: np.ndarray,
    t_first: int,
    peaks: np.ndarray,
    t_start_device: np.ndarray,
    counts: PeriodCounts,
    span_s: float,
    threshold: float | None,
    post: dict[str, int],
    cutoffs: tuple[float, float | None],
    windows: Any = None,
) -> dict[str, Any]:
    """``imulog.timing`` (see the module docstring); ``windows``: the window sizes when more than one was read."""
    ph = phases
    quality = list(ph.quality)
    durations = (np.asarray(t_end, np.int64) - np.asarray(t_start, np.int64)) * 1e-9
    record: dict[str, Any] = {
        "imu": f"/imu/{imu}",
        "method": params.method,
        "protocol": params.protocol,
        "clock": "reference" if aligned else "device",
        "rate_hz": round(rate_hz, 4),
        "n_movements": int(n_movements),
        "n_repetitions": int(ph.repetition.max()) if len(ph) else 0,
        "n_phases": int(len(ph)),
        "n_corrected_repetitions": int(ph.n_corrected),
        "n_forced_phases": int(np.sum(ph.forced)) if ph.forced is not None else 0,
        "mean_confidence": round(float(np.mean([q["confidence"] for q in quality])), 3) if quality else None,
        "low_confidence_repetitions": [q["repetition"] for q in quality if q["confidence"] < LOW_CONFIDENCE],
        "repetition_quality": quality,
        # what event correction says alone (split, missing, merged, low confidence); the trajectory step adds drift
        "flagged_repetitions": flagged_repetitions({int(q["repetition"]): q for q in quality}),
        "static_fraction": round(float(static_fraction), 4),
        "phase_durations": duration_summary(durations),
        "threshold_rad_s": None if threshold is None else round(float(threshold), 6),
        "postprocess_changes": int(post.get("changes", 0)),
        "cutoff_hz": {
            "gyroscope": round(float(cutoffs[0]), 4),
            "accelerometer": None if cutoffs[1] is None else round(float(cutoffs[1]), 4),
        },
    }
    if len(ph) <= MAX_ROWS:
        record["phases"] = phase_rows(ph, t_start, t_end, t_first, peaks)
    if windows is not None:
        record["computed"] = f"window by window ({windows.core_s:g} s cores, bounded memory)" + (
            "" if len(ph) <= MAX_ROWS else f"; no per-phase rows beyond {MAX_ROWS:,} phases"
        )
    for key, period_s in counts.periods.items():
        if key == "by_day" and span_s <= period_s:  # per hour always; per day beyond a day
            continue
        origin_ns, origin_time = counts.origins[key]
        known = counts.sums[key].get("known", np.zeros(0))
        static = counts.sums[key].get("static", np.zeros(0))
        record[key] = period_rows(
            t_start_device, durations, known, static, origin_ns, origin_time, period_s, rate_hz, counts.first_ns
        )
    return record
