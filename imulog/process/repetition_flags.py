"""Which repetitions of a drinking trial to distrust, and why (issue 31, point 3).

The phases step's confidence (:func:`imulog.process.segmentation.repetitions.repetition_quality`) ranks what
event correction did to a repetition; on the accuracy grid most repetitions with a large error need no
correction at all: their trajectory drifts. The trajectory step sees that drift, so the flag combines both:
per repetition, the phases step's counts and a few figures of the dead reckoning itself (all without optical
data):

- ``drift_mps``: the speed (m/s) plain integration of the gravity-free acceleration reaches at the end of the
  repetition's window, which starts and ends at rest: what ZUPT has to remove;
- ``reference_cm``: the optimisation's initial estimate (``zupt_bias`` turned by the trial's heading drift, or ZUPT
  without an orientation) against the minimum-jerk reference at the rests after the first phase starts: RMS per
  axis, the worst axis (cm). It does not depend on how far the optimisation trusts the estimate
  (``OptimizationParams.closure_factor``), so the ``drift`` reason keeps its meaning whatever the trust rule;
- ``zupt_bias_optimized_cm`` (``zupt_optimized_cm`` without an orientation): RMS distance (cm) between the
  initial estimate and the optimised result: how far the optimisation pulled it (the ``drift`` feature until
  2026-12-07; kept in the records, not a reason by default);
- ``rest_before_s`` / ``rest_after_s``: the rest (s) at each end of the window that the velocity is reset on;
- with ``candidates`` only (``benchmarks/confidence_calibration.py`` asks; the trajectory step does not): the
  candidates measured for the ``drift`` reason with ``RotatingBiasParams.outlier_factor = 4`` and not used by any
  reason (docs/accuracy.md, "a drift feature for the robust bias fit"): ``start_zupt_cm`` (the start against plain
  ZUPT at the same rests, both turned, worst axis), ``zupt_reference_cm`` (ZUPT against the reference there),
  ``anchored_reference_cm`` (``reference_cm`` on the reference coordinates the start does not enter) and
  ``closure_mps`` (the largest velocity the repetition's movements leave at their next rest after the
  rotating-bias compensation: the fit's own residual there; in ``trajectory_info`` when
  :func:`imulog.process.trajectory_opt.reconstruct_repetitions` ran with ``drift_candidates``).

:func:`flag_repetition` turns them into reasons (``merged``, ``split``, ``missing``, ``drift``, ``weak rest``);
thresholds are :class:`FlagParams`, calibrated on the grid by ``benchmarks/confidence_calibration.py``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np


@dataclass(frozen=True)
class FlagParams:
    """Thresholds of :func:`flag_repetition` (units in the names)."""

    min_confidence: float = 0.7  # the phases step's confidence (0..1)
    # the initial estimate's RMS distance to the reference at rests, worst axis (cm; None: off): the largest value
    # in 0.25-cm steps that keeps recall >= 0.8 on the calibration set (docs/accuracy.md), about twice the
    # reference's own uncertainty there (OptimizationParams.sigma_ref_static_m = 1.5 cm)
    max_reference_cm: float | None = 3.25
    max_pull_cm: float | None = None  # the pull (initial estimate to optimised, RMS cm): the rule until 2026-12-07
    min_rest_s: float = 0.1  # the shorter of the two rests around the repetition (s)


def repetition_features(
    t_s: np.ndarray,
    acc_mps2: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Any],
    trajectories_m: Mapping[str, np.ndarray],
    quality: Sequence[Mapping[str, Any]] = (),
    trajectory_info: Mapping[str, Any] | None = None,
    candidates: bool = False,
) -> dict[int, dict[str, Any]]:
    """Per repetition (by its ``index``): the phases step's counts and the dead-reckoning figures above.

    t_s (N,) s; acc_mps2 (N, 3) gravity-free, world frame; static_mask (N,) true rests; repetitions: objects
    with ``index``, ``start``, ``stop`` (sample slice) and, for ``reference_cm``, ``phase_bounds_s`` (4, 2) s;
    trajectories_m: {method: (N, 3) m} with ``zupt`` and, when computed, ``zupt_bias`` and ``optimized``;
    quality: the phases step's per-repetition records (``repetition`` 1-based); trajectory_info: the ``info``
    :func:`imulog.process.trajectory_opt.reconstruct_repetitions` filled (``waypoints_m``, ``heading_drift_deg``
    per repetition in list order), needed for ``reference_cm``; candidates: also the unused ``drift`` candidates
    (above; no reason reads them, so the flags are the same without them).
    """
    import numpy as np  # lazily: `imulog info` reads flag_line without numpy

    t = np.asarray(t_s, dtype=np.float64)
    acc = np.asarray(acc_mps2, dtype=np.float64)
    static = np.asarray(static_mask, dtype=bool)
    by_rep = {int(q["repetition"]): q for q in quality}
    reference = _reference_distances(t, static, repetitions, trajectories_m, trajectory_info or {}, candidates)
    out: dict[int, dict[str, Any]] = {}
    for i, rep in enumerate(repetitions):
        sl = slice(rep.start, rep.stop)
        tt, a, st = t[sl], acc[sl], static[sl]
        if len(tt) < 3:
            continue
        dt = np.diff(tt)
        v_end = np.sum(0.5 * (a[1:] + a[:-1]) * dt[:, None], axis=0)
        f: dict[str, Any] = {
            "duration_s": float(tt[-1] - tt[0]),
            "drift_mps": float(np.linalg.norm(v_end)),
            "rest_before_s": _edge_run_s(tt, st),
            "rest_after_s": _edge_run_s(tt[::-1], st[::-1]),
        }
        o = trajectories_m.get("optimized")
        for name in ("zupt", "zupt_bias"):
            z = trajectories_m.get(name)
            if z is not None and o is not None:
                f[f"{name}_optimized_cm"] = _rms_distance_cm(o[sl], z[sl])
        f.update(reference.get(i, {}))
        closure = (trajectory_info or {}).get("closure_mps") or () if candidates else ()
        if i < len(closure) and closure[i] is not None:
            f["closure_mps"] = closure[i]
        q = by_rep.get(int(rep.index), {})
        for key in ("merged", "dropped", "split", "missing", "forced", "confidence"):
            if key in q:
                f[key] = q[key]
        out[int(rep.index)] = f
    return out


def _reference_distances(
    t: np.ndarray,
    static: np.ndarray,
    repetitions: Sequence[Any],
    trajectories_m: Mapping[str, np.ndarray],
    info: Mapping[str, Any],
    candidates: bool = False,
) -> dict[int, dict[str, float]]:
    """Per repetition (list position): ``reference_cm``, the initial estimate's RMS distance (cm, worst axis) to
    the minimum-jerk reference at the static samples after the first phase starts (the samples the
    optimisation's ``sigma_ref_static_m`` term holds; before the first phase both are 0 by construction); with
    ``candidates`` also ``start_zupt_cm``, ``zupt_reference_cm`` and ``anchored_reference_cm``."""
    import numpy as np

    from imulog.process.minjerk import R2GWaypoints
    from imulog.process.trajectory_repetitions import reference_residuals

    initial = trajectories_m.get("zupt_bias", trajectories_m.get("zupt"))
    wp = info.get("waypoints_m")
    if initial is None or not wp:
        return {}
    turned = {"start": _turned(initial, repetitions, info)}
    if candidates and "zupt_bias" in trajectories_m and "zupt" in trajectories_m:
        turned["zupt"] = _turned(trajectories_m["zupt"], repetitions, info)
    complete = [r for r in repetitions if len(getattr(r, "phase_bounds_s", ())) == 4]
    waypoints = R2GWaypoints(tuple(wp["bottle"]), tuple(wp["mouth"]))
    res = {k: reference_residuals(t, v, static, complete, waypoints) for k, v in turned.items()}
    position = {id(r): i for i, r in enumerate(repetitions)}
    out: dict[int, dict[str, float]] = {}
    for j, d in res["start"].items():
        ok = np.all(np.isfinite(d), axis=1)
        if not ok.any():
            continue
        f = {"reference_cm": _worst_axis_cm(d[ok])}
        if "zupt" in res and j in res["zupt"]:
            dz = res["zupt"][j]
            both = ok & np.all(np.isfinite(dz), axis=1)
            if both.any():  # the two estimates at the same rests: their disagreement, and ZUPT's own distance
                f["start_zupt_cm"] = _worst_axis_cm(d[both] - dz[both])
                f["zupt_reference_cm"] = _worst_axis_cm(dz[both])
        anchored = _anchored_distance_cm(t, turned["start"], static, complete[j], waypoints) if candidates else None
        if anchored is not None:
            f["anchored_reference_cm"] = anchored
        out[position[id(complete[j])]] = f
    return out


# Which reference coordinates do not come from the start itself (trial_waypoints: the bottle's x, y and the
# mouth's y, z from the anthropometrics, home in z (the return the optimisation holds); the bottle's z and mouth's x are the start's medians)
_ANCHORED_AXES = {"bottle": (0, 1), "mouth": (1, 2), "home": (2,)}


def _anchored_distance_cm(
    t: np.ndarray, start: np.ndarray, static: np.ndarray, rep: Any, waypoints: Any
) -> float | None:
    """``reference_cm`` on the reference coordinates the start does not enter (:data:`_ANCHORED_AXES`, task frame
    = world frame): RMS per axis over the rests at the bottle, the mouth and home, the worst axis (cm)."""
    import numpy as np

    from imulog.process.minjerk import r2g_reference

    sl = slice(rep.start, rep.stop)
    b = np.asarray(rep.phase_bounds_s, dtype=np.float64)
    tt = t[sl]
    st = np.asarray(static[sl], dtype=bool) & (tt >= b[0, 0])
    d = (np.asarray(start[sl]) - r2g_reference(tt, b, waypoints))[st]
    ts = tt[st]
    where = np.where(ts < b[1, 0], 0, np.where(ts < b[2, 0], 1, np.where(ts < b[3, 0], 2, 3)))
    sq: list[list[float]] = [[], [], []]
    for k, name in enumerate(("bottle", "mouth", "bottle", "home")):
        for ax in _ANCHORED_AXES[name]:
            v = d[where == k, ax]
            sq[ax].extend(v[np.isfinite(v)].tolist())
    rms = [float(np.sqrt(np.mean(np.square(v)))) for v in sq if v]
    return 100 * max(rms) if rms else None


def _turned(positions: np.ndarray, repetitions: Sequence[Any], info: Mapping[str, Any]) -> np.ndarray:
    """``positions`` (N, 3) m turned back by each repetition's heading drift, as the optimisation starts."""
    import numpy as np

    from imulog.process.trajectory_optimize import rotate_about_z

    out = np.array(positions, dtype=np.float64, copy=True)
    for rep, deg in zip(repetitions, info.get("heading_drift_deg") or (), strict=False):
        if deg:
            out[rep.start : rep.stop] = rotate_about_z(out[rep.start : rep.stop], np.radians(deg))
    return out


def _worst_axis_cm(d: np.ndarray) -> float:
    """The largest per-axis RMS (cm) of (n, 3) m differences."""
    import numpy as np

    return float(100 * np.max(np.sqrt(np.mean(d**2, axis=0))))


def _rms_distance_cm(a: np.ndarray, b: np.ndarray) -> float | None:
    """RMS 3D distance (cm) between two (N, 3) m trajectories over the samples where both are finite."""
    import numpy as np

    d = np.asarray(a) - np.asarray(b)
    d = d[np.all(np.isfinite(d), axis=1)]
    return float(100 * np.sqrt(np.mean(np.sum(d**2, axis=1)))) if len(d) else None


def _edge_run_s(t: np.ndarray, static: np.ndarray) -> float:
    """Length (s) of the run of static samples at the start of ``static``."""
    import numpy as np

    if not len(static) or not static[0]:
        return 0.0
    moving = np.flatnonzero(~static)
    end = moving[0] if len(moving) else len(static)
    return float(abs(t[end - 1] - t[0]))


def flag_repetition(features: Mapping[str, Any], params: FlagParams = FlagParams()) -> list[str]:
    """The reasons to distrust one repetition (empty: trusted)."""
    reasons = []
    if features.get("split"):
        reasons.append("split")
    if features.get("missing"):
        reasons.append("missing")
    if features.get("merged") and (features.get("confidence", 1.0) < params.min_confidence):
        reasons.append("merged")
    elif features.get("confidence", 1.0) < params.min_confidence:
        reasons.append("low confidence")
    ref = features.get("reference_cm")
    if ref is not None and params.max_reference_cm is not None and ref > params.max_reference_cm:
        reasons.append("drift")
    pull = features.get("zupt_bias_optimized_cm", features.get("zupt_optimized_cm"))
    if pull is not None and params.max_pull_cm is not None and pull > params.max_pull_cm:
        reasons.append("drift")
    if min(features.get("rest_before_s", 1.0), features.get("rest_after_s", 1.0)) < params.min_rest_s:
        reasons.append("weak rest")
    return list(dict.fromkeys(reasons))


def flagged_repetitions(
    features: Mapping[int, Mapping[str, Any]],
    params: FlagParams = FlagParams(),
    alignment_quality: str | None = None,
) -> list[dict[str, Any]]:
    """``[{"repetition": k, "reasons": [...]}]`` for every flagged repetition, in repetition order.

    ``alignment_quality``: the ``imulog.alignment`` quality grade; ``poor`` adds the reason ``poor alignment``
    to every repetition (the errors against the reference cannot be trusted then either)."""
    out = []
    for k in sorted(features):
        reasons = flag_repetition(features[k], params)
        if alignment_quality == "poor":
            reasons.append("poor alignment")
        if reasons:
            out.append({"repetition": int(k), "reasons": reasons})
    return out


def flag_line(flagged: Sequence[Mapping[str, Any]], total: int, limit: int = 12) -> str:
    """One line: how many repetitions are flagged, which and why (empty when none is)."""
    if not flagged:
        return ""
    shown = ", ".join(f"{f['repetition']} ({', '.join(f['reasons'])})" for f in flagged[:limit])
    more = f" +{len(flagged) - limit} more" if len(flagged) > limit else ""
    return f"{len(flagged)} of {total} repetitions flagged: {shown}{more}"


def trial_flags(timing: Mapping[str, Any], trajectory: Mapping[str, Any]) -> tuple[list[dict[str, Any]], int] | None:
    """A trial's repetition flags and its repetition count: the trajectory step's when it ran (it adds drift to
    event correction's reasons), else the phases step's (``imulog.trajectory`` / ``imulog.timing`` records);
    None when neither holds flags (records of an older imulog)."""
    timing, trajectory = timing or {}, trajectory or {}
    if "flagged_repetitions" in trajectory:
        return list(trajectory["flagged_repetitions"] or []), len(trajectory.get("repetitions") or [])
    if "flagged_repetitions" in timing:
        return list(timing["flagged_repetitions"] or []), int(timing.get("n_repetitions") or 0)
    return None
