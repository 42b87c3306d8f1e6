"""Repetition windows and the R2G reference's waypoints for the trajectory methods.

:func:`repetition_windows` cuts sample windows around each repetition's phases (widened to a true rest at each
end), :func:`merge_overlapping` joins windows with no rest between them; :func:`trial_waypoints` measures the
minimum-jerk reference's waypoints, and :func:`reference_residuals`, :func:`inconsistent_repetitions` and
:func:`estimate_data_sigma` judge the initial estimate against that reference; :func:`heading_drift` finds the
initial estimate's heading drift over the trial. Times in s, positions in m.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import t as student_t
from scipy.stats import theilslopes

from imulog.process.input_checks import (
    DEFAULT_INPUT_CHECKS,
    InputCheck,
    InputCheckParams,
    SideCheck,
    apply_checks,
    explicit_waypoints,
    given_value,
    side_checks,
    waypoint_checks,
)
from imulog.process.minjerk import (
    R2GReferenceParams,
    R2GWaypoints,
    r2g_reference,
    r2g_waypoints_from_anthropometrics,
    r2g_waypoints_from_positions,
)
from imulog.process.trajectory_checks import movement_closures
from imulog.process.trajectory_optimize import heading_alignment

DEFAULT_REFERENCE = R2GReferenceParams()


@dataclass
class Repetition:
    """One repetition: the sample window [start, stop) and its four phase bounds (4, 2) in s."""

    index: int
    start: int
    stop: int
    phase_bounds_s: np.ndarray


def reference_residuals(
    t_s: np.ndarray,
    initial_m: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
) -> dict[int, np.ndarray]:
    """Per repetition (by list position), the (initial - reference) residuals (K, 3) m at the static samples
    after the repetition's first phase starts."""
    t = np.asarray(t_s, dtype=np.float64)
    out: dict[int, np.ndarray] = {}
    for i, rep in enumerate(repetitions):
        if len(rep.phase_bounds_s) != 4:
            continue
        sl = slice(rep.start, rep.stop)
        ref = r2g_reference(t[sl], rep.phase_bounds_s, waypoints)
        # static samples after the first phase starts (before it, both are zero by construction)
        st = np.asarray(static_mask[sl], dtype=bool) & (t[sl] >= rep.phase_bounds_s[0, 0])
        out[i] = (np.asarray(initial_m[sl]) - ref)[st]
    return out


def inconsistent_repetitions(
    residuals: Mapping[int, np.ndarray], factor: float = 3.0, min_m: float = 0.20
) -> list[int]:
    """Repetitions whose RMS residual against the reference exceeds ``factor`` x the trial median and
    ``min_m`` (m; 0.2 m is about half an adult's bottle-to-mouth distance, so only a reference shifted by
    whole waypoints exceeds it): their phases do not follow the protocol (e.g. a missed movement shifted the
    labels), the optimisation's premise fails and they keep the initial estimate."""
    rms = {i: float(np.sqrt(np.nanmean(np.sum(r**2, axis=1)))) for i, r in residuals.items() if len(r)}
    if not rms:
        return []
    med = float(np.median(list(rms.values())))
    return sorted(i for i, v in rms.items() if v > max(factor * med, min_m))


def estimate_data_sigma(
    t_s: np.ndarray,
    initial_m: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
    sigma_ref_m: float | Sequence[float],
    floor_m: float = 0.006,
) -> tuple[float, float, float]:
    """Per-axis error (m) of the initial estimate's static positions, by variance components.

    Over the static samples of every complete repetition, the mean square of (initial - reference) is
    the initial estimate's error variance plus the reference's (``sigma_ref_m``, assumed; one value or one per
    axis); the remainder (at least ``floor_m``) is the estimate's.
    """
    resid = reference_residuals(t_s, initial_m, static_mask, repetitions, waypoints)
    bad = set(inconsistent_repetitions(resid))
    res = [r for i, r in resid.items() if i not in bad and len(r)]
    ref = np.broadcast_to(np.asarray(sigma_ref_m, dtype=np.float64), (3,))
    if not res:
        return tuple(float(v) for v in ref)
    ms = np.nanmean(np.vstack(res) ** 2, axis=0)
    return tuple(float(np.sqrt(max(v - r**2, floor_m**2))) for v, r in zip(ms, ref, strict=True))


def closure_sigma(
    t_s: np.ndarray, acc_mps2: np.ndarray, static_mask: np.ndarray, repetitions: Sequence[Repetition]
) -> tuple[float, float, float]:
    """Per-axis size (m) of what ZUPT's de-drift removed in the complete repetitions' movements: the RMS of the
    velocity reached at the next rest times half the movement's duration (the displacement the linear de-drift
    takes off). An estimate whose movements close with little velocity has little to be wrong about."""
    t = np.asarray(t_s, dtype=np.float64)
    parts = []
    for rep in repetitions:
        if len(rep.phase_bounds_s) != 4:
            continue
        sl = slice(rep.start, rep.stop)
        vel, dur = movement_closures(t[sl], np.asarray(acc_mps2)[sl], np.asarray(static_mask, dtype=bool)[sl])
        if len(dur):
            parts.append(vel * dur[:, None] / 2.0)
    if not parts:
        return (float("inf"),) * 3
    d = np.vstack(parts)
    return tuple(float(x) for x in np.sqrt(np.nanmean(d**2, axis=0)))


def repetition_windows(
    t_s: np.ndarray, phase_bounds_s: Mapping[int, np.ndarray], static_mask: np.ndarray, pad_s: float = 1.0
) -> list[Repetition]:
    """Sample windows around each repetition: from ``pad_s`` before its first phase to ``pad_s`` after its
    last (never past the neighbouring repetitions' phases), widened to include a static sample at each end."""
    t = np.asarray(t_s, dtype=np.float64)
    static = np.asarray(static_mask, dtype=bool)
    keys = sorted(phase_bounds_s)
    reps: list[Repetition] = []
    for i, k in enumerate(keys):
        b = np.asarray(phase_bounds_s[k], dtype=np.float64).reshape(-1, 2)
        lo = b[0, 0] - pad_s
        hi = b[-1, 1] + pad_s
        if i > 0:
            lo = max(lo, 0.5 * (np.asarray(phase_bounds_s[keys[i - 1]])[-1, 1] + b[0, 0]))
        shared = False  # the upper bound is the midpoint the next window starts at: a sample there is the next's
        if i + 1 < len(keys):
            mid = 0.5 * (b[-1, 1] + np.asarray(phase_bounds_s[keys[i + 1]])[0, 0])
            shared, hi = mid <= hi, min(hi, mid)
        s = int(np.searchsorted(t, lo, side="left"))
        e = int(np.searchsorted(t, hi, side="left" if shared else "right"))
        while s > 0 and not static[s]:
            s -= 1
        while e < len(t) and not static[e - 1]:
            e += 1
        if e - s >= 3:
            reps.append(Repetition(int(k), s, e, b))
    return reps


def merge_overlapping(repetitions: Sequence[Repetition]) -> tuple[list[Repetition], list[list[int]]]:
    """Windows that overlap (no true rest between two movements, so both widened to the same rests) merged
    into one, in time order: ``(windows, [[indices merged], ...])``. A merged window keeps the first index and
    every phase bound (so it is not a 4-phase R2G repetition any more)."""
    out: list[Repetition] = []
    groups: list[list[int]] = []
    for rep in sorted(repetitions, key=lambda r: r.start):
        if out and rep.start < out[-1].stop:
            last = out[-1]
            bounds = np.vstack([last.phase_bounds_s.reshape(-1, 2), rep.phase_bounds_s.reshape(-1, 2)])
            out[-1] = Repetition(last.index, last.start, max(last.stop, rep.stop), bounds)
            groups[-1].append(rep.index)
        else:
            out.append(rep)
            groups.append([rep.index])
    return out, [g for g in groups if len(g) > 1]


def trial_waypoints(
    anthropometrics: Mapping[str, Any] | None,
    t_s: np.ndarray,
    zupt_m: np.ndarray,
    repetitions: Sequence[Repetition],
    params: R2GReferenceParams = DEFAULT_REFERENCE,
    checks: list[InputCheck | SideCheck] | None = None,
    check_params: InputCheckParams = DEFAULT_INPUT_CHECKS,
    side: tuple[str, str] | None = None,
) -> R2GWaypoints:
    """Waypoints for a trial: h1, h2, h3 (and ``mouth_dx_m``, the mouth's x, and ``bottle_dy_m``, the bottle's
    lateral offset from the start when it is not h2, when present) from the anthropometrics; every
    other coordinate is the median over repetitions of the ZUPT displacement at the phase ends (no optical
    data involved). Without anthropometrics all coordinates come from ZUPT.

    Every given value is checked against the same ZUPT medians (:mod:`imulog.process.input_checks`): ``checks``,
    when given, receives one :class:`InputCheck` per value; a disagreeing value marked approximate is replaced
    by the estimate. Explicit ``bottle_m`` and ``mouth_m`` (both given) are the waypoints, each coordinate checked
    the same way. ``side``: ``(left|right, where the metadata says so)``, checked against the ZUPT mouths' y and
    the sign of the given h2 (or ``mouth_m``'s y) (:func:`imulog.process.input_checks.side_checks`), never
    changed."""
    t = np.asarray(t_s, dtype=np.float64)
    bottles, mouths = [], []
    for rep in repetitions:
        if len(rep.phase_bounds_s) != 4:
            continue
        sl = slice(rep.start, rep.stop)
        w = r2g_waypoints_from_positions(zupt_m[sl], t[sl], rep.phase_bounds_s)
        bottles.append(w.bottle_m)
        mouths.append(w.mouth_m)
    if not bottles:
        raise ValueError("no complete repetition to measure waypoints from")
    bottle = np.median(np.asarray(bottles), axis=0)
    mouth = np.median(np.asarray(mouths), axis=0)
    c, s = np.cos(params.heading_rad), np.sin(params.heading_rad)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    given_y = None  # the mouth's y the reference is given (task frame), for the side's check
    explicit = explicit_waypoints(anthropometrics or {})
    if explicit is not None:  # the reference's waypoints as given (world frame), each coordinate checked
        found = waypoint_checks(anthropometrics, np.asarray(bottles), np.asarray(mouths), params.keys, check_params)
        bottle, mouth = apply_checks(explicit[0], explicit[1], found)
        given_y = ("mouth_m[1]", float((rot.T @ explicit[1])[1]))
        if checks is not None:
            checks.extend(found)
    elif anthropometrics:
        try:
            anth = r2g_waypoints_from_anthropometrics(anthropometrics, params)
        except KeyError:
            anth = None
        if anth is not None:
            bt, mt = rot.T @ bottle, rot.T @ mouth  # into the task frame
            at_b, at_m = rot.T @ np.asarray(anth.bottle_m), rot.T @ np.asarray(anth.mouth_m)
            bt[0], bt[1] = at_b[0], at_b[1]  # h1, h2
            mt[1], mt[2] = at_m[1], at_m[2]  # h2, h3
            if "mouth_dx_m" in anthropometrics:
                mt[0] = float(anthropometrics["mouth_dx_m"])
            if anthropometrics.get("bottle_dy_m") is not None:  # bottle not in front of the shoulder: measured
                bt[1] = float(anthropometrics["bottle_dy_m"])
            found = waypoint_checks(
                anthropometrics,
                np.asarray(bottles) @ rot,  # each row into the task frame
                np.asarray(mouths) @ rot,
                params.keys,
                check_params,
                bottle_y_fraction=params.bottle_y_fraction,
            )
            bt, mt = apply_checks(bt, mt, found)
            if checks is not None:
                checks.extend(found)
            bottle, mouth = rot @ bt, rot @ mt
            given_y = given_value(anthropometrics, tuple(params.keys.get("h2", ())))
    if side is not None and checks is not None:
        checks.extend(side_checks(side[0], side[1], np.asarray(mouths) @ rot, given_y, check_params))
    return R2GWaypoints(bottle_m=tuple(bottle.tolist()), mouth_m=tuple(mouth.tolist()))


def velocity_sigma(
    sigma_static_m: Sequence[float], repetitions: Sequence[Repetition], floor_mps: float
) -> tuple[float, float, float]:
    """Per-axis error (m/s) of the initial estimate's velocity, consistent with its static positions' error.

    The initial estimate starts every repetition from zero, so an error ``sigma_static_m`` (m, per axis, from
    :func:`estimate_data_sigma`) at the holds was built up during the phases: over a phase of the trial's
    median duration ``T`` (s) the velocity is off by about ``sigma_static_m / T``. The optimisation's
    velocity term must trust the estimate no more than that, or it keeps the shape of a drifting estimate
    against the reference (``floor_mps``, the configured ``sigma_data_mps``, is the least)."""
    durations = [float(b[1] - b[0]) for r in repetitions if len(r.phase_bounds_s) == 4 for b in r.phase_bounds_s]
    if not durations:
        return (float(floor_mps),) * 3
    t = max(float(np.median(durations)), 1e-3)
    return tuple(max(float(floor_mps), float(s) / t) for s in sigma_static_m)


def heading_drift(
    t_s: np.ndarray,
    initial_m: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
    sigma_ref_m: float,
    alpha: float = 0.001,
) -> np.ndarray:
    """Per repetition, the heading error (rad, about the vertical) of the initial estimate when it drifts
    significantly over the trial; 0 otherwise (and for incomplete repetitions, or fewer than 3 complete ones).

    A 6D orientation filter has no heading reference, so a gyroscope bias about the vertical turns the whole
    trial's horizontal trajectory by an angle that grows with time. Each complete repetition's angle is the
    rotation about z that best maps its static positions onto the reference's
    (:func:`imulog.process.trajectory_optimize.heading_alignment`, unwrapped over the trial); a straight line in
    time (what a constant bias gives) is fitted through them robustly (Theil-Sen). Unless its slope differs
    from 0 at significance level ``alpha`` (t test with the angles' scatter about the line, n - 2 degrees of
    freedom) there is no drift to remove: the angles then mostly measure position errors of the estimate and the
    reference, not its heading, and every angle is 0. Otherwise each repetition gets the line plus its own
    deviation from it, shrunk by the share of the deviations' variance the reference's error does not explain
    (empirical Bayes: the reference's error in angle is ``sigma_ref_m`` over the bottle's horizontal distance,
    rad), so a drift that is not quite linear is followed where the repetitions agree on it."""
    t = np.asarray(t_s, dtype=np.float64)
    static = np.asarray(static_mask, dtype=bool)
    out = np.zeros(len(repetitions))
    idx, angles, times = [], [], []
    for i, rep in enumerate(repetitions):
        if len(rep.phase_bounds_s) != 4:
            continue
        sl = slice(rep.start, rep.stop)
        ref = r2g_reference(t[sl], rep.phase_bounds_s, waypoints)
        mask = static[sl] & (t[sl] >= rep.phase_bounds_s[0, 0])
        if not np.any(mask):
            continue
        idx.append(i)
        angles.append(heading_alignment(np.asarray(initial_m[sl]), ref, mask, full_circle=True))
        times.append(float(np.mean(t[sl])))
    lever = float(np.hypot(waypoints.bottle_m[0], waypoints.bottle_m[1]))
    if len(idx) < 3 or lever <= 0:
        return out
    order = np.argsort(times)
    th = np.empty(len(angles))
    th[order] = np.unwrap(np.asarray(angles)[order])
    tm = np.asarray(times)
    slope, intercept, _, _ = theilslopes(th, tm)
    line = intercept + slope * tm
    scatter = float(np.sqrt(np.sum((th - line) ** 2) / (len(th) - 2)))
    spread = float(np.sqrt(np.sum((tm - tm.mean()) ** 2)))
    if spread <= 0 or abs(slope) * spread < scatter * student_t.ppf(1.0 - alpha / 2.0, len(th) - 2):
        return out
    own = max(0.0, 1.0 - (sigma_ref_m / lever) ** 2 / scatter**2) if scatter > 0 else 0.0
    out[idx] = line + own * (th - line)
    return out
