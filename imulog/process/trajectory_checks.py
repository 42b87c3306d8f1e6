"""Does a trajectory method apply? Each method's own assumptions, checked on the data it ran on (issue 32).

Dead reckoning is only as good as its velocity resets: without a rest for a minute every method drifts, and a
number in centimetres then hides that it measures nothing. These pure functions check, per method:

* rests (:func:`rest_summary`): how many true rests the windows hold, their spacing and the longest stretch
  without one (ZUPT, Kalman, ZUPT with bias, the optimisation, and the de-drift baseline need them;
  ``ddi`` integrates a whole window from its first rest);
* accelerometer errors (:func:`bias_check`): the rotating-bias estimate of ``zupt_bias`` must be within the
  sensor's physical range (a MEMS accelerometer's zero-g offset is at most ~1 m/s^2, scale and misalignment a
  few per cent) within its own uncertainty (``limit_z`` standard errors of the least-squares fit); an estimate
  significantly outside it is a fit of motion, not of the sensor;
* drift correction (:func:`dedrift_check`): the linear velocity de-drift assumes a constant acceleration
  offset; the offset each movement implies (velocity reached at the next rest / duration) must be small;
* filtering (:func:`removed_share`): high-pass and wavelet remove everything slow, drift and motion alike;
  applied to the ZUPT estimate of windows whose rests control its drift they show what share of the motion's
  range they remove; without such windows the share cannot be known and the check fails for want of rests.

:func:`assess` turns these into one verdict per method with a one-line reason and what would work instead.
Times in s, accelerations in m/s^2, positions in m.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from imulog.param_rules import check_rules

REST_METHODS = ("zupt", "kalman", "zupt_bias", "optimized", "dedrift")
FILTER_METHODS = ("highpass", "wavelet")


@dataclass(frozen=True)
class CheckParams:
    """Limits of the assumptions.

    max_without_rest_s: longest stretch (s) a method may integrate without a velocity reset.
    max_bias_mps2: largest physical accelerometer bias (m/s^2; MEMS zero-g offsets are <= ~0.9 m/s^2).
    max_matrix: largest scale/misalignment element (dimensionless; 0.05 = 5 %).
    limit_z: an estimate is refused only when an element exceeds its physical limit by more than this many of
        its own standard errors (the estimate's uncertainty, not a constant margin, decides; 0: the bare limits).
    max_offset_mps2: largest constant acceleration offset (m/s^2) the de-drift may imply for a movement
        (0.35 m/s^2 is the gravity left by a 2 deg tilt error).
    max_removed_share: largest share of the motion's range a filter may remove.
    min_motion_m: windows whose motion range is below this (m) do not count for the share.
    """

    max_without_rest_s: float = 15.0
    max_bias_mps2: float = 1.0
    max_matrix: float = 0.05
    limit_z: float = 3.0
    max_offset_mps2: float = 0.35
    max_removed_share: float = 0.10
    min_motion_m: float = 0.02
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


DEFAULT_CHECKS = CheckParams()


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.concatenate([[0], np.asarray(mask, bool).astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def rest_summary(t_s: np.ndarray, rests: np.ndarray, windows: Sequence[tuple[int, int]]) -> dict[str, Any]:
    """Rests inside the sample windows ``[start, stop)``: ``count``, ``median_spacing_s`` (between rest
    starts), ``longest_without_s`` (longest stretch between two rests, or from a window's edge to its first or
    last rest; a window without a rest counts whole) and ``longest_window_s``."""
    t = np.asarray(t_s, dtype=np.float64)
    m = np.asarray(rests, dtype=bool)
    count, starts, longest, longest_window = 0, [], 0.0, 0.0
    for a, b in windows:
        if b - a < 2:
            continue
        longest_window = max(longest_window, float(t[b - 1] - t[a]))
        runs = _runs(m[a:b])
        count += len(runs)
        starts += [float(t[a + s]) for s, _ in runs]
        edges = [a] + [x for s, e in runs for x in (a + s, a + e - 1)] + [b - 1]
        gaps = [float(t[edges[i + 1]] - t[edges[i]]) for i in range(0, len(edges) - 1, 2)]
        longest = max([longest, *gaps])
    spacing = float(np.median(np.diff(starts))) if len(starts) > 1 else None
    return {
        "count": int(count),
        "median_spacing_s": None if spacing is None else round(spacing, 3),
        "longest_without_s": round(longest, 3),
        "longest_window_s": round(longest_window, 3),
    }


def _beyond(values: Any, se: Any, z: float) -> float:
    """The largest ``|value| - z * se`` over the elements (the part of each estimate its uncertainty does not
    explain); without standard errors (or a NaN one) the bare ``|value|``."""
    v = np.abs(np.asarray(values, dtype=float)).ravel()
    s = np.zeros_like(v) if se is None else np.nan_to_num(np.asarray(se, dtype=float).ravel(), nan=0.0)
    return float(np.max(v - z * s)) if len(v) == len(s) else float(np.max(v))


def bias_check(errors: Mapping[str, Any] | None, params: CheckParams = DEFAULT_CHECKS) -> dict[str, Any]:
    """Is the rotating-bias estimate (``AccelerometerErrors.as_dict()``) physical? ``ok`` when no element exceeds
    its limit by more than ``limit_z`` of its standard errors (``bias_se_mps2``, ``matrix_se``; absent: the bare
    limits); the largest bias component (m/s^2) and matrix element, and the same after the uncertainty
    (``*_beyond_se``)."""
    if not errors:
        return {"ok": True, "max_bias_mps2": 0.0, "max_matrix": 0.0}
    bias = errors.get("bias_mps2", [0.0])
    matrix = errors.get("matrix", [[0.0]])
    b = float(np.max(np.abs(np.asarray(bias, dtype=float))))
    e = float(np.max(np.abs(np.asarray(matrix, dtype=float))))
    b_se = _beyond(bias, errors.get("bias_se_mps2"), params.limit_z)
    e_se = _beyond(matrix, errors.get("matrix_se"), params.limit_z)
    ok = b_se <= params.max_bias_mps2 and e_se <= params.max_matrix
    return {
        "ok": bool(ok),
        "max_bias_mps2": round(b, 4),
        "max_matrix": round(e, 4),
        "max_bias_beyond_se_mps2": round(b_se, 4),
        "max_matrix_beyond_se": round(e_se, 4),
    }


def movement_closures(t_s: np.ndarray, acc_mps2: np.ndarray, rests: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per movement between two rests: the velocity (K, D) m/s integrated from the last rest sample to the next
    (what ZUPT's linear de-drift removes) and the movement's duration (K,) s."""
    t = np.asarray(t_s, dtype=np.float64)
    a = np.asarray(acc_mps2, dtype=np.float64).reshape(len(t), -1)
    m = np.asarray(rests, dtype=bool)
    vel, dur = [], []
    for s, e in _runs(~m):
        if s == 0 or e >= len(t):
            continue
        i0, i1 = s - 1, e
        seg = a[i0 : i1 + 1]
        vel.append(np.sum(0.5 * (seg[1:] + seg[:-1]) * np.diff(t[i0 : i1 + 1])[:, None], axis=0))
        dur.append(max(float(t[i1] - t[i0]), 1e-9))
    return np.asarray(vel).reshape(len(vel), a.shape[1]), np.asarray(dur)


def dedrift_offsets(t_s: np.ndarray, acc_mps2: np.ndarray, rests: np.ndarray) -> np.ndarray:
    """Per movement between two rests, the constant acceleration offset (m/s^2, 3D norm) that the linear
    de-drift removes: the velocity integrated from the last rest sample to the next, divided by the duration."""
    vel, dur = movement_closures(t_s, acc_mps2, rests)
    return np.linalg.norm(vel, axis=1) / dur if len(dur) else np.zeros(0)


def dedrift_check(offsets_mps2: np.ndarray, params: CheckParams = DEFAULT_CHECKS) -> dict[str, Any]:
    """``ok`` when every movement's implied offset is within ``max_offset_mps2``; the largest and median."""
    o = np.asarray(offsets_mps2, dtype=float)
    o = o[np.isfinite(o)]
    if not len(o):
        return {"ok": True, "movements": 0}
    return {
        "ok": bool(o.max() <= params.max_offset_mps2),
        "movements": len(o),
        "max_offset_mps2": round(float(o.max()), 4),
        "median_offset_mps2": round(float(np.median(o)), 4),
    }


def removed_share(before_m: np.ndarray, after_m: np.ndarray) -> list[float]:
    """Per axis, the share of ``before``'s range (max - min) that the filter removed: range(before - after) /
    range(before) (0: nothing removed, 1: as much as the whole motion). NaN rows ignored."""
    b = np.asarray(before_m, dtype=np.float64).reshape(len(before_m), -1)
    a = np.asarray(after_m, dtype=np.float64).reshape(len(after_m), -1)
    ok = np.all(np.isfinite(b), axis=1) & np.all(np.isfinite(a), axis=1)
    if ok.sum() < 2:
        return [float("nan")] * b.shape[1]
    rng = np.ptp(b[ok], axis=0)
    rem = np.ptp((b - a)[ok], axis=0)
    return [round(float(r / g), 4) if g > 0 else 0.0 for r, g in zip(rem, rng, strict=True)]


def assess(
    method: str,
    *,
    rests: Mapping[str, Any] | None = None,
    bias: Mapping[str, Any] | None = None,
    dedrift: Mapping[str, Any] | None = None,
    share: Sequence[float] | None = None,
    params: CheckParams = DEFAULT_CHECKS,
) -> dict[str, Any]:
    """One method's verdict: ``ok``, ``failed`` (names of the failed checks), ``why`` and ``suggest`` (one
    line each, empty when ok) and the figures the checks used."""
    failed: list[str] = []
    why: list[str] = []
    suggest = ""
    out: dict[str, Any] = {}
    if rests is not None:
        out["rests"] = dict(rests)
        ends_only = method in ("ddi", "dedrift")
        stretch = float(rests["longest_window_s"] if ends_only else rests["longest_without_s"])
        if method in FILTER_METHODS:
            if share is None and (int(rests["count"]) == 0 or stretch > params.max_without_rest_s):
                failed.append("no_rest")
                why.append(
                    f"no rest for {stretch:.0f} s: what the filter removes cannot be told from drift, and it "
                    "removes slow motion with it"
                )
                suggest = "use a reference, or reconstruct between rests"
        elif not ends_only and int(rests["count"]) == 0:
            failed.append("no_rest")
            why.append(f"no rest in {rests['longest_window_s']:.0f} s: dead reckoning drifts")
            suggest = "reconstruct between rests or use a reference"
        elif stretch > params.max_without_rest_s:
            failed.append("no_rest")
            what = "window" if ends_only else "rest"
            why.append(f"no {what} boundary for {stretch:.0f} s: dead reckoning drifts")
            suggest = "reconstruct between rests or use a reference"
    if bias is not None:
        out["bias"] = dict(bias)
        if not bias.get("ok", True):
            failed.append("bias")
            why.append(
                f"accelerometer bias estimate {bias['max_bias_mps2']:.2f} m/s^2 (limit {params.max_bias_mps2:g}) or "
                f"scale {bias['max_matrix']:.3f} (limit {params.max_matrix:g}) is not physical beyond "
                f"{params.limit_z:g} standard errors: not applied"
            )
            suggest = suggest or "zupt (the estimate fits motion, not the sensor); calibrate the accelerometer"
    if dedrift is not None:
        out["dedrift"] = dict(dedrift)
        if not dedrift.get("ok", True):
            failed.append("dedrift")
            why.append(
                f"de-drift implies an acceleration offset of {dedrift['max_offset_mps2']:.2f} m/s^2 "
                f"(> {params.max_offset_mps2:g}): the rests are not rests or the orientation is off"
            )
            # rests that are no rests matter before a bias estimate (whose fallback, zupt, needs the rests)
            suggest = suggest if "no_rest" in failed else "check the rests (imulog process phases) and the orientation"
    if share is not None:
        out["removed_share"] = list(share)
        worst = max((s for s in share if np.isfinite(s)), default=0.0)
        if worst > params.max_removed_share:
            failed.append("removes_motion")
            why.append(
                f"removes {100 * worst:.0f} % of the motion's range (limit {100 * params.max_removed_share:g} %)"
            )
            suggest = suggest or "zupt between rests; filters only suit motion far above their cut-off"
    out.update(ok=not failed, failed=failed, why="; ".join(why), suggest=suggest)
    return out


def format_check(method: str, check: Mapping[str, Any]) -> str:
    """The one line ``process trajectory`` prints for a failed check (empty when ok)."""
    if check.get("ok", True):
        return ""
    tail = f"; {check['suggest']}" if check.get("suggest") else ""
    return f"{method}: {check['why']}{tail}"


def check_attrs(check: Mapping[str, Any]) -> dict[str, str]:
    """Channel metadata of a trajectory: ``assumptions`` (``ok`` or ``failed``) and, when failed,
    ``assumptions_failed`` (comma-separated check names) and ``assumptions_why`` (the one line)."""
    if not check:
        return {}
    if check.get("ok", True):
        return {"assumptions": "ok"}
    return {
        "assumptions": "failed",
        "assumptions_failed": ",".join(check.get("failed", [])),
        "assumptions_why": format_check("", check).lstrip(": "),
    }
