"""Every trajectory method on every repetition of a trial, with each method's assumption checks (issue 32).

:func:`reconstruct_repetitions` is what the trajectory step runs; :func:`method_checks` judges each method on the
windows it ran on. The parts live one concern per module, lowest first:

* :mod:`imulog.process.trajectory_checks`: the assumption checks as pure functions (rests, bias, de-drift, share
  of the motion removed) and the verdict;
* :mod:`imulog.process.trajectory_optimize`: the R2G thesis's optimisation (one sparse least squares);
* :mod:`imulog.process.trajectory_methods`: every method on one window (:func:`reconstruct`), its parameters;
* :mod:`imulog.process.trajectory_repetitions`: repetition windows and the R2G reference's waypoints.

Their public names are importable from here as well (the trajectory step, the benchmarks and the docs use them).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from imulog.process.acc_rest_calibration import AccRestCalibration
from imulog.process.drift import highpass, wavelet_detrend
from imulog.process.input_checks import InputCheck, SideCheck
from imulog.process.integration import compensate_rotating_bias, estimate_rotating_bias, rest_ramp, zupt
from imulog.process.minjerk import R2GReferenceParams, R2GWaypoints
from imulog.process.trajectory_checks import (
    FILTER_METHODS,
    assess,
    bias_check,
    dedrift_check,
    dedrift_offsets,
    movement_closures,
    removed_share,
    rest_summary,
)
from imulog.process.trajectory_methods import (
    BASELINE,
    DEFAULT_PARAMS,
    METHODS,
    TrajectoryParams,
    quat_to_matrix,
    reconstruct,
)
from imulog.process.trajectory_optimize import (
    OptimizationParams,
    OptimizationResult,
    _symmetry_rows,
    coupled_symmetry_cost,
    heading_alignment,
    optimize_repetition,
    rotate_about_z,
)
from imulog.process.trajectory_repetitions import (
    DEFAULT_REFERENCE,
    Repetition,
    closure_sigma,
    estimate_data_sigma,
    heading_drift,
    inconsistent_repetitions,
    merge_overlapping,
    reference_residuals,
    repetition_windows,
    trial_waypoints,
    velocity_sigma,
)
from imulog.process.trajectory_rest_model import RestRule, reference_scatter, repetition_references
from imulog.process.trajectory_rests import repetition_offsets, rest_blend_weight, shifted_waypoints

__all__ = [
    "BASELINE",
    "DEFAULT_PARAMS",
    "DEFAULT_REFERENCE",
    "METHODS",
    "OptimizationParams",
    "OptimizationResult",
    "Repetition",
    "TrajectoryParams",
    "_symmetry_rows",
    "coupled_symmetry_cost",
    "estimate_data_sigma",
    "heading_alignment",
    "heading_drift",
    "inconsistent_repetitions",
    "merge_overlapping",
    "method_checks",
    "optimize_repetition",
    "quat_to_matrix",
    "reconstruct",
    "reconstruct_repetitions",
    "reference_residuals",
    "repetition_windows",
    "rotate_about_z",
    "trial_waypoints",
    "velocity_sigma",
]


def reconstruct_repetitions(
    t_s: np.ndarray,
    acc_mps2: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    methods: Sequence[str] = METHODS,
    *,
    anthropometrics: Mapping[str, Any] | None = None,
    waypoints: R2GWaypoints | None = None,
    orientation: np.ndarray | None = None,
    params: TrajectoryParams = DEFAULT_PARAMS,
    reference_params: R2GReferenceParams = DEFAULT_REFERENCE,
    info: dict[str, Any] | None = None,
    baseline: bool = False,
    side: tuple[str, str] | None = None,
    drift_candidates: bool = False,
    acc_calibration: AccRestCalibration | None = None,
) -> dict[str, np.ndarray]:
    """Every method on every repetition: {method: (N, 3) m relative to each repetition's start, NaN outside}.

    orientation: (N, 4) w,x,y,z sensor-to-frame-of-``acc_mps2`` quaternions; enables ``zupt_bias`` and the
    rotating-bias compensation of the optimisation's initial estimate. ``info``, when given, receives the
    estimated bias (m/s^2), the waypoints, the per-repetition heading corrections and ``checks``: per method
    the verdict of :func:`imulog.process.trajectory_checks.assess` on its assumptions. A rotating-bias estimate
    outside the sensor's physical range (``params.checks``) is refused: ``zupt_bias`` is then ZUPT and the
    optimisation starts from ZUPT. ``baseline``: also return :data:`BASELINE` (linear velocity de-drift
    between each window's first and last sample), the figure every method must beat. ``side``: the placement's
    ``(left|right, source)``, checked with the given anthropometrics (``info["input_checks"]``).
    ``drift_candidates``: also ``info["closure_mps"]``, an unused candidate of the repetition flags' ``drift``
    reason (:mod:`imulog.process.repetition_flags`; only ``benchmarks/confidence_calibration.py`` asks for it).
    ``acc_calibration``: the correction ``acc_mps2`` was computed with (``TrajectoryParams.acc_rests``); its
    posterior is the rotating-bias fit's prior with ``RotatingBiasParams.calibration_prior``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    a = np.asarray(acc_mps2, dtype=np.float64)
    static = np.asarray(static_mask, dtype=bool)
    methods = [m for m in methods if m != "zupt_bias" or orientation is not None]
    out = {m: np.full((len(t), 3), np.nan) for m in methods}
    a_comp = None
    bias: dict[str, Any] | None = None
    if orientation is not None and any(m in ("zupt_bias", "optimized") for m in methods):
        rot = quat_to_matrix(orientation)
        prior = None
        if params.rotating_bias.calibration_prior and acc_calibration is not None and acc_calibration.applied:
            prior = acc_calibration.covariance
        errors = estimate_rotating_bias(a, rot, t, static, params.rotating_bias, prior)
        bias = bias_check(errors.as_dict(), params.checks)
        a_comp = compensate_rotating_bias(a, rot, t, static, errors, params.rotating_bias) if bias["ok"] else None
        if info is not None:
            info["accelerometer_errors"] = {**errors.as_dict(), "applied": bool(bias["ok"])}
    base = a if a_comp is None else a_comp
    if drift_candidates and info is not None and bias is not None:  # what the fit leaves (a drift candidate)
        info["closure_mps"] = [
            _closure_left(t[r.start : r.stop], base[r.start : r.stop], static[r.start : r.stop]) for r in repetitions
        ]
    if "optimized" in methods:
        if any(params.optimized.rest_ramp):  # the start's drift as a ramp between the flanking rests
            base = rest_ramp(base, t, static, params.rotating_bias.rest_s, params.optimized.rest_ramp)
        z = _initial(t, base, static, repetitions, params)
        if waypoints is None:
            input_checks: list[InputCheck | SideCheck] = []
            waypoints = trial_waypoints(anthropometrics, t, z, repetitions, reference_params, input_checks, side=side)
            if info is not None and input_checks:
                info["input_checks"] = [c.as_dict() for c in input_checks]
                info["input_warnings"] = [c.line() for c in input_checks if c.disagrees]
    if info is not None and waypoints is not None:
        info["waypoints_m"] = {"bottle": list(waypoints.bottle_m), "mouth": list(waypoints.mouth_m)}
    fallback: set[int] = set()
    rep_waypoints = [waypoints] * len(repetitions)
    rep_params: list[TrajectoryParams | None] = [None] * len(repetitions)
    if "optimized" in methods:
        turn = np.zeros(len(repetitions))
        if params.optimized.heading_drift:
            turn = heading_drift(t, z, static, repetitions, waypoints, params.optimized.sigma_ref_static_m)
            if np.any(turn):
                base = base.copy()
                for rep, angle in zip(repetitions, turn, strict=True):
                    base[rep.start : rep.stop] = rotate_about_z(base[rep.start : rep.stop], float(angle))
                z = _initial(t, base, static, repetitions, params)
            if info is not None:
                info["heading_drift_deg"] = np.degrees(turn).round(3).tolist()
        if any(params.optimized.start_blend) and a_comp is not None:
            base, z = _blended_start(t, a, base, z, turn, static, repetitions, waypoints, anthropometrics, params, info)
        fallback = set(inconsistent_repetitions(reference_residuals(t, z, static, repetitions, waypoints)))
        if params.optimized.sigma_data_static_m == "auto":
            floor_m, floor_mps = _trust_floors(params.optimized, acc_calibration)
            srs = params.optimized.sigma_ref_static_m
            sig = _start_sigma(t, z, base, static, repetitions, waypoints, params.optimized, floor_m, srs)
            if any(params.optimized.reference_scatter):  # the reference trusted no more than the hand's scatter says
                least = [s / np.sqrt(2.0) for s in sig]  # a displacement is no better known than the start's rests
                wide = reference_scatter(t, z, static, repetitions, waypoints, srs, least)
                own = np.broadcast_to(np.asarray(srs, dtype=np.float64), (3,))
                srs = tuple(float(v) for v in np.where(params.optimized.reference_scatter, wide, own))
                sig = _start_sigma(t, z, base, static, repetitions, waypoints, params.optimized, floor_m, srs)
                params = replace(params, optimized=replace(params.optimized, sigma_ref_static_m=srs))
                if info is not None:
                    info["sigma_ref_static_m"] = list(srs)
            params = replace(params, optimized=replace(params.optimized, sigma_data_static_m=sig))
            if info is not None:
                info["sigma_data_static_m"] = list(sig)
            if params.optimized.velocity_from_static:
                vel = velocity_sigma(sig, repetitions, floor_mps)
                params = replace(params, optimized=replace(params.optimized, sigma_data_mps=vel))
                if info is not None:
                    info["sigma_data_mps"] = list(vel)
        if info is not None:
            info["optimized_fallback"] = [repetitions[i].index for i in sorted(fallback)]
        if params.optimized.rest_chain:
            rep_waypoints = _chained_waypoints(t, z, static, repetitions, waypoints, params, info)
        if params.optimized.rest_model:
            rule = RestRule.parse(str(params.optimized.rest_model))
            z_rests = z
            if rule.ramp:  # the rests from displacements with each movement's offset ramped between its rests
                z_rests = _initial(
                    t, rest_ramp(base, t, static, params.rotating_bias.rest_s, rule.axes), static, repetitions, params
                )
            rep_waypoints, own = repetition_references(
                t, z_rests, static, repetitions, rep_waypoints, waypoints, params.optimized, info
            )
            rep_params = [None if o is None else replace(params, optimized=o) for o in own]
    if baseline:
        methods = [*methods, BASELINE]
        out[BASELINE] = np.full((len(t), 3), np.nan)
    for i, rep in enumerate(repetitions):
        sl = slice(rep.start, rep.stop)
        # a refused (unphysical) estimate: zupt_bias is ZUPT on the uncompensated acceleration
        comp = a_comp[sl] if a_comp is not None else a[sl] if bias is not None else None
        for m in methods:
            if m == "optimized" and len(rep.phase_bounds_s) != 4:
                continue
            if m == "optimized" and i in fallback:  # keep the initial estimate
                out[m][sl] = z[sl]
                continue
            out[m][sl] = reconstruct(
                m,
                t[sl],
                a[sl],
                static[sl],
                phase_bounds_s=rep.phase_bounds_s,
                waypoints=rep_waypoints[i] if m == "optimized" else waypoints,
                acc_compensated_mps2=base[sl] if m == "optimized" else comp,  # optimized: heading-corrected
                params=(rep_params[i] or params) if m == "optimized" else params,
            )
    if info is not None:
        info["checks"] = method_checks(t, a, a_comp, static, repetitions, out, params, bias)
    return out


def _start_sigma(
    t: np.ndarray,
    z: np.ndarray,
    acc: np.ndarray,
    static: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
    o: OptimizationParams,
    floor_m: float,
    sigma_ref_m: Any,
) -> tuple[float, float, float]:
    """The ``"auto"`` static-position trust of the start ``z`` per axis (m): its variance component against a
    reference off by ``sigma_ref_m`` (:func:`estimate_data_sigma`), at most ``o.closure_factor`` x what the
    movements' closure on ``acc`` allows and at least ``floor_m``."""
    sig = estimate_data_sigma(t, z, static, repetitions, waypoints, sigma_ref_m)
    if o.closure_factor is not None:  # at most what the movements' closure allows
        closure = closure_sigma(t, acc, static, repetitions)
        sig = tuple(max(floor_m, min(s, o.closure_factor * c)) for s, c in zip(sig, closure, strict=True))
    return sig


def _trust_floors(o: OptimizationParams, calibration: AccRestCalibration | None) -> tuple[float, Any]:
    """The least static-position trust (m) and velocity trust (m/s) of the ``"auto"`` start: 6 mm and
    ``sigma_data_mps``, or with ``o.corrected_floor_m`` and an applied rest calibration that floor and none."""
    if o.corrected_floor_m is not None and calibration is not None and calibration.applied:
        return float(o.corrected_floor_m), 0.0
    return 0.006, o.sigma_data_mps


def _chained_waypoints(
    t: np.ndarray,
    z: np.ndarray,
    static: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
    params: TrajectoryParams,
    info: dict[str, Any] | None,
) -> list[R2GWaypoints]:
    """Each repetition's reference waypoints moved by where it starts and ends relative to the trial's home
    (:func:`imulog.process.trajectory_rests.repetition_offsets` on the start ``z``, the axes not held to return
    to the start), with the start's static-position error per axis against the reference (variance components,
    :func:`imulog.process.trajectory_repetitions.estimate_data_sigma`, not bounded by the closure) as the chain's
    uncertainty."""
    o = params.optimized
    sig = estimate_data_sigma(t, z, static, repetitions, waypoints, o.sigma_ref_static_m)
    rts = o.return_to_start
    free = [not r for r in rts] if isinstance(rts, (tuple, list)) else [not rts] * 3
    offsets = repetition_offsets(t, z, static, repetitions, sig, o.sigma_ref_static_m)
    if info is not None:
        info["repetition_offsets_m"] = np.round(offsets * np.asarray(free), 5).tolist()
    return [shifted_waypoints(waypoints, off, free) for off in offsets]


def _blended_start(
    t: np.ndarray,
    acc: np.ndarray,
    comp: np.ndarray,
    z: np.ndarray,
    turn: np.ndarray,
    static: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
    anthropometrics: Mapping[str, Any] | None,
    params: TrajectoryParams,
    info: dict[str, Any] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """The optimisation's start on the acceleration ``acc + w (comp - acc)`` per global axis, ``w`` from the rests
    (:func:`imulog.process.trajectory_rests.rest_blend_weight`); ``comp`` is the compensated (and turned)
    acceleration, ``z`` its ZUPT start. The measured acceleration is turned by the same heading drift (``turn``,
    rad per repetition)."""
    raw = np.array(acc, dtype=np.float64, copy=True)
    for rep, angle in zip(repetitions, turn, strict=True):
        if angle:
            raw[rep.start : rep.stop] = rotate_about_z(raw[rep.start : rep.stop], float(angle))
    z_raw = _initial(t, raw, static, repetitions, params)
    mouth_x = bool(anthropometrics) and "mouth_dx_m" in anthropometrics
    w = np.asarray(rest_blend_weight(t, z_raw, z, static, repetitions, waypoints, mouth_x))
    w = np.where(np.asarray(params.optimized.start_blend, dtype=bool), w, 1.0)
    if info is not None:
        info["start_weight"] = np.round(w, 4).tolist()
    return raw + w * (comp - raw), z_raw + w * (z - z_raw)


def _closure_left(t: np.ndarray, acc: np.ndarray, static: np.ndarray) -> float | None:
    """The largest velocity (m/s, 3D norm) a window's movements leave at their next rest (None: no movement
    between two rests): with the rotating-bias-compensated acceleration, the fit's residual there."""
    vel, _ = movement_closures(t, acc, static)
    return round(float(np.max(np.linalg.norm(vel, axis=1))), 5) if len(vel) else None


def _initial(
    t: np.ndarray, acc: np.ndarray, static: np.ndarray, repetitions: Sequence[Repetition], params: TrajectoryParams
) -> np.ndarray:
    """ZUPT positions (N, 3) m of every repetition from its own start (NaN outside): the optimisation's start."""
    z = np.full((len(t), 3), np.nan)
    for rep in repetitions:
        sl = slice(rep.start, rep.stop)
        z[sl] = zupt(acc[sl], t[sl], static[sl], params.zupt)[1]
    return z


def method_checks(
    t_s: np.ndarray,
    acc_mps2: np.ndarray,
    acc_compensated_mps2: np.ndarray | None,
    rests: np.ndarray,
    repetitions: Sequence[Any],
    positions: Mapping[str, np.ndarray],
    params: TrajectoryParams | None = None,
    bias: Mapping[str, Any] | None = None,
) -> dict[str, dict[str, Any]]:
    """Per method in ``positions``, :func:`imulog.process.trajectory_checks.assess` on the windows it ran on:
    rests (every dead-reckoning method), the implied de-drift offset (ZUPT-based methods), the rotating-bias
    estimate's range (``zupt_bias``) and the share of the motion's range a filter removes (``highpass``,
    ``wavelet``: the filter applied to ZUPT, or to the baseline in a window without rests)."""
    params = params or TrajectoryParams()
    t = np.asarray(t_s, dtype=np.float64)
    windows = [(r.start, r.stop) for r in repetitions]
    summary = rest_summary(t, rests, windows)
    offsets = np.concatenate(
        [dedrift_offsets(t[r.start : r.stop], acc_mps2[r.start : r.stop], rests[r.start : r.stop]) for r in repetitions]
        or [np.zeros(0)]
    )
    out: dict[str, dict[str, Any]] = {}
    for m in positions:
        if m in FILTER_METHODS:
            shares = []
            for r in repetitions:
                sl = slice(r.start, r.stop)
                own = rest_summary(t, rests, [(r.start, r.stop)])
                if not own["count"] or own["longest_without_s"] > params.checks.max_without_rest_s:
                    continue  # ZUPT drifts here too: what the filter removes cannot be told from drift
                before = reconstruct("zupt", t[sl], acc_mps2[sl], rests[sl], params=params)
                if np.nanmax(np.ptp(before, axis=0)) < params.checks.min_motion_m:
                    continue  # hardly any motion (the alignment wave): no share to speak of
                after = (
                    highpass(before, (len(t[sl]) - 1) / (t[sl][-1] - t[sl][0]), params.highpass)
                    if m == "highpass"
                    else wavelet_detrend(before, params.wavelet)
                )
                shares.append(removed_share(before, after - after[0]))
            share = np.nanmedian(np.asarray(shares, dtype=float), axis=0).round(4).tolist() if shares else None
            out[m] = assess(m, rests=summary, share=share, params=params.checks)
            continue
        kwargs: dict[str, Any] = {"rests": summary}
        if m in ("zupt", "kalman", "optimized"):
            kwargs["dedrift"] = dedrift_check(offsets, params.checks)
        if m == "zupt_bias":
            comp = acc_mps2 if acc_compensated_mps2 is None else acc_compensated_mps2
            off = np.concatenate(
                [
                    dedrift_offsets(t[r.start : r.stop], comp[r.start : r.stop], rests[r.start : r.stop])
                    for r in repetitions
                ]
                or [np.zeros(0)]
            )
            kwargs["dedrift"] = dedrift_check(off, params.checks)
            if bias is not None:
                kwargs["bias"] = bias
        out[m] = assess(m, params=params.checks, **kwargs)
    return out
