"""The R2G thesis's trajectory optimisation (3.3.6-3.3.7) as a sparse equality-constrained least squares.

The thesis starts from the ZUPT trajectory and minimises, with MATLAB ``fmincon`` (interior point, up to
200 iterations), coupled symmetry + smoothness + distance to a minimum-jerk reference built from h1/h2/h3,
subject to the trajectory returning to its start. Written with quadratic (instead of absolute-value)
penalties every term is linear in the unknown positions, so the optimum is one sparse linear solve::

    minimise  sum_k || W_k (A_k p - b_k) ||^2   subject to   p[0] = 0,  p[-1] = p[0]

per axis, with the rows (each weighted by sqrt(dt) / sigma, so every term is a time integral divided by
a variance with explicit units):

* data: the velocity of ``p`` stays near the ZUPT velocity, ``(p[i+1]-p[i])/dt - v_zupt`` (sigma m/s).
  The thesis keeps the data through the ZUPT starting point and the limited iterations; a convex
  problem forgets its starting point, so the data term makes that explicit;
* reference: ``p - r`` with r the minimum-jerk reference (sigma in m, one value for static samples and
  a larger one during phases, whose timing the reference only approximates);
* coupled symmetry (thesis eq. 3.2): phase 1 against phase 4 reversed and phase 2 against phase 3
  reversed, at equal fractions of each phase's duration, ``p(t) - p(mirror(t))`` (sigma m);
* smoothness (thesis eq. 3.5, "low to null velocity during static phases"): the velocity in static
  samples (sigma m/s).

The KKT system ``[[2 A^T A, C^T], [C, 0]] [p; lambda] = [2 A^T b; d]`` is factorised once (SuperLU)
and solved for the three axes together.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from imulog.param_rules import check_rules


@dataclass(frozen=True)
class OptimizationParams:
    """Weights of the R2G trajectory optimisation as standard deviations with units.

    sigma_data_mps: trust in the ZUPT velocity (m/s).
    sigma_ref_static_m: distance to the reference while the hand is still (m).
    sigma_ref_moving_m: distance to the reference during phases (m).
    sigma_symmetry_m: coupled symmetry (m); None disables the term.
    sigma_static_vel_mps: velocity in static samples (m/s); None disables the term.
    sigma_data_static_m: static positions close to the initial estimate's (m), one value or one per axis;
        ``"auto"`` estimates it per trial and axis in :func:`reconstruct_repetitions` (see
        :func:`estimate_data_sigma`); None disables the term (the thesis's formulation).
    return_to_start: hard constraint ``p[-1] = p[0]`` (thesis 3.3.7); one bool, or one per axis (x, y, z).
        ``(False, False, True)``, z only (issue 31): the hand comes back to the table's height but 1-3 cm away
        from where it started in x and y; with the heading through rests (``AnchorParams.heading="gyroscope"``)
        the estimate measures that and x and y get 0.00-0.09 cm better on held-out trials (with the filter's
        heading `combined` x got 0.07 cm worse): the default since 2026-12-07, with that heading (before: True).
    align_heading: before optimising, rotate the initial estimate about the vertical by the angle that best
        matches its static positions to the reference's (closed-form 2D Procrustes; an imulog addition that
        removes the heading error of 6D orientation filters using only the anthropometric waypoints).
    max_heading_deg: the largest heading correction applied (deg); larger fits are clipped.
    velocity_from_static: trust the initial velocity per axis no more than its static positions' error allows
        (:func:`imulog.process.trajectory_repetitions.velocity_sigma`, issue 31).
    heading_drift: before optimising, turn each repetition's initial estimate about the vertical by the trial's
        heading drift when it is significant (:func:`imulog.process.trajectory_repetitions.heading_drift`, issue 31; needs the
        whole trial, so :func:`imulog.process.trajectory_opt.reconstruct_repetitions` applies it).
    closure_factor: the ``"auto"`` static-position error per axis is at most this many times what ZUPT's de-drift
        took off the initial estimate's movements (:func:`imulog.process.trajectory_repetitions.closure_sigma`,
        issue 31; at least 6 mm; None: off, the default before 2026-12-07). The variance components measure the
        estimate against a reference that is itself 1-5 cm off per repetition, so a good estimate looked as poor
        as the reference; its movements' closure says it is good. 0.5 (chosen on development trials; 0.25 hurt
        ``combined``): ``residual-velocity`` about -1 cm per axis, no condition worse on development or held-out
        trials (docs/accuracy.md). The default since the repetition flags' ``drift`` reason stopped measuring how
        far the optimisation pulls the estimate (:mod:`imulog.process.repetition_flags`).
    start_blend: per global axis (x, y, z), start from ZUPT on the measured acceleration plus the share of the
        rotating-bias compensation that best puts the rests where the anthropometric reference has them
        (:func:`imulog.process.trajectory_rests.rest_blend_weight`, issue 31 point 2); False: all of it.
    rest_chain: on the axes not held to return to the start, move each repetition's reference by where the hand
        started and ended it relative to the trial's home (:func:`imulog.process.trajectory_rests.repetition_offsets`:
        the start's return displacements chained, each offset 0 within ``sigma_ref_static_m``; issue 31 point 2).
    rest_model: give each complete repetition's reference its own rests (bottle, mouth, bottle put back, and on the
        axes not held to return to the start its end), estimated from the start's rest-to-rest displacements and
        the trial-wide waypoints by variance components
        (:func:`imulog.process.trajectory_rest_model.repetition_rests`; issue 31 point 2; an option, None: off).
        ``"waypoints"``: only the waypoints; ``"posterior"``: also the reference's static trust per axis from the
        estimate's posterior standard deviation (at least 3 mm) and no static-position term for the start (the
        estimate already holds it); ``"posterior-data"``: the posterior trust, the start's term kept; ``"replace"``:
        the waypoints, no static-position term.
    rest_ramp: per global axis (x, y, z), take each movement's acceleration offset off the optimisation's start as
        a line from the rest before's mean to the rest after's (:func:`imulog.process.integration.rest_ramp`, over
        ``RotatingBiasParams.rest_s`` of each rest) before ZUPT's linear de-drift (issue 31 point 2, eighth
        round); ZUPT and ``zupt_bias`` themselves are unchanged.
    corrected_floor_m: with the accelerometer corrected from the trial's own rests (``TrajectoryParams.acc_rests``,
        applied), the ``"auto"`` static-position trust is bounded below by this (m) instead of 6 mm, and the
        velocity trust follows it (:func:`imulog.process.trajectory_repetitions.velocity_sigma`) without
        ``sigma_data_mps`` (0.02 m/s) as its floor: the start is then trusted as far as its own closure says
        (issue 31 point 2, tenth round: on a corrected accelerometer both floors bind on most trials and hold the
        optimisation away from a start better than they allow). None (the default): the floors as before; 2 mm is
        a guard against a closure near zero (no floor at all gave the same counts on development trials).
    reference_scatter: per global axis (x, y, z), trust the trial-wide reference's static positions no more than
        the hand's own scatter about them allows: ``sigma_ref_static_m`` raised to ``sqrt(2) tau``, ``tau`` the
        rests' scatter estimated from the start's rest-to-rest displacements, each displacement's error at least the
        start's ``"auto"`` trust over sqrt 2 (:func:`imulog.process.trajectory_rest_model.reference_scatter`); the
        start's ``"auto"`` trust is then split against that value (issue 31 point 2, eleventh round: on stroke-like
        trials the reference's ends are 2.5-3 cm off per repetition and axis, not 1.5 cm). Needs
        ``sigma_data_static_m="auto"``; an option (off).
    """

    sigma_data_mps: float | tuple[float, float, float] = 0.02
    sigma_ref_static_m: float | tuple[float, float, float] = 0.015
    sigma_ref_moving_m: float = 0.10
    sigma_symmetry_m: float | None = 0.02
    sigma_static_vel_mps: float | None = 0.005
    sigma_data_static_m: float | tuple[float, float, float] | str | None = "auto"
    return_to_start: bool | tuple[bool, bool, bool] = (False, False, True)
    align_heading: bool = False
    max_heading_deg: float = 20.0
    velocity_from_static: bool = True
    heading_drift: bool = True
    closure_factor: float | None = 0.5
    start_blend: tuple[bool, bool, bool] = (False, False, False)
    rest_chain: bool = False
    rest_model: str | None = None
    rest_ramp: tuple[bool, bool, bool] = (False, False, False)
    corrected_floor_m: float | None = None
    reference_scatter: tuple[bool, bool, bool] = (False, False, False)
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


@dataclass
class OptimizationResult:
    """Optimised positions (N, 3) m relative to the start, each cost term (dimensionless), heading fix (rad)."""

    position: np.ndarray
    costs: dict[str, float]
    heading_rad: float = 0.0


def _symmetry_rows(t_s: np.ndarray, a_s: tuple[float, float], b_s: tuple[float, float]):
    """Rows p[i] - interp(p, mirror(t_i)) for samples i in phase a (times a_s, s), mirrored onto phase b reversed.

    ``mirror(t) = b_end - u (b_end - b_start)`` with ``u = (t - a_start) / (a_end - a_start)``.
    """
    (ta0, ta1), (tb0, tb1) = a_s, b_s
    idx = np.flatnonzero((t_s >= ta0) & (t_s <= ta1))
    if ta1 <= ta0 or tb1 <= tb0 or len(idx) == 0:
        return None
    u = (t_s[idx] - ta0) / (ta1 - ta0)
    tm = tb1 - u * (tb1 - tb0)
    j = np.clip(np.searchsorted(t_s, tm, side="right") - 1, 0, len(t_s) - 2)
    w = np.clip((tm - t_s[j]) / (t_s[j + 1] - t_s[j]), 0.0, 1.0)
    rows = np.arange(len(idx))
    r = np.concatenate([rows, rows, rows])
    c = np.concatenate([idx, j, j + 1])
    v = np.concatenate([np.ones(len(idx)), -(1.0 - w), -w])
    return r, c, v, idx


def optimize_repetition(
    t_s: np.ndarray,
    initial_m: np.ndarray,
    reference_m: np.ndarray,
    phase_bounds_s: np.ndarray,
    static_mask: np.ndarray,
    params: OptimizationParams = OptimizationParams(),
) -> OptimizationResult:
    """Optimise one repetition.

    t_s: (N,) s; initial_m: (N, 3) ZUPT positions (m, start at 0); reference_m: (N, 3) reference (m);
    phase_bounds_s: (4, 2) reach, lift, return_bottle, return_hand start/end (s); static_mask: (N,) bool.
    """
    t = np.asarray(t_s, dtype=np.float64)
    z = np.asarray(initial_m, dtype=np.float64).reshape(len(t), -1)
    ref = np.asarray(reference_m, dtype=np.float64).reshape(len(t), -1)
    static = np.asarray(static_mask, dtype=bool)
    n, d = z.shape
    if n < 3:
        raise ValueError("a repetition needs at least 3 samples")
    sds = params.sigma_data_static_m
    if isinstance(sds, str):
        sds = None  # "auto" needs the whole trial (reconstruct_repetitions); alone: term off
        params = replace(params, sigma_data_static_m=None)
    sdv = params.sigma_data_mps
    rts = params.return_to_start
    srs = params.sigma_ref_static_m
    if any(isinstance(v, (tuple, list, np.ndarray)) for v in (sdv, rts, srs)):
        for name, value in (("sigma_data_mps", sdv), ("return_to_start", rts), ("sigma_ref_static_m", srs)):
            if isinstance(value, (tuple, list, np.ndarray)) and len(value) != d:
                raise ValueError(f"{name} has {len(value)} values for {d} axes")
        if not isinstance(sds, (tuple, list, np.ndarray)):
            sds = (sds,) * d
    if isinstance(sds, (tuple, list, np.ndarray)):
        if len(sds) != d:
            raise ValueError(f"sigma_data_static_m has {len(sds)} values for {d} axes")
        if params.align_heading and d == 3:
            raise ValueError("per-axis sigma_data_static_m cannot be combined with align_heading")
        parts = [
            optimize_repetition(
                t,
                z[:, j],
                ref[:, j],
                phase_bounds_s,
                static,
                replace(
                    params,
                    sigma_data_static_m=None if v is None else float(v),
                    sigma_data_mps=float(sdv[j]) if isinstance(sdv, (tuple, list, np.ndarray)) else sdv,
                    return_to_start=bool(rts[j]) if isinstance(rts, (tuple, list)) else rts,
                    sigma_ref_static_m=float(srs[j]) if isinstance(srs, (tuple, list, np.ndarray)) else srs,
                ),
            )
            for j, v in enumerate(sds)
        ]
        costs = {k: float(sum(pt.costs.get(k, 0.0) for pt in parts)) for k in parts[0].costs}
        return OptimizationResult(position=np.column_stack([pt.position for pt in parts]), costs=costs)
    heading = 0.0
    if params.align_heading and d == 3 and np.any(static):
        limit = np.radians(params.max_heading_deg)
        heading = float(np.clip(heading_alignment(z, ref, static), -limit, limit))
        z = rotate_about_z(z, heading)
    dt = np.diff(t)
    blocks: list[sp.csr_matrix] = []
    rhs: list[np.ndarray] = []
    names: list[str] = []

    # data: velocity close to the initial (ZUPT) velocity
    diff = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n), format="csr")
    w = np.sqrt(dt) / dt / params.sigma_data_mps
    blocks.append(sp.diags(w) @ diff)
    rhs.append(w[:, None] * np.diff(z, axis=0))
    names.append("data")

    # data, position level: static positions close to the initial estimate's
    dt_s = np.concatenate([[dt[0]], 0.5 * (dt[1:] + dt[:-1]), [dt[-1]]])
    if params.sigma_data_static_m is not None and np.any(static):
        sel = np.flatnonzero(static)
        w = np.sqrt(dt_s[sel]) / params.sigma_data_static_m
        blocks.append(sp.csr_matrix((w, (np.arange(len(sel)), sel)), shape=(len(sel), n)))
        rhs.append(w[:, None] * z[sel])
        names.append("data_static")

    # reference
    dt_s = np.concatenate([[dt[0]], 0.5 * (dt[1:] + dt[:-1]), [dt[-1]]])
    sigma_ref = np.where(static, params.sigma_ref_static_m, params.sigma_ref_moving_m)
    w = np.sqrt(dt_s) / sigma_ref
    blocks.append(sp.diags(w, format="csr"))
    rhs.append(w[:, None] * ref)
    names.append("reference")

    # coupled symmetry: phase 1 <-> phase 4 reversed, phase 2 <-> phase 3 reversed
    if params.sigma_symmetry_m is not None:
        pb = np.asarray(phase_bounds_s, dtype=np.float64).reshape(-1, 2)
        if len(pb) == 4:
            for a, b in ((0, 3), (1, 2)):
                rows = _symmetry_rows(t, tuple(pb[a]), tuple(pb[b]))
                if rows is None:
                    continue
                r, c, v, idx = rows
                m = sp.csr_matrix((v, (r, c)), shape=(len(idx), n))
                w = np.sqrt(dt_s[idx]) / params.sigma_symmetry_m
                blocks.append(sp.diags(w) @ m)
                rhs.append(np.zeros((len(idx), d)))
                names.append(f"symmetry_{a + 1}{b + 1}")

    # smoothness: velocity in static samples
    if params.sigma_static_vel_mps is not None:
        both = static[:-1] & static[1:]
        if np.any(both):
            sel = np.flatnonzero(both)
            w = np.sqrt(dt[sel]) / dt[sel] / params.sigma_static_vel_mps
            blocks.append(sp.diags(w) @ diff[sel])
            rhs.append(np.zeros((len(sel), d)))
            names.append("smoothness")

    a_mat = sp.vstack(blocks, format="csr")
    b_vec = np.vstack(rhs)
    # equality constraints: start at 0, optionally end at the start
    c_rows = [0] + ([n - 1] if params.return_to_start else [])
    c_mat = sp.csr_matrix((np.ones(len(c_rows)), (np.arange(len(c_rows)), c_rows)), shape=(len(c_rows), n))
    d_vec = np.zeros((len(c_rows), d))
    h = (a_mat.T @ a_mat).tocsc()
    kkt = sp.bmat([[2.0 * h, c_mat.T], [c_mat, None]], format="csc")
    rhs_kkt = np.vstack([2.0 * (a_mat.T @ b_vec), d_vec])
    sol = splu(kkt).solve(rhs_kkt)
    p = sol[:n]
    costs = {name: float(np.sum((blk @ p - rb) ** 2)) for name, blk, rb in zip(names, blocks, rhs, strict=True)}
    return OptimizationResult(position=p, costs=costs, heading_rad=heading)


def heading_alignment(
    initial_m: np.ndarray, reference_m: np.ndarray, mask: np.ndarray | None = None, full_circle: bool = False
) -> float:
    """Rotation angle (rad) about z that best maps the initial estimate's x-y onto the reference's (least squares);
    beyond +-90 deg it is 0 unless ``full_circle``."""
    z = np.asarray(initial_m, dtype=np.float64)
    r = np.asarray(reference_m, dtype=np.float64)
    if mask is not None:
        z, r = z[mask], r[mask]
    ok = np.all(np.isfinite(z[:, :2]), axis=1) & np.all(np.isfinite(r[:, :2]), axis=1)
    z, r = z[ok], r[ok]
    num = np.sum(z[:, 0] * r[:, 1] - z[:, 1] * r[:, 0])
    den = np.sum(z[:, 0] * r[:, 0] + z[:, 1] * r[:, 1])
    return float(np.arctan2(num, den)) if den > 0 or full_circle else 0.0


def rotate_about_z(pos: np.ndarray, angle_rad: float) -> np.ndarray:
    """Positions (N, 3) rotated by ``angle_rad`` about the vertical axis."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    out = np.array(pos, dtype=np.float64, copy=True)
    out[:, 0], out[:, 1] = c * pos[:, 0] - s * pos[:, 1], s * pos[:, 0] + c * pos[:, 1]
    return out


def coupled_symmetry_cost(t_s: np.ndarray, pos: np.ndarray, phase_bounds_s: np.ndarray) -> np.ndarray:
    """Thesis eq. 3.2 per axis (m): mean |s(t) - s(mirror(t))| over phases 1 and 2, normalised by duration."""
    t = np.asarray(t_s, dtype=np.float64)
    p = np.asarray(pos, dtype=np.float64).reshape(len(t), -1)
    pb = np.asarray(phase_bounds_s, dtype=np.float64).reshape(-1, 2)
    total = np.zeros(p.shape[1])
    for a, b in ((0, 3), (1, 2)):
        rows = _symmetry_rows(t, tuple(pb[a]), tuple(pb[b]))
        if rows is None:
            continue
        r, c, v, idx = rows
        m = sp.csr_matrix((v, (r, c)), shape=(len(idx), len(t)))
        total += np.sum(np.abs(m @ p), axis=0)
    return total / max(int(np.count_nonzero((t >= pb[0, 0]) & (t <= pb[3, 1]))), 1)
