"""Offline gyroscope self-calibration before VQF offline: the ``vqf_gyrocal`` orientation backend.

What an offline estimator can use and VQF does not: the whole trial at once, to estimate the gyroscope's
sensitivity and axis misalignment (a 3x3 correction ``M``, true rate = ``M @ (gyr - bias)``) from the data itself. VQF
offline integrates the bias-corrected gyroscope into an almost-inertial frame ``I``, low-passes the accelerometer
in ``I`` (where gravity is constant) and tilts the result onto it. A sensitivity error ``E`` makes ``I`` drift by
``dtheta(t) = integral of R_I(s) E w(s) ds`` (rad), and gravity seen in ``I`` moves by ``g0 x dtheta(t)``
(first order): linear in the nine entries of ``E``. This module fits them by least squares on the low-passed
accelerometer in ``I`` (VQF's own low-pass, ``tau_s``), next to a constant gravity, a constant error of VQF's bias
estimate and a piecewise-linear drift (knots every ``knot_s``), with a Gaussian prior of ``prior_sd`` on each
entry; then runs ``vqf.offlineVQF`` on the corrected gyroscope. With little rotation (a translation trial) the data say
little and the prior keeps ``M`` near the identity.

Units: gyr rad/s, acc m/s^2, rate Hz, times s; ``M`` and ``prior_sd`` dimensionless (0.002 = 0.2 %).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit
from scipy import signal

from imulog.process import quaternion as quat


@dataclass(frozen=True)
class GyroCalParams:
    """Settings of :func:`estimate_gyro_correction` (chosen on the shared BROAD trials 02, 05, 14 only).

    ``tau_s``: time constant of the accelerometer low-pass in the almost-inertial frame (VQF's ``tauAcc``, 3 s);
    ``knot_s``: spacing of the piecewise-linear drift of that frame (s); ``prior_sd``: standard deviation of the
    prior on each entry of the sensitivity/misalignment error (fraction); ``fit_rate_hz``: rate the fit is
    evaluated at (block means, then the low-pass, at that rate); ``min_duration_s``: shorter recordings are left
    uncalibrated (``M`` = identity).
    """

    tau_s: float = 3.0
    knot_s: float = 10.0
    prior_sd: float = 0.002
    fit_rate_hz: float = 10.0
    min_duration_s: float = 30.0


@njit(cache=True)
def integrate_gyro(gyr: np.ndarray, dt: float) -> np.ndarray:  # pragma: no cover - compiled
    """Sensor-to-frame quaternions (N, 4) of the gyroscope integrated from the identity (rad/s, s); the rate at k
    carries k-1 to k, and the first sample is applied too (as ``vqf.offlineVQF``'s ``integrateGyr``)."""
    n = gyr.shape[0]
    out = np.empty((n, 4))
    w0, x0, y0, z0 = 1.0, 0.0, 0.0, 0.0
    for k in range(n):
        gx, gy, gz = gyr[k, 0], gyr[k, 1], gyr[k, 2]
        norm = np.sqrt(gx * gx + gy * gy + gz * gz)
        if norm > 1e-12:
            c = np.cos(0.5 * norm * dt)
            s = np.sin(0.5 * norm * dt) / norm
            pw, px, py, pz = c, s * gx, s * gy, s * gz
            w1 = w0 * pw - x0 * px - y0 * py - z0 * pz
            x1 = w0 * px + x0 * pw + y0 * pz - z0 * py
            y1 = w0 * py - x0 * pz + y0 * pw + z0 * px
            z1 = w0 * pz + x0 * py - y0 * px + z0 * pw
            m = np.sqrt(w1 * w1 + x1 * x1 + y1 * y1 + z1 * z1)
            w0, x0, y0, z0 = w1 / m, x1 / m, y1 / m, z1 / m
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = w0, x0, y0, z0
    return out


def lowpass_zero_phase(x: np.ndarray, rate_hz: float, tau_s: float) -> np.ndarray:
    """VQF's accelerometer low-pass (2nd-order Butterworth, cut-off sqrt(2)/(2 pi tau) Hz) run forwards and
    backwards along axis 0 (zero phase, as ``offlineVQF``)."""
    fc = np.sqrt(2.0) / (2.0 * np.pi * tau_s)
    sos = signal.butter(2, min(fc, 0.45 * rate_hz), fs=rate_hz, output="sos")
    return signal.sosfiltfilt(sos, x, axis=0)


def block_mean(x: np.ndarray, step: int) -> np.ndarray:
    """Means of consecutive blocks of ``step`` rows (the last, partial block dropped)."""
    n = (len(x) // step) * step
    return x[:n].reshape(n // step, step, *x.shape[1:]).mean(axis=1)


def _design(r_i: np.ndarray, w: np.ndarray, g0: np.ndarray, dt: float, step: int, knot_s: float) -> np.ndarray:
    """Regressors (M, 3, P) of gravity in the almost-inertial frame as block means over ``step`` samples: 3
    constant, 9 sensitivity entries (``g0 x cumsum(R_I[:, :, i] w_j) dt``, column 3 + 3 i + j), 3 for a constant
    error of the bias estimate (``g0 x cumsum(R_I[:, :, i]) dt``: its drift turns with the sensor, so a ramp in
    the frame cannot absorb it) and 2 drift ramps per knot perpendicular to ``g0``."""
    m = len(w) // step
    cols = [np.broadcast_to(np.eye(3)[i], (m, 3)) for i in range(3)]
    for i in range(3):
        for j in range(3):
            cols.append(np.cross(g0, block_mean(np.cumsum(r_i[:, :, i] * w[:, j : j + 1], axis=0) * dt, step)))
    for i in range(3):
        cols.append(np.cross(g0, block_mean(np.cumsum(r_i[:, :, i], axis=0) * dt, step)))
    t = (np.arange(m) + 0.5) * step * dt
    u1 = np.cross(g0, [1.0, 0.0, 0.0] if abs(g0[0]) < 0.9 * np.linalg.norm(g0) else [0.0, 1.0, 0.0])
    u1 /= np.linalg.norm(u1)
    u2 = np.cross(g0 / np.linalg.norm(g0), u1)
    for start in np.arange(0.0, t[-1], knot_s):
        ramp = np.clip((t - start) / knot_s, 0.0, 1.0)[:, None]
        cols.extend([ramp * u1, ramp * u2])
    return np.stack(cols, axis=-1)


def estimate_gyro_correction(
    gyr: np.ndarray, acc: np.ndarray, rate_hz: float, bias: np.ndarray, params: GyroCalParams = GyroCalParams()
) -> np.ndarray:
    """The 3x3 correction ``M`` (true rate = ``M @ (gyr - bias)``) fitted over the whole recording; ``bias``
    (N, 3 or 3, rad/s) is the gyroscope bias estimate (e.g. VQF offline's). Identity for recordings shorter than
    ``params.min_duration_s``."""
    gyr = np.asarray(gyr, dtype=np.float64)
    acc = np.asarray(acc, dtype=np.float64)
    dt = 1.0 / float(rate_hz)
    if len(gyr) * dt < params.min_duration_s:
        return np.eye(3)
    w = np.ascontiguousarray(gyr - bias)
    q_i = integrate_gyro(w, dt)
    r_i = quat.to_rotation_matrix(q_i)
    step = max(1, int(round(rate_hz / params.fit_rate_hz)))
    fit_hz = rate_hz / step
    # block means over `step` samples (0.1 s), then VQF's low-pass at the fit rate, on data and regressors alike:
    # the model stays linear, and the filter runs on 1/step of the samples
    a_i = lowpass_zero_phase(block_mean(quat.rotate(q_i, acc), step), fit_hz, params.tau_s)
    g0 = a_i.mean(axis=0)
    design = lowpass_zero_phase(_design(r_i, w, g0, dt, step, params.knot_s), fit_hz, params.tau_s)
    n_fixed = 3
    a = design.reshape(-1, design.shape[-1])
    y = a_i.reshape(-1)
    ata = np.einsum("ij,ik->jk", a, a)  # einsum, not BLAS: threaded BLAS spins on a loaded machine (docs)
    aty = np.einsum("ij,i->j", a, y)
    penalty = np.zeros(a.shape[1])
    x = ridge_solve(ata, aty, penalty)
    # Gaussian prior on the sensitivity entries; the residual is correlated over about tau: its variance counts
    # once per tau, not once per decimated sample
    noise_var = float(np.mean((y - np.einsum("ij,j->i", a, x)) ** 2)) * fit_hz * params.tau_s
    penalty[n_fixed : n_fixed + 9] = noise_var / params.prior_sd**2
    x = ridge_solve(ata, aty, penalty)
    return np.eye(3) + x[n_fixed : n_fixed + 9].reshape(3, 3)


def ridge_solve(ata: np.ndarray, aty: np.ndarray, penalty: np.ndarray) -> np.ndarray:
    """``argmin |A x - y|^2 + sum(penalty x^2)`` from the normal equations ``A^T A``, ``A^T y``, with the columns
    scaled to unit norm first (and a 1e-10 relative ridge, so columns the data do not determine stay at 0)."""
    scale = np.sqrt(np.maximum(np.diag(ata), 1e-300))
    m = ata / np.outer(scale, scale) + np.diag(penalty / scale**2 + 1e-10)
    return np.linalg.solve(m, aty / scale) / scale


def vqf_gyrocal(
    gyr: np.ndarray,
    acc: np.ndarray,
    rate_hz: float,
    mag: np.ndarray | None = None,
    params: GyroCalParams = GyroCalParams(),
    info: dict[str, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Sensor-to-global quaternions (N, 4) of VQF offline run on the self-calibrated gyroscope, and the
    correction ``M`` (3x3). 6D without ``mag`` (z up, arbitrary heading), ENU with it.

    ``info``, when given, receives what was estimated and applied (:func:`correction_record`): ``M``, the mean of
    VQF offline's bias estimate the correction turns about (rad/s) and whether the recording was long enough to
    fit ``M`` (``params.min_duration_s``)."""
    from vqf import offlineVQF

    gyr = np.ascontiguousarray(gyr, dtype=np.float64)
    acc = np.ascontiguousarray(acc, dtype=np.float64)
    if gyr.shape != acc.shape or gyr.ndim != 2 or gyr.shape[1] != 3:
        raise ValueError(f"gyr and acc must both be (N, 3), got {gyr.shape} and {acc.shape}")
    dt = 1.0 / float(rate_hz)
    bias = offlineVQF(gyr, acc, None, dt)["bias"]
    m = estimate_gyro_correction(gyr, acc, rate_hz, bias, params)
    if info is not None:
        info.update(correction_record(m, bias, len(gyr) * dt >= params.min_duration_s))
    corrected = np.ascontiguousarray((gyr - bias) @ m.T + bias)  # VQF estimates (and removes) the bias again
    mag = None if mag is None else np.ascontiguousarray(mag, dtype=np.float64)
    out = offlineVQF(corrected, acc, mag, dt)
    return np.asarray(out["quat6D" if mag is None else "quat9D"]), m


def correction_record(m: np.ndarray, bias: np.ndarray, fitted: bool) -> dict[str, Any]:
    """The gyroscope correction as recorded (JSON): ``matrix`` ``M`` (3x3, true rate = ``M @ (gyr - bias)``,
    dimensionless), ``bias_rad_s`` the mean of the bias estimate (N, 3 or 3, rad/s) it is applied about, and
    ``fitted`` (False: the recording was shorter than ``GyroCalParams.min_duration_s``, ``M`` is the identity)."""
    mean_bias = np.asarray(bias, dtype=np.float64).reshape(-1, 3).mean(axis=0)
    return {
        "matrix": np.asarray(m, dtype=np.float64).tolist(),
        "bias_rad_s": mean_bias.tolist(),
        "fitted": bool(fitted),
    }
