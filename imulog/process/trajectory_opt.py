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

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from imulog.process.drift import HighpassParams, WaveletParams, highpass, wavelet_detrend
from imulog.process.input_checks import (
    DEFAULT_INPUT_CHECKS,
    InputCheck,
    InputCheckParams,
    apply_checks,
    waypoint_checks,
)
from imulog.process.integration import (
    AnchorParams,
    DdiParams,
    RotatingBiasParams,
    ZuptParams,
    compensate_rotating_bias,
    double_integrate,
    estimate_rotating_bias,
    zupt,
)
from imulog.process.kalman import KalmanParams, kalman_track
from imulog.process.minjerk import (
    R2GReferenceParams,
    R2GWaypoints,
    r2g_reference,
    r2g_waypoints_from_anthropometrics,
    r2g_waypoints_from_positions,
)
from imulog.process.rests import RestParams
from imulog.process.trajectory_checks import CheckParams, bias_check


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
    return_to_start: hard constraint ``p[-1] = p[0]`` (thesis 3.3.7).
    align_heading: before optimising, rotate the initial estimate about the vertical by the angle that best
        matches its static positions to the reference's (closed-form 2D Procrustes; an imulog addition that
        removes the heading error of 6D orientation filters using only the anthropometric waypoints).
    max_heading_deg: the largest heading correction applied (deg); larger fits are clipped.
    """

    sigma_data_mps: float = 0.02
    sigma_ref_static_m: float = 0.015
    sigma_ref_moving_m: float = 0.10
    sigma_symmetry_m: float | None = 0.02
    sigma_static_vel_mps: float | None = 0.005
    sigma_data_static_m: float | tuple[float, float, float] | str | None = "auto"
    return_to_start: bool = True
    align_heading: bool = False
    max_heading_deg: float = 20.0


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
    if isinstance(sds, (tuple, list, np.ndarray)):
        if len(sds) != d:
            raise ValueError(f"sigma_data_static_m has {len(sds)} values for {d} axes")
        if params.align_heading and d == 3:
            raise ValueError("per-axis sigma_data_static_m cannot be combined with align_heading")
        parts = [
            optimize_repetition(
                t, z[:, j], ref[:, j], phase_bounds_s, static, replace(params, sigma_data_static_m=float(v))
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


def heading_alignment(initial_m: np.ndarray, reference_m: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Rotation angle (rad) about z that best maps the initial estimate's x-y onto the reference's (least squares)."""
    z = np.asarray(initial_m, dtype=np.float64)
    r = np.asarray(reference_m, dtype=np.float64)
    if mask is not None:
        z, r = z[mask], r[mask]
    ok = np.all(np.isfinite(z[:, :2]), axis=1) & np.all(np.isfinite(r[:, :2]), axis=1)
    z, r = z[ok], r[ok]
    num = np.sum(z[:, 0] * r[:, 1] - z[:, 1] * r[:, 0])
    den = np.sum(z[:, 0] * r[:, 0] + z[:, 1] * r[:, 1])
    return float(np.arctan2(num, den)) if den > 0 else 0.0


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


# --------------------------------------------------------------------------------------------------
# All methods on one window (a repetition, or a whole trial without repetitions)

METHODS = ("ddi", "zupt", "highpass", "wavelet", "kalman", "zupt_bias", "optimized")
BASELINE = "dedrift"  # double integration with linear velocity de-drift between the window's boundaries


@dataclass(frozen=True)
class TrajectoryParams:
    """Parameters of every reconstruction method (see each class for units)."""

    ddi: DdiParams = DdiParams()
    zupt: ZuptParams = ZuptParams()
    highpass: HighpassParams = HighpassParams()
    wavelet: WaveletParams = WaveletParams()
    kalman: KalmanParams = KalmanParams(zero_velocity=True, smoother=True)
    rotating_bias: RotatingBiasParams = RotatingBiasParams()
    optimized: OptimizationParams = OptimizationParams()
    anchor: AnchorParams = AnchorParams()
    rests: RestParams = RestParams()
    checks: CheckParams = CheckParams()


def reconstruct(
    method: str,
    t_s: np.ndarray,
    acc_mps2: np.ndarray,
    static_mask: np.ndarray | None = None,
    *,
    phase_bounds_s: np.ndarray | None = None,
    waypoints: R2GWaypoints | None = None,
    acc_compensated_mps2: np.ndarray | None = None,
    params: TrajectoryParams = TrajectoryParams(),
) -> np.ndarray:
    """Position (N, 3) m relative to the window start from gravity-free global acceleration (N, 3) m/s^2.

    ``zupt``, ``kalman`` (its zero-velocity updates), ``zupt_bias`` and ``optimized`` need ``static_mask``;
    ``optimized`` also needs the four R2G ``phase_bounds_s`` (4, 2) s and ``waypoints``. ``zupt_bias`` needs
    ``acc_compensated_mps2`` (the acceleration after :func:`compensate_rotating_bias`); ``optimized`` starts
    from ZUPT on it when given, else from ZUPT on ``acc_mps2``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    a = np.asarray(acc_mps2, dtype=np.float64)
    if method == "ddi":
        return double_integrate(a, t, params.ddi)[1]
    if method == BASELINE:  # zero velocity at the window's first and last sample only
        ends = np.zeros(len(t), dtype=bool)
        ends[[0, -1]] = True
        return zupt(a, t, ends, params.zupt)[1]
    if method in ("highpass", "wavelet"):
        pos = double_integrate(a, t, params.ddi)[1]
        if method == "highpass":
            rate = (len(t) - 1) / (t[-1] - t[0])
            out = highpass(pos, rate, params.highpass)
        else:
            out = wavelet_detrend(pos, params.wavelet)
        return out - out[0]
    if static_mask is None:
        raise ValueError(f"method {method!r} needs a static mask")
    if method == "zupt":
        return zupt(a, t, static_mask, params.zupt)[1]
    if method == "kalman":
        res = kalman_track(a, t, static_mask, params.kalman)
        return res.position - res.position[0]
    if method == "zupt_bias":
        if acc_compensated_mps2 is None:
            raise ValueError("method 'zupt_bias' needs the orientation (for the rotating-bias compensation)")
        return zupt(acc_compensated_mps2, t, static_mask, params.zupt)[1]
    if method == "optimized":
        if phase_bounds_s is None or waypoints is None:
            raise ValueError("method 'optimized' needs phase bounds and waypoints")
        base = a if acc_compensated_mps2 is None else np.asarray(acc_compensated_mps2, dtype=np.float64)
        initial = zupt(base, t, static_mask, params.zupt)[1]
        reference = r2g_reference(t, phase_bounds_s, waypoints)
        return optimize_repetition(t, initial, reference, phase_bounds_s, static_mask, params.optimized).position
    raise ValueError(f"unknown method {method!r}; choose from {', '.join((*METHODS, BASELINE))}")


DEFAULT_PARAMS = TrajectoryParams()
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
    sigma_ref_m: float,
    floor_m: float = 0.006,
) -> tuple[float, float, float]:
    """Per-axis error (m) of the initial estimate's static positions, by variance components.

    Over the static samples of every complete repetition, the mean square of (initial - reference) is
    the initial estimate's error variance plus the reference's (``sigma_ref_m``, assumed); the remainder
    (at least ``floor_m``) is the estimate's.
    """
    resid = reference_residuals(t_s, initial_m, static_mask, repetitions, waypoints)
    bad = set(inconsistent_repetitions(resid))
    res = [r for i, r in resid.items() if i not in bad and len(r)]
    if not res:
        return (sigma_ref_m,) * 3
    ms = np.nanmean(np.vstack(res) ** 2, axis=0)
    return tuple(float(np.sqrt(max(v - sigma_ref_m**2, floor_m**2))) for v in ms)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3) of scalar-first unit quaternions (N, 4)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=-2,
    )


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
        if i + 1 < len(keys):
            hi = min(hi, 0.5 * (b[-1, 1] + np.asarray(phase_bounds_s[keys[i + 1]])[0, 0]))
        s = int(np.searchsorted(t, lo, side="left"))
        e = int(np.searchsorted(t, hi, side="right"))
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
    checks: list[InputCheck] | None = None,
    check_params: InputCheckParams = DEFAULT_INPUT_CHECKS,
) -> R2GWaypoints:
    """Waypoints for a trial: h1, h2, h3 (and ``mouth_dx_m``, the mouth's x, and ``bottle_dy_m``, the bottle's
    lateral offset from the start when it is not h2, when present) from the anthropometrics; every
    other coordinate is the median over repetitions of the ZUPT displacement at the phase ends (no optical
    data involved). Without anthropometrics all coordinates come from ZUPT.

    Every given value is checked against the same ZUPT medians (:mod:`imulog.process.input_checks`): ``checks``,
    when given, receives one :class:`InputCheck` per value; a disagreeing value marked approximate is replaced
    by the estimate."""
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
    if anthropometrics:
        try:
            anth = r2g_waypoints_from_anthropometrics(anthropometrics, params)
        except KeyError:
            anth = None
        if anth is not None:
            if "bottle_m" in anthropometrics:
                return anth
            c, s = np.cos(params.heading_rad), np.sin(params.heading_rad)
            rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
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
    return R2GWaypoints(bottle_m=tuple(bottle.tolist()), mouth_m=tuple(mouth.tolist()))


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
    params: TrajectoryParams = TrajectoryParams(),
    reference_params: R2GReferenceParams = DEFAULT_REFERENCE,
    info: dict[str, Any] | None = None,
    baseline: bool = False,
) -> dict[str, np.ndarray]:
    """Every method on every repetition: {method: (N, 3) m relative to each repetition's start, NaN outside}.

    orientation: (N, 4) w,x,y,z sensor-to-frame-of-``acc_mps2`` quaternions; enables ``zupt_bias`` and the
    rotating-bias compensation of the optimisation's initial estimate. ``info``, when given, receives the
    estimated bias (m/s^2), the waypoints, the per-repetition heading corrections and ``checks``: per method
    the verdict of :func:`imulog.process.trajectory_checks.assess` on its assumptions. A rotating-bias estimate
    outside the sensor's physical range (``params.checks``) is refused: ``zupt_bias`` is then ZUPT and the
    optimisation starts from ZUPT. ``baseline``: also return :data:`BASELINE` (linear velocity de-drift
    between each window's first and last sample), the figure every method must beat.
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
        errors = estimate_rotating_bias(a, rot, t, static, params.rotating_bias)
        bias = bias_check(errors.as_dict(), params.checks)
        a_comp = compensate_rotating_bias(a, rot, t, static, errors, params.rotating_bias) if bias["ok"] else None
        if info is not None:
            info["accelerometer_errors"] = {**errors.as_dict(), "applied": bool(bias["ok"])}
    if "optimized" in methods and waypoints is None:
        base = a if a_comp is None else a_comp
        z = np.full((len(t), 3), np.nan)
        for rep in repetitions:
            sl = slice(rep.start, rep.stop)
            z[sl] = zupt(base[sl], t[sl], static[sl], params.zupt)[1]
        input_checks: list[InputCheck] = []
        waypoints = trial_waypoints(anthropometrics, t, z, repetitions, reference_params, input_checks)
        if info is not None and input_checks:
            info["input_checks"] = [c.as_dict() for c in input_checks]
            info["input_warnings"] = [c.line() for c in input_checks if c.disagrees]
    if info is not None and waypoints is not None:
        info["waypoints_m"] = {"bottle": list(waypoints.bottle_m), "mouth": list(waypoints.mouth_m)}
    fallback: set[int] = set()
    if "optimized" in methods:
        base = a if a_comp is None else a_comp
        z = np.full((len(t), 3), np.nan)
        for rep in repetitions:
            sl = slice(rep.start, rep.stop)
            z[sl] = zupt(base[sl], t[sl], static[sl], params.zupt)[1]
        fallback = set(inconsistent_repetitions(reference_residuals(t, z, static, repetitions, waypoints)))
        if params.optimized.sigma_data_static_m == "auto":
            sig = estimate_data_sigma(t, z, static, repetitions, waypoints, params.optimized.sigma_ref_static_m)
            params = replace(params, optimized=replace(params.optimized, sigma_data_static_m=sig))
            if info is not None:
                info["sigma_data_static_m"] = list(sig)
        if info is not None:
            info["optimized_fallback"] = [repetitions[i].index for i in sorted(fallback)]
    if baseline:
        methods = [*methods, BASELINE]
        out[BASELINE] = np.full((len(t), 3), np.nan)
    for i, rep in enumerate(repetitions):
        sl = slice(rep.start, rep.stop)
        for m in methods:
            if m == "optimized" and len(rep.phase_bounds_s) != 4:
                continue
            if m == "optimized" and i in fallback:  # keep the initial estimate
                base = a[sl] if a_comp is None else a_comp[sl]
                out[m][sl] = zupt(base, t[sl], static[sl], params.zupt)[1]
                continue
            out[m][sl] = reconstruct(
                m,
                t[sl],
                a[sl],
                static[sl],
                phase_bounds_s=rep.phase_bounds_s,
                waypoints=waypoints,
                # a refused (unphysical) estimate: zupt_bias is ZUPT on the uncompensated acceleration
                acc_compensated_mps2=a_comp[sl] if a_comp is not None else a[sl] if bias is not None else None,
                params=params,
            )
    if info is not None:
        from imulog.process.trajectory_checks import method_checks

        info["checks"] = method_checks(t, a, a_comp, static, repetitions, out, params, bias)
    return out
