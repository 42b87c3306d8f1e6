"""The accelerometer's bias and sensitivity from a trial's own rests (issue 31 point 2, ninth round).

At rest k a still accelerometer reads ``f_k = M g u_k + b``: gravity (``g`` m/s^2) along the unit direction ``u_k``
in the sensor frame, a sensitivity matrix ``M`` (scale and misalignment) and a bias ``b`` (m/s^2). An orientation
filter makes the biased reading vertical at every rest, so it cannot see ``b``; but between two rests the gyroscope
gives the sensor's rotation ``D_k`` (sensor frame of rest k to that of rest k + 1, integrated over a few seconds with
the bias of the rest before taken off: :func:`imulog.process.rest_runs.through_movement`), and gravity must follow
it, ``u_{k+1} = D_k^T u_k``. A bias does not turn with the sensor, so over rests at several wrist orientations
(home, bottle, mouth) it is told apart from gravity.

The fit (:func:`estimate`): unknowns ``b``, ``M`` (the identity, a per-axis scale or a whole matrix:
:attr:`AccRestParams.model`) and each rest's ``u_k`` (two angles about the reading's own direction); weighted least
squares over the rests' readings (within the rest's own standard error, at least ``reading_sd_mps2``), the links
between consecutive rests (within ``gyro_angle_sd_rad`` plus ``gyro_scale_sd`` of the angle turned) and priors
toward zero bias (``bias_prior_mps2``) and the identity sensitivity (``scale_prior``, ``misalignment_prior_deg``).
The posterior covariance is the inverse normal matrix, inflated by the reduced chi-square when it is above 1. The
result is applied only when identifiable (:attr:`AccRestCalibration.reason` says why not). Without ``M`` the bias
absorbs the sensor's scale error at the trial's poses and its standard deviation is far too small (docs/accuracy.md,
ninth round). Pure numpy / scipy; times in s, accelerations in m/s^2, rates in rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from imulog.param_rules import check_rules
from imulog.process.calibration import GRAVITY_M_S2, AxisCalibration
from imulog.process.rest_runs import rest_bias, static_runs, through_movement


@dataclass(frozen=True)
class AccRestParams:
    """Parameters of :func:`estimate` (units in the names).

    enabled: estimate and apply it (off: the accelerometer as recorded).
    model: what is estimated besides gravity's direction at each rest: ``"bias"``; ``"scale"``, the bias and a
        per-axis scale; ``"matrix"``, the bias and a full 3x3 sensitivity matrix (scale and misalignment).
    min_rest_s: shortest rest used (s), after ``trim_s`` is cut from both ends (s).
    max_rest_sd_mps2: a rest whose readings vary more than this (3D standard deviation) is not still: left out.
    min_rests: fewest rests for an estimate.
    min_spread_deg: smallest RMS angle (deg) of the rests' gravity directions about their mean direction.
    max_gap_s: rests further apart than this (s) are not linked by the gyroscope.
    bias_prior_mps2: prior standard deviation of each bias component around zero (m/s^2).
    scale_prior: prior standard deviation of each scale around 1 (fraction).
    misalignment_prior_deg: prior standard deviation of each off-diagonal sensitivity (deg; ``"matrix"``).
    reading_sd_mps2: floor of a rest's mean reading's standard error (m/s^2; tremor, slow tilt within a rest).
    gyro_angle_sd_rad: the gyroscope's rotation error between two rests (rad), plus ``gyro_scale_sd`` of the
        angle turned (its scale and misalignment).
    gyro_bias_window_s: the gyroscope's bias is its mean over at most this long (s) at the end of the rest before.
    max_bias_sd_mps2: identifiable when every bias component's posterior standard deviation is below this (0.1: a
        third of the prior's; with the matrix model the drinking task's rests leave 0.05-0.07).
    """

    enabled: bool = False
    model: str = "matrix"
    min_rest_s: float = 0.3
    trim_s: float = 0.1
    max_rest_sd_mps2: float = 0.15
    min_rests: int = 6
    min_spread_deg: float = 15.0
    max_gap_s: float = 10.0
    bias_prior_mps2: float = 0.3
    scale_prior: float = 0.01
    misalignment_prior_deg: float = 0.5
    reading_sd_mps2: float = 0.02
    gyro_angle_sd_rad: float = 0.005
    gyro_scale_sd: float = 0.01
    gyro_bias_window_s: float = 1.0
    max_bias_sd_mps2: float = 0.1
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


MODELS = {"bias": 0, "scale": 3, "matrix": 9}  # sensitivity unknowns besides the bias


@dataclass
class AccRestCalibration:
    """What :func:`estimate` found: bias (3,) m/s^2 and sensitivity matrix (3, 3) (the identity for the model
    ``"bias"``) with their posterior standard deviations (m/s^2; dimensionless, an entry the model does not estimate
    at its prior's) and their joint posterior ``covariance`` (correlations kept: a combination the rests determine, such
    as the error along gravity at the trial's poses, is known far better than either part); ``applied`` False with a
    one-line ``reason`` when not identifiable."""

    bias_mps2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    matrix: np.ndarray = field(default_factory=lambda: np.eye(3))
    bias_sd_mps2: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))
    matrix_sd: np.ndarray = field(default_factory=lambda: np.full((3, 3), np.inf))
    covariance: np.ndarray | None = None  # (12, 12): bias m/s^2, then the matrix's deviation from I row by row
    rests: int = 0
    spread_deg: float = 0.0
    applied: bool = False
    reason: str = ""

    def axis_calibration(self) -> AxisCalibration:
        """``calibrated = matrix^-1 @ (raw - bias)`` as :class:`imulog.process.calibration.AxisCalibration`; the
        identity where not applied."""
        if not self.applied:
            return AxisCalibration()
        return AxisCalibration(bias=self.bias_mps2.copy(), matrix=np.linalg.inv(self.matrix))

    def apply(self, acc_mps2: np.ndarray) -> np.ndarray:
        """The corrected accelerometer (N, 3) m/s^2 (unchanged where not applied)."""
        return self.axis_calibration().apply(acc_mps2)

    def as_dict(self) -> dict:
        """The run's provenance record (plain floats)."""
        return {
            "applied": self.applied,
            "reason": self.reason,
            "bias_mps2": [round(float(x), 5) for x in self.bias_mps2],
            "bias_sd_mps2": [round(float(x), 5) for x in self.bias_sd_mps2],
            "matrix_sd": [[round(float(x), 6) for x in row] for row in self.matrix_sd],
            "matrix": [[round(float(x), 6) for x in row] for row in self.matrix],
            "rests": self.rests,
            "spread_deg": round(float(self.spread_deg), 2),
        }


def rest_readings(
    acc_mps2: np.ndarray, gyr_rad_s: np.ndarray, t_s: np.ndarray, static: np.ndarray, params: AccRestParams
) -> tuple[np.ndarray, np.ndarray, list[tuple[int, np.ndarray, float]]]:
    """The still rests' mean readings (K, 3) m/s^2 and standard errors (K,) m/s^2, and the gyroscope's links
    ``[(k, D_k (3, 3), angle rad)]`` from rest k to rest k + 1 (those at most ``max_gap_s`` apart)."""
    acc = np.asarray(acc_mps2, dtype=np.float64)
    gyr = np.asarray(gyr_rad_s, dtype=np.float64)
    t = np.asarray(t_s, dtype=np.float64)
    mask = np.asarray(static, dtype=bool)
    rate = (len(t) - 1) / max(t[-1] - t[0], 1e-9)
    trim = int(round(params.trim_s * rate))
    means, ses, spans = [], [], []
    for s, e in static_runs(mask):
        a, b = s + trim, e - trim
        if (b - a) / rate < params.min_rest_s:
            continue
        seg = acc[a:b]
        seg = seg[np.all(np.isfinite(seg), axis=1)]
        if len(seg) < 3:
            continue
        sd = float(np.sqrt(seg.var(axis=0).sum()))
        if sd > params.max_rest_sd_mps2:
            continue
        means.append(seg.mean(axis=0))
        ses.append(max(sd / np.sqrt(len(seg)), params.reading_sd_mps2))
        spans.append((int(a), int(b), int(e)))
    from imulog.process import quaternion as quat

    links = []
    for k in range(len(spans) - 1):
        _, b0, e0 = spans[k]
        a1 = spans[k + 1][0]
        if t[a1] - t[b0 - 1] > params.max_gap_s:
            continue
        sl = slice(b0 - 1, a1 + 1)
        w = gyr[sl]
        if not np.all(np.isfinite(w)):
            continue
        bias = rest_bias(gyr, t, mask, e0, params.gyro_bias_window_s)
        q = through_movement(np.array([1.0, 0.0, 0.0, 0.0]), w, t[sl], bias, None, "time")[-1]
        links.append((k, quat.to_rotation_matrix(q), float(quat.angle(q))))
    return np.asarray(means).reshape(-1, 3), np.asarray(ses), links


def _tangents(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (K, 3) orthogonal to each row of ``u`` (K, 3) and to each other."""
    helper = np.where(np.abs(u[:, [0]]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(u, e1)


def spread_deg(u: np.ndarray) -> float:
    """RMS angle (deg) of unit directions ``u`` (K, 3) about their mean direction."""
    m = u.mean(axis=0)
    m /= max(np.linalg.norm(m), 1e-12)
    return float(np.degrees(np.sqrt(np.mean(np.arccos(np.clip(u @ m, -1.0, 1.0)) ** 2))))


def fit(
    means: np.ndarray,
    ses: np.ndarray,
    links: list[tuple[int, np.ndarray, float]],
    params: AccRestParams,
    gravity_mps2: float = GRAVITY_M_S2,
) -> AccRestCalibration:
    """Bias and scale from the rests' mean readings ``means`` (K, 3) m/s^2 with standard errors ``ses`` (K,)
    and the gyroscope's ``links`` (:func:`rest_readings`); identifiability as in :class:`AccRestParams`."""
    from scipy.optimize import least_squares

    f = np.asarray(means, dtype=np.float64).reshape(-1, 3)
    n = len(f)
    out = AccRestCalibration(rests=n)
    if n < params.min_rests:
        out.reason = f"{n} still rests, fewer than {params.min_rests}"
        return out
    u0 = f / np.linalg.norm(f, axis=1, keepdims=True)
    out.spread_deg = spread_deg(u0)
    if out.spread_deg < params.min_spread_deg:
        out.reason = (
            f"the rests' gravity directions spread {out.spread_deg:.1f} deg, less than {params.min_spread_deg:g}"
        )
        return out
    e1, e2 = _tangents(u0)
    if params.model not in MODELS:
        raise ValueError(f"unknown accelerometer model {params.model!r}; choose one of {', '.join(MODELS)}")
    ns = MODELS[params.model]
    prior = np.full(ns, params.scale_prior)
    if ns == 9:  # off-diagonal entries: misalignment
        prior[[1, 2, 3, 5, 6, 7]] = np.radians(params.misalignment_prior_deg)
    w_f = 1.0 / np.asarray(ses, dtype=np.float64)[:, None]
    idx = np.array([k for k, _, _ in links], dtype=np.int64)
    rot_t = np.array([d.T for _, d, _ in links]).reshape(-1, 3, 3)
    w_l = 1.0 / np.array([params.gyro_angle_sd_rad + params.gyro_scale_sd * a for _, _, a in links])[:, None]

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = x[3 : 3 + ns]
        m = np.eye(3) + (np.diag(e) if ns == 3 else e.reshape(3, 3) if ns == 9 else 0.0)
        al = x[3 + ns :].reshape(n, 2)
        u = u0 + al[:, [0]] * e1 + al[:, [1]] * e2
        return x[:3], m, u / np.linalg.norm(u, axis=1, keepdims=True)

    def residuals(x: np.ndarray) -> np.ndarray:
        b, m, u = unpack(x)
        r = [((f - gravity_mps2 * u @ m.T - b) * w_f).ravel()]
        if len(idx):
            pred = np.einsum("kij,kj->ki", rot_t, u[idx])
            r.append(((u[idx + 1] - pred) * w_l).ravel())
        r.append(b / params.bias_prior_mps2)
        r.append(x[3 : 3 + ns] / prior)
        return np.concatenate(r)

    sol = least_squares(residuals, np.zeros(3 + ns + 2 * n), method="lm")
    dof = max(len(sol.fun) - len(sol.x), 1)
    chi2 = float(sol.fun @ sol.fun) / dof
    cov = np.linalg.pinv(sol.jac.T @ sol.jac) * max(chi2, 1.0)
    b, m, _ = unpack(sol.x)
    out.bias_mps2, out.matrix = b, m
    out.bias_sd_mps2 = np.sqrt(np.maximum(np.diag(cov)[:3], 0.0))
    out.matrix_sd = _matrix_sd(np.sqrt(np.maximum(np.diag(cov)[3 : 3 + ns], 0.0)), params)
    out.covariance = _joint_covariance(cov[: 3 + ns, : 3 + ns], out.matrix_sd, ns)
    worst = float(out.bias_sd_mps2.max())
    if worst > params.max_bias_sd_mps2:
        out.reason = f"bias standard deviation {worst:.3f} m/s^2, above {params.max_bias_sd_mps2:g}"
        return out
    out.applied = True
    return out


def _matrix_sd(sd: np.ndarray, params: AccRestParams) -> np.ndarray:
    """The sensitivity matrix's standard deviations (3, 3) from the fitted ones ``sd`` (0, 3 or 9 entries); an
    entry the model does not fit keeps its prior's (``scale_prior``, ``misalignment_prior_deg`` in rad)."""
    out = np.full((3, 3), np.radians(params.misalignment_prior_deg))
    np.fill_diagonal(out, params.scale_prior)
    if len(sd) == 3:
        np.fill_diagonal(out, sd)
    elif len(sd) == 9:
        out = sd.reshape(3, 3).copy()
    return out


def _joint_covariance(cov: np.ndarray, matrix_sd: np.ndarray, ns: int) -> np.ndarray:
    """The (12, 12) posterior covariance of the bias (m/s^2) and the matrix's deviation from the identity (row by
    row) from the fit's ``cov`` (3 + ``ns`` unknowns); an entry the model does not fit is independent at its
    prior's variance (``matrix_sd``)."""
    out = np.diag(np.concatenate([np.zeros(3), np.ravel(matrix_sd) ** 2]))
    idx = np.arange(3) if ns == 0 else np.r_[0:3, 3 + 4 * np.arange(3)] if ns == 3 else np.arange(12)
    out[np.ix_(idx, idx)] = cov
    return out


def estimate(
    acc_mps2: np.ndarray,
    gyr_rad_s: np.ndarray,
    t_s: np.ndarray,
    static: np.ndarray,
    params: AccRestParams = AccRestParams(),
) -> AccRestCalibration:
    """The accelerometer's bias (and scale) from the rests of ``static`` (N,) bool with the gyroscope
    ``gyr_rad_s`` (N, 3) rad/s between them; ``acc_mps2`` (N, 3) m/s^2 raw, ``t_s`` (N,) s."""
    means, ses, links = rest_readings(acc_mps2, gyr_rad_s, t_s, static, params)
    return fit(means, ses, links, params)
