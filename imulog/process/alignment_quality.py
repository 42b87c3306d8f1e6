"""The quality grade of an IMU-to-reference alignment, from its residuals and their uncertainty (issue 32).

An alignment is *poor* when the evidence says its lag is wrong or uncertain beyond ``poor_spread_s`` (3 ms):

* the correlation score is low, or the markers do not reproduce the gyroscope (vector match), or a single
  marker was used (its acceleration is a weaker signal than a rigid cluster's rotation);
* the windows disagree: their residual lag spread (with 3 or more windows), or the difference between two
  windows' lags, exceeds ``poor_spread_s``;
* the lag's uncertainty at the trial's ends exceeds it: the offset's standard error combined with the drift's
  effect over half the trial, ``drift x duration / 2``, where an unmeasured drift (fewer than 3 windows)
  counts as ``assumed_drift_ppm`` (a crystal clock's tolerance, 50 ppm).

The number of windows is not itself a reason: a 66 s trial has two windows, and at 50 ppm an unmeasured
drift moves its ends by 1.7 ms, within the tolerance; it is noted (``notes``), not graded poor. A 10-minute
trial with one usable window is poor (15 ms at its ends).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

NS = 1_000_000_000
ASSUMED_DRIFT_PPM = 50.0


def _duration_s(record: Mapping[str, Any]) -> float:
    """Span (s) of the windows the alignment looked at (start of the first to the end of the last, by
    ``width_s`` or the windows' spacing), or the record's ``duration_s`` when it has one."""
    if record.get("duration_s"):
        return float(record["duration_s"])
    windows = [w for w in record.get("windows") or [] if "start_s" in w]
    if not windows:
        return 0.0
    starts = [float(w["start_s"]) for w in windows]
    width = float(windows[-1].get("width_s") or ((starts[1] - starts[0]) if len(starts) > 1 else 30.0))
    return max(starts) + width - min(starts)


def grade(
    record: Mapping[str, Any],
    *,
    poor_score: float,
    poor_spread_s: float,
    poor_vector_match: float,
    assumed_drift_ppm: float = ASSUMED_DRIFT_PPM,
) -> tuple[str, list[str], list[str]]:
    """``("good" | "poor", reasons, notes)`` of an ``imulog.alignment`` record (reasons: why poor; notes:
    caveats that do not make it poor)."""
    reasons: list[str] = []
    notes: list[str] = []
    score = float(record.get("score") or 0.0)
    if score < poor_score:
        reasons.append(f"low correlation score {score:.2f} (< {poor_score:g})")
    vm = (record.get("cluster") or {}).get("vector_match")
    if vm is not None and vm < poor_vector_match:
        reasons.append(f"the markers reproduce the gyroscope poorly (vector match {vm:.2f} < {poor_vector_match:g})")
    if record.get("signal") == "marker-acceleration":
        reasons.append("single marker: aligned on its acceleration, less certain than a rigid cluster")
    limit_ns = poor_spread_s * NS
    spread = record.get("residual_spread_ns")
    if spread is not None and spread > limit_ns:
        reasons.append(f"residual lag spread {spread / 1e6:.1f} ms over the windows (> {poor_spread_s * 1e3:g} ms)")
    used = [w for w in record.get("windows") or [] if w.get("used") and "offset_ns" in w]
    if len(used) == 2 and not record.get("drift_estimated"):
        d = abs(int(used[1]["offset_ns"]) - int(used[0]["offset_ns"]))
        if d > limit_ns:
            reasons.append(f"the two windows' lags differ by {d / 1e6:.1f} ms (> {poor_spread_s * 1e3:g} ms)")
    if not used:
        reasons.append("no usable window: only the coarse lag over the whole recording")
    half = 0.5 * _duration_s(record)
    if record.get("drift_estimated") and record.get("drift_uncertainty_ppm") is not None:
        drift_ns = float(record["drift_uncertainty_ppm"]) * 1e-6 * half * NS
    else:
        drift_ns = assumed_drift_ppm * 1e-6 * half * NS
        if used:
            notes.append(
                f"drift not estimated ({len(used)} usable window(s)); at {assumed_drift_ppm:g} ppm it moves the "
                f"trial's ends by up to {drift_ns / 1e6:.1f} ms"
            )
    se_ns = float(record.get("offset_uncertainty_ns") or 0.0)
    total_ns = (se_ns**2 + drift_ns**2) ** 0.5
    if used and total_ns > limit_ns:
        reasons.append(
            f"lag uncertainty {total_ns / 1e6:.1f} ms at the trial's ends (> {poor_spread_s * 1e3:g} ms)"
            + ("" if record.get("drift_estimated") else ": drift not estimated in so few windows")
        )
    return ("poor" if reasons else "good"), reasons, notes
