"""Dead reckoning from gravity-free global acceleration: direct double integration and ZUPT.

All functions are pure numpy. Inputs: acceleration ``acc_mps2`` (N,) or (N, D) in m/s^2 in a
fixed (global) frame with gravity removed, sample times ``t_s`` (N,) in seconds (need not be
uniform). Outputs: velocity in m/s and position in m, starting at zero.

* Direct double integration (DDI): trapezoidal rule twice (MATLAB ``cumtrapz``, as in the R2G
  thesis 3.3.4), optionally after subtracting the mean acceleration of the window (the thesis's
  gravity removal: "removing the mean value of the acceleration during the R2G task").
* ZUPT (Bai et al. 2023, 3.1): velocity is reset to zero in static samples; between two rests the
  residual velocity at the next rest is assumed to come from a constant acceleration offset, so a
  straight line from 0 (at the previous rest) to that residual is subtracted (linear de-drift).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from imulog.param_rules import check_rules
from imulog.process.rest_runs import movement_runs, rest_bias, static_runs, through_movement


def _as_2d(x: np.ndarray) -> tuple[np.ndarray, bool]:
    a = np.asarray(x, dtype=np.float64)
    if a.ndim == 1:
        return a[:, None], True
    if a.ndim != 2:
        raise ValueError(f"expected (N,) or (N, D) array, got shape {a.shape}")
    return a, False


def _check_time(t_s: np.ndarray, n: int) -> np.ndarray:
    t = np.asarray(t_s, dtype=np.float64)
    if t.shape != (n,):
        raise ValueError(f"t_s must have shape ({n},), got {t.shape}")
    if n > 1 and np.any(np.diff(t) <= 0):
        raise ValueError("t_s must be strictly increasing")
    return t


def cumtrapz(y: np.ndarray, t_s: np.ndarray, initial: float | np.ndarray = 0.0) -> np.ndarray:
    """Cumulative trapezoidal integral of ``y`` (N,) or (N, D) over ``t_s`` (N,) s, starting at ``initial``."""
    a, squeeze = _as_2d(y)
    t = _check_time(t_s, len(a))
    out = np.empty_like(a)
    out[0] = initial
    if len(a) > 1:
        dt = np.diff(t)[:, None]
        out[1:] = out[0] + np.cumsum(0.5 * (a[1:] + a[:-1]) * dt, axis=0)
    return out[:, 0] if squeeze else out


@dataclass(frozen=True)
class DdiParams:
    """Direct double integration. remove_mean: subtract the window's mean acceleration (m/s^2) before integrating,
    as the R2G thesis does for gravity removal (exact for a constant offset when the window starts and ends at
    rest: the true acceleration then integrates to zero)."""

    remove_mean: bool = True
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def double_integrate(
    acc_mps2: np.ndarray, t_s: np.ndarray, params: DdiParams = DdiParams()
) -> tuple[np.ndarray, np.ndarray]:
    """Direct double integration. Returns ``(velocity m/s, position m)``, both zero at ``t_s[0]``."""
    a, squeeze = _as_2d(acc_mps2)
    if params.remove_mean:
        a = a - np.nanmean(a, axis=0)
    vel = cumtrapz(a, t_s)
    pos = cumtrapz(vel, t_s)
    if squeeze:
        return vel[:, 0], pos[:, 0]
    return vel, pos


@dataclass(frozen=True)
class ZuptParams:
    """Zero-velocity update with linear velocity de-drift (Bai et al. 2023).

    dedrift: subtract, in each movement between two rests, the straight line that brings the integrated velocity
        back to zero at the next rest (assumes a constant acceleration offset).
    min_static_samples: static runs shorter than this many samples are ignored (treated as moving).
    """

    dedrift: bool = True
    min_static_samples: int = 1
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def zupt_velocity(
    acc_mps2: np.ndarray, t_s: np.ndarray, static_mask: np.ndarray, params: ZuptParams = ZuptParams()
) -> np.ndarray:
    """Velocity (m/s) integrated from ``acc_mps2`` with zero-velocity updates in ``static_mask`` samples.

    A movement (samples between two static runs) is integrated from zero at the last static sample
    before it. With ``dedrift`` the velocity reached at the first static sample after it is removed
    linearly in time over the movement. A movement running to the end of the window is not de-drifted
    (no rest to observe its drift); one starting at the first sample starts from zero velocity.
    """
    a, squeeze = _as_2d(acc_mps2)
    n = len(a)
    t = _check_time(t_s, n)
    mask = np.asarray(static_mask, dtype=bool)
    if mask.shape != (n,):
        raise ValueError(f"static_mask must have shape ({n},), got {mask.shape}")
    runs = static_runs(mask, params.min_static_samples)
    static = np.zeros(n, dtype=bool)
    for s, e in runs:
        static[s:e] = True
    vel = np.zeros_like(a)
    # movement segments: maximal runs of non-static samples, integrated from the preceding sample
    moving = static_runs(~static)
    for s, e in moving:
        i0 = max(s - 1, 0)  # last static sample (zero velocity) or the first sample
        i1 = min(e, n - 1)  # first static sample after the movement (or the last sample)
        seg = cumtrapz(a[i0 : i1 + 1], t[i0 : i1 + 1])
        if params.dedrift and e < n:
            frac = (t[i0 : i1 + 1] - t[i0]) / (t[i1] - t[i0])
            seg = seg - frac[:, None] * seg[-1]
        vel[s:e] = seg[s - i0 : e - i0]
    return vel[:, 0] if squeeze else vel


def zupt(
    acc_mps2: np.ndarray, t_s: np.ndarray, static_mask: np.ndarray, params: ZuptParams = ZuptParams()
) -> tuple[np.ndarray, np.ndarray]:
    """ZUPT dead reckoning. Returns ``(velocity m/s, position m)``; position starts at zero."""
    vel = zupt_velocity(acc_mps2, t_s, static_mask, params)
    return vel, cumtrapz(vel, t_s)


def rest_ramp(
    acc_mps2: np.ndarray, t_s: np.ndarray, static_mask: np.ndarray, rest_s: float, axes: Sequence[bool]
) -> np.ndarray:
    """The acceleration (N, 3) m/s^2 with, on the ``axes`` given, each movement's offset taken off as a line in time
    from the mean over the last ``rest_s`` s of the rest before it to the mean over the first ``rest_s`` s of the
    rest after it (issue 31 point 2, eighth round). Linear de-drift (:func:`zupt_velocity`) assumes one constant
    offset per movement; when the orientation's tilt error differs between the two rests (the anchoring spreads
    that difference over the movement), gravity leaks as an offset that moves from one rest's value to the other's,
    and a ramp ``d`` left over a movement of ``T`` s puts the displacement off by ``d T^2 / 12``. Movements
    without a rest on both sides are left as they are."""
    a = np.array(acc_mps2, dtype=np.float64, copy=True)
    t = _check_time(t_s, len(a))
    static = np.asarray(static_mask, dtype=bool)
    use = np.flatnonzero(np.asarray(axes, dtype=bool))
    if not len(use):
        return a
    for s, e in movement_runs(static):
        lo = int(np.searchsorted(t, t[s - 1] - rest_s, side="left"))
        hi = int(np.searchsorted(t, t[e] + rest_s, side="right"))
        before = a[lo:s][static[lo:s]][:, use]
        after = a[e:hi][static[e:hi]][:, use]
        if not (len(before) and len(after)) or not (np.all(np.isfinite(before)) and np.all(np.isfinite(after))):
            continue
        c0, c1 = before.mean(axis=0), after.mean(axis=0)
        frac = (t[s - 1 : e + 1] - t[s - 1]) / (t[e] - t[s - 1])
        a[s - 1 : e + 1, use] -= c0 + frac[:, None] * (c1 - c0)
    return a


# --------------------------------------------------------------------------------------------------
# Rotating accelerometer errors (an imulog addition to Bai's ZUPT)
#
# A constant accelerometer bias b (sensor frame, m/s^2) appears in the global frame as R(t) b; scale and
# axis-misalignment errors E (3x3, dimensionless) add R(t) E f(t) with f ~ R(t)^T g the specific force,
# dominated by gravity. At rest the orientation filter absorbs both into a small tilt error, so the global
# acceleration is ~0 there; once the sensor rotates, the errors turn with it and leave
#     e(t) - e(t_m),   e(t) = R(t) b + g R(t) E R(t)^T z,
# which is not constant and so is not removed by the linear de-drift. Each movement between rests must
# integrate to zero velocity; with c_m the mean global acceleration in the rest just before movement m,
#     integral_m (a_global - c_m) dt = integral_m (e(t) - e(t_m)) dt,
# three equations per movement, linear in the 3 (+ 9) unknowns, solved by least squares over the trial.


@dataclass(frozen=True)
class RotatingBiasParams:
    """Estimation of sensor-frame accelerometer errors from the ZUPT closure of every movement.

    rest_s: length (s) of the rest just before a movement whose mean global acceleration is c_m.
    gravity_coupled: also fit the 3x3 scale/misalignment matrix acting on gravity (12 unknowns, else 3).
    gravity_mps2: gravity magnitude (m/s^2) for the gravity-coupled term.
    min_movements: fewer complete movements than this (at least 2 per unknown triple) give no estimate.
    outlier_factor: refit without the movements whose closure residual (3D norm, m/s) exceeds this many times
        the median movement's (never below ``min_movements``; None, the default: one plain least squares). A
        movement the model cannot close (a long continuous swing such as the alignment wave, a rest missed inside
        it) otherwise dominates the 12 unknowns (issue 31: `default` subject 52's start was 1.5 cm off in z). 4 is
        no condition worse on development trials, but not the default: the repetition flags' precision on their
        calibration set falls to 0.497 with it at the current drift threshold (docs/accuracy.md).
    outlier_refits: at most this many refits, each judging the residuals of the previous fit (1: the plain
        fit's residuals only; more peels off borderline movements once the gross ones are gone).
    shrink: apply the compensation on each global axis only as far as it stands out of its own uncertainty
        (:func:`axis_shrinkage`: per axis, the positive-part James-Stein / Wiener factor ``1 - noise / total``
        of the velocity it removes per movement; False: in full). Issue 31 point 2: on calibrated trials the
        x / y compensation is mostly noise and put the start above plain ZUPT.
    calibration_prior: when the accelerometer was already corrected from the trial's own rests
        (:mod:`imulog.process.acc_rest_calibration`, applied), fit the unknowns with a Gaussian prior at zero whose
        covariance is that correction's joint posterior (bias m/s^2, matrix dimensionless, correlations kept), the
        closure rows weighted by the plain fit's residual standard deviation (m/s): the compensation then fits only
        what the correction may have left (issue 31 point 2, ninth round; an option).
    held_out: apply the compensation on each global axis only as far as it predicts the closures of movements it
        was not fitted on (:func:`held_out_weight`: leave one movement out, the share of that axis's closure
        variance the fit predicts, 0..1; False: in full). Issue 31 point 2, tenth round: on a corrected
        accelerometer the fit still closes errors that are not the sensor's (mostly in z), which cost the start
        against plain ZUPT; an option.
    """

    rest_s: float = 0.5
    gravity_coupled: bool = True
    gravity_mps2: float = 9.81
    min_movements: int = 8
    outlier_factor: float | None = None
    outlier_refits: int = 1
    shrink: bool = False
    calibration_prior: bool = False
    held_out: bool = False
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


@dataclass
class AccelerometerErrors:
    """Sensor-frame accelerometer bias (3,) m/s^2 and gravity-coupled error matrix (3, 3) (dimensionless), with
    their least-squares standard errors (same shapes and units; NaN when there was no estimate)."""

    bias_mps2: np.ndarray
    matrix: np.ndarray
    bias_se_mps2: np.ndarray | None = None
    matrix_se: np.ndarray | None = None
    axis_z: np.ndarray | None = None  # (3,) per global axis: the compensation in units of its own noise
    axis_weight: np.ndarray | None = None  # (3,) 0..1: how much of it each global axis gets (None: all)

    def as_dict(self) -> dict:
        out = {"bias_mps2": self.bias_mps2.tolist(), "matrix": self.matrix.tolist()}
        for key in ("axis_z", "axis_weight"):
            if getattr(self, key) is not None:
                out[key] = np.round(getattr(self, key), 4).tolist()
        if self.bias_se_mps2 is not None:
            out["bias_se_mps2"] = np.round(self.bias_se_mps2, 6).tolist()
        if self.matrix_se is not None:
            out["matrix_se"] = np.round(self.matrix_se, 6).tolist()
        return out


def _error_terms(rot: np.ndarray, params: RotatingBiasParams) -> np.ndarray:
    """Regressors (n, 3, 3 or 12): d e(t) / d [b, vec(E)] at each sample."""
    parts = [rot]
    if params.gravity_coupled:
        up = rot[:, 2, :]  # R^T z: the vertical in the sensor frame
        parts.append(params.gravity_mps2 * (rot[:, :, :, None] * up[:, None, None, :]).reshape(len(rot), 3, 9))
    return np.concatenate(parts, axis=2)


def _rest_mean(a: np.ndarray, t: np.ndarray, static: np.ndarray, s: int, rest_s: float) -> np.ndarray | None:
    rest = np.flatnonzero(static[:s] & (t[:s] >= t[s - 1] - rest_s))
    return np.nanmean(a[rest], axis=0) if len(rest) else None


def estimate_rotating_bias(
    acc_mps2: np.ndarray,
    rot_sensor_to_global: np.ndarray,
    t_s: np.ndarray,
    static_mask: np.ndarray,
    params: RotatingBiasParams = RotatingBiasParams(),
    prior_cov: np.ndarray | None = None,
) -> AccelerometerErrors:
    """Sensor-frame accelerometer errors from gravity-free global acceleration (N, 3) m/s^2 and the
    sensor-to-global rotation matrices (N, 3, 3) used to compute it. ``prior_cov`` (12, 12): covariance of a zero-mean
    Gaussian prior on the unknowns (bias m/s^2, then the matrix row by row, dimensionless; its first (3, 3) without
    ``gravity_coupled``), :func:`prior_fit`; None: the plain least squares."""
    a = np.asarray(acc_mps2, dtype=np.float64)
    r = np.asarray(rot_sensor_to_global, dtype=np.float64)
    t = _check_time(t_s, len(a))
    static = np.asarray(static_mask, dtype=bool)
    k = 12 if params.gravity_coupled else 3
    rows, rhs = [], []
    for s, e in movement_runs(static):
        c = _rest_mean(a, t, static, s, params.rest_s)
        if c is None:
            continue
        i0, i1 = s - 1, e
        terms = _error_terms(r[i0 : i1 + 1], params)
        g = cumtrapz((terms - terms[0]).reshape(len(terms), -1), t[i0 : i1 + 1])[-1].reshape(3, k)
        v = cumtrapz(a[i0 : i1 + 1] - c, t[i0 : i1 + 1])[-1]
        if np.all(np.isfinite(g)) and np.all(np.isfinite(v)):
            rows.append(g)
            rhs.append(v)
    zero = AccelerometerErrors(np.zeros(3), np.zeros((3, 3)))
    if len(rows) < max(params.min_movements, k // 3 * 2):
        return zero
    keep = _closing_movements(rows, rhs, params, max(params.min_movements, k // 3 * 2))
    design, y = np.vstack([rows[i] for i in keep]), np.concatenate([rhs[i] for i in keep])
    x, *_ = np.linalg.lstsq(design, y, rcond=None)
    cov = _covariance(design, y - design @ x)
    if prior_cov is not None:
        x, cov = prior_fit(design, y, x, np.asarray(prior_cov, dtype=np.float64)[:k, :k])
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    matrix = x[3:].reshape(3, 3) if params.gravity_coupled else np.zeros((3, 3))
    matrix_se = se[3:].reshape(3, 3) if params.gravity_coupled else np.zeros((3, 3))
    z = axis_significance(np.stack([rows[i] for i in keep]), x, cov)
    weight = shrinkage_weight(z) if params.shrink else None
    if params.held_out:
        prior = None if prior_cov is None else np.asarray(prior_cov, dtype=np.float64)[:k, :k]
        held = held_out_weight(np.stack([rows[i] for i in keep]), np.stack([rhs[i] for i in keep]), prior)
        weight = held if weight is None else weight * held
    return AccelerometerErrors(x[:3], matrix, se[:3], matrix_se, axis_z=z, axis_weight=weight)


def prior_fit(
    design: np.ndarray, y: np.ndarray, x_plain: np.ndarray, prior_cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The unknowns (k,) and their posterior covariance (k, k) under a zero-mean Gaussian prior of covariance
    ``prior_cov`` (k, k): the closure rows ``design`` (n, k) m/s per unit and ``y`` (n,) m/s weighted by the
    residual standard deviation of the plain fit ``x_plain`` (m/s; without degrees of freedom the plain fit is
    returned)."""
    n, k = design.shape
    if n <= k:
        return x_plain, np.full((k, k), np.nan)
    resid = y - design @ x_plain
    w2 = 1.0 / max(float(resid @ resid / (n - k)), 1e-24)
    normal = design.T @ design * w2 + np.linalg.pinv(prior_cov, hermitian=True)
    cov = np.linalg.pinv(normal, hermitian=True)
    return cov @ (design.T @ y) * w2, cov


def held_out_weight(rows: np.ndarray, rhs: np.ndarray, prior_cov: np.ndarray | None = None) -> np.ndarray:
    """Per global axis (3,), the share (0..1) of the movements' closure variance that the compensation predicts for
    movements it was not fitted on: ``max(0, 1 - sum_m (v_mj - rows[m, j] x_(-m))^2 / sum_m v_mj^2)``, with
    ``x_(-m)`` the fit (plain, or under the prior ``prior_cov`` (k, k), :func:`prior_fit`) without movement m.

    rows (M, 3, k): each movement's closure velocity (m/s) per unit of the k unknowns; rhs (M, 3): the closure
    velocities (m/s) to explain. 0 where predicting zero does as well (the fit closes what is not the sensor's:
    noise, a tilt or a velocity at the rests), 1 where the held-out closures are predicted exactly; 1 on every axis
    with too few movements to leave one out (fewer than two per unknown), where nothing can be judged."""
    r = np.asarray(rows, dtype=np.float64)
    v = np.asarray(rhs, dtype=np.float64)
    m, _, k = r.shape
    if m - 1 < max(2, k // 3 * 2):
        return np.ones(3)
    pred = np.zeros_like(v)
    for i in range(m):
        rest = np.arange(m) != i
        design, y = r[rest].reshape(-1, k), v[rest].reshape(-1)
        x, *_ = np.linalg.lstsq(design, y, rcond=None)
        if prior_cov is not None:
            x, _ = prior_fit(design, y, x, prior_cov)
        pred[i] = r[i] @ x
    total = np.sum(v**2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = 1.0 - np.sum((v - pred) ** 2, axis=0) / total
    return np.clip(np.where(total > 0, share, 0.0), 0.0, 1.0)


def axis_significance(rows: np.ndarray, x: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Per global axis (3,), the compensation's size in units of its own uncertainty (dimensionless).

    rows (M, 3, k): each movement's velocity (m/s) per unit of the k unknowns ``x`` (their covariance ``cov``,
    (k, k)); the compensation removes ``d_mj = rows[m, j] @ x`` from movement m on axis j, with variance
    ``s_mj^2 = rows[m, j] cov rows[m, j]^T``. Returns ``sqrt(sum_m d_mj^2 / sum_m s_mj^2)``: about 1 when the
    estimate is pure noise on that axis (NaN covariance, too few movements: inf, taken as significant)."""
    d = np.einsum("mjk,k->mj", rows, x)
    var = np.einsum("mjk,kl,mjl->mj", rows, cov, rows)
    total, noise = np.sum(d**2, axis=0), np.sum(var, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.sqrt(total / noise)
    return np.where(np.isfinite(z), z, np.inf)


def shrinkage_weight(z: np.ndarray) -> np.ndarray:
    """Per axis, the share (0..1) of a compensation of significance ``z`` (:func:`axis_significance`) to apply:
    ``max(0, 1 - 1 / z^2)``, the positive-part James-Stein (Wiener) factor, the share of its mean square that
    exceeds what noise alone gives; the least-squares-optimal shrinkage, with no threshold to choose."""
    z = np.asarray(z, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.clip(1.0 - 1.0 / z**2, 0.0, 1.0)


def _closing_movements(
    rows: list[np.ndarray], rhs: list[np.ndarray], params: RotatingBiasParams, least: int
) -> list[int]:
    """Indices of the movements the fit keeps: all, or (``params.outlier_factor``) those whose residual norm
    (m/s) is at most that factor times the median's, refitting up to ``params.outlier_refits`` times while the
    set changes (never fewer than ``least``)."""
    keep = list(range(len(rows)))
    if params.outlier_factor is None:
        return keep
    for _ in range(params.outlier_refits):
        x, *_ = np.linalg.lstsq(np.vstack([rows[i] for i in keep]), np.concatenate([rhs[i] for i in keep]), rcond=None)
        norm = np.array([np.linalg.norm(r @ x - v) for r, v in zip(rows, rhs, strict=True)])
        new = [i for i in range(len(rows)) if norm[i] <= params.outlier_factor * float(np.median(norm[keep]))]
        if new == keep or len(new) < least:
            break
        keep = new
    return keep


def _covariance(design: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Least-squares covariance of the unknowns: (A^T A)^-1 * RSS / (rows - unknowns) (NaN without dof)."""
    n, k = design.shape
    if n <= k:
        return np.full((k, k), np.nan)
    return np.linalg.pinv(design.T @ design) * float(residual @ residual) / (n - k)


def compensate_rotating_bias(
    acc_mps2: np.ndarray,
    rot_sensor_to_global: np.ndarray,
    t_s: np.ndarray,
    static_mask: np.ndarray,
    errors: AccelerometerErrors,
    params: RotatingBiasParams = RotatingBiasParams(),
) -> np.ndarray:
    """Global acceleration with ``c_m + e(t) - e(t_m)`` removed in every movement (rests unchanged)."""
    a = np.array(acc_mps2, dtype=np.float64, copy=True)
    r = np.asarray(rot_sensor_to_global, dtype=np.float64)
    t = _check_time(t_s, len(a))
    static = np.asarray(static_mask, dtype=bool)
    x = np.concatenate([errors.bias_mps2, errors.matrix.reshape(-1)]) if params.gravity_coupled else errors.bias_mps2
    for s, e in movement_runs(static):
        c = _rest_mean(a, t, static, s, params.rest_s)
        if c is None:
            c = np.zeros(3)
        err = _error_terms(r[s - 1 : e], params) @ x
        if errors.axis_weight is not None:
            err = err * errors.axis_weight
        a[s:e] = a[s:e] - c - (err[1:] - err[0])
    return a


@dataclass(frozen=True)
class AnchorParams:
    """Parameters of :func:`rest_anchored_orientation` (imulog addition, issue 19).

    enabled: re-integrate the orientation through every movement from the gyroscope (in the trajectory step).
    bias_window_s: the gyroscope bias is the mean over at most this much (s) of the rest before a movement.
    max_movement_s: longer movements (continuous motion: no rest to anchor to) keep the filter's orientation.
    spread: how the end discrepancy is spread over the movement: ``"time"`` (linear in time, right for a
        gyroscope bias), ``"angle"`` (in proportion to the angle turned so far, right for a scale error) or
        ``"mixed"`` (their mean: neither error is known to dominate); ``"none"``: the gyroscope's orientation through
        the whole movement, the next rest's tilt taken up at that rest (a diagnostic of the eighth round of issue 31
        point 2: the tilt the filter gives each rest differs from rest to rest, and spreading that difference makes
        gravity leak as a ramp the linear de-drift cannot remove).
    heading: ``"filter"``: every rest keeps the filter's orientation (its heading too); ``"gyroscope"``: a rest
        keeps the filter's tilt (averaged over the rest, constant through it) but the heading the gyroscope
        carried through the movement before it (issue 31): a 6D filter's heading drifts with the residual
        gyroscope bias about the vertical, which depends on the hand's pose (the mouth hold turns it), while the
        bias measured at each rest leaves the integrated heading within ~0.01 deg/s. Each chain is then turned
        about the vertical so its mean heading equals the filter's (the frame the align step fitted). The default
        since 2026-12-07 (before: ``"filter"``; docs/accuracy.md, issue 31 point 2).
    restart: with ``heading="gyroscope"``, restart the heading chain at the rests the caller marks (the trajectory
        step: where it may cut a window, :func:`imulog.process.anchor_heading.restart_rests`), each chain turned
        onto the filter's mean heading on its own, so the step's windows equal the whole computation; False: one
        chain over the whole recording (not window-invariant; kept for the paired comparison).
    rest_tilt: with ``heading="gyroscope"``, each rest's tilt: ``"filter"`` (the filter's, averaged over the rest)
        or ``"accelerometer"`` (the direction the accelerometer measures, averaged over the rest; an option, issue
        31 point 2: an offline filter's tilt still converges through a rest next to a fast rotation, by up to 3 deg
        on the simulated ``stroke`` trial of subject 44, and its mean over the rest is then off by 0.7-1.1 deg).
    """

    enabled: bool = True
    bias_window_s: float = 0.5
    max_movement_s: float = 15.0
    spread: str = "mixed"
    heading: str = "gyroscope"
    restart: bool = True
    rest_tilt: str = "filter"
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def rest_anchored_orientation(
    q_s2g: np.ndarray,
    gyr_rad_s: np.ndarray,
    t_s: np.ndarray,
    static_mask: np.ndarray,
    params: AnchorParams = AnchorParams(),
    restart: np.ndarray | None = None,
    acc: np.ndarray | None = None,
) -> np.ndarray:
    """Orientation (N, 4) w,x,y,z sensor-to-global re-integrated through every movement and anchored at its rests.

    A 6-axis filter corrects its tilt towards the accelerometer also while the hand accelerates, so its
    orientation is worst exactly when the position integral needs it most. At rest it is right (the
    accelerometer then measures gravity only). Each movement between two rests is therefore integrated from the
    gyroscope (``gyr_rad_s`` rad/s, bias = mean over the preceding rest, trapezoidal increments) starting at the
    filter's orientation at the last static sample, and the discrepancy with the filter's orientation at the
    next rest (a world-frame rotation ``delta``) is spread linearly in time over the movement, the way ZUPT's
    de-drift spreads the velocity error. Static samples keep ``q_s2g``. ``t_s`` seconds, ``static_mask`` (N,) True
    at zero velocity; samples with NaN gyroscope keep the filter's orientation. ``restart`` (N,) bool: the rests
    where the heading chain of ``params.heading="gyroscope"`` restarts (:mod:`imulog.process.anchor_heading`).
    ``acc`` (N, 3) m/s^2: the accelerometer in the sensor frame, needed by ``params.rest_tilt="accelerometer"``.
    """
    q = np.asarray(q_s2g, dtype=np.float64)
    gyr = np.asarray(gyr_rad_s, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    static = np.asarray(static_mask, dtype=bool)
    out = q.copy()
    if not params.enabled or len(q) < 3:
        return out
    if params.rest_tilt not in ("filter", "accelerometer"):
        raise ValueError(f"AnchorParams.rest_tilt must be 'filter' or 'accelerometer', got {params.rest_tilt!r}")
    if params.rest_tilt == "accelerometer" and (acc is None or params.heading != "gyroscope"):
        raise ValueError("AnchorParams.rest_tilt='accelerometer' needs heading='gyroscope' and the accelerometer")
    if params.heading == "gyroscope":
        from imulog.process.anchor_heading import heading_through_rests

        up = acc if params.rest_tilt == "accelerometer" else None
        return heading_through_rests(q, gyr, t, static, params, restart if params.restart else None, up)
    for a, b in movement_runs(static):
        a, b = int(a), int(b)
        if a == 0 or b >= len(q) or t[b] - t[a - 1] > params.max_movement_s:
            continue
        w = gyr[a - 1 : b + 1]
        if not np.all(np.isfinite(w)):
            continue
        bias = rest_bias(gyr, t, static, a, params.bias_window_s)
        end = None if params.spread == "none" else q[b]
        out[a - 1 : b + 1] = through_movement(q[a - 1], w, t[a - 1 : b + 1], bias, end, params.spread)
    return out
