"""Offline 6D orientation by an error-state Kalman filter and Rauch-Tung-Striebel smoother over the whole trial.

What an offline estimator can use and a causal filter cannot: every sample informs every other. State: the
orientation error in the global frame (rad, 3) and the gyroscope bias (rad/s, 3). The gyroscope drives the
nominal orientation; the accelerometer's direction observes the inclination with a noise that grows with the
acceleration disturbance (|‖a‖ - g|) and with the local change of ‖a‖ (so translations and impacts weigh
little); at rest (gyroscope and accelerometer both still over ``rest_s``) the gyroscope observes its own bias.
A linear acceleration state (AR(1), global frame) can absorb slow accelerations. The forward pass is followed by the RTS backward pass, and the smoothed errors are injected into the forward
estimates. Heading is unobservable without a magnetometer: it stays the gyroscope's (z-up, arbitrary heading).

Units: gyr rad/s, acc m/s², rate Hz; noise densities as named (``*_rad_s`` per sample, ``*_rad_s2`` per √s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from imulog.numeric import moving_mean
from imulog.process.rest_runs import static_runs

GRAVITY_M_S2 = 9.81


@dataclass(frozen=True)
class SmootherParams:
    """Noise model of :func:`smooth_orientation` (defaults: a MEMS IMU such as BROAD's, not tuned on one trial).

    ``gyr_noise_rad_s``: gyroscope white noise per sample; ``bias_walk_rad_s2``: bias random walk per √s;
    ``acc_noise``: accelerometer white noise (m/s²) when undisturbed; ``disturbance_gain``: added noise per unit
    of relative disturbance (| |a| - g | / g plus the local change of |a|, over ``smooth_s``), times g;
    ``lin_sd_m_s2``, ``lin_tau_s``: the linear acceleration as an AR(1) process in the global frame (standard
    deviation, time constant; on BROAD a large one trades tilt for acceleration and is worse, docs/orientation.md);
    ``backward``: run the RTS pass (False: the forward filter alone, for comparison);
    ``rest_gyr_rad_s`` / ``rest_acc_m_s2``: rest thresholds (gyroscope norm, deviation of |a| from its local
    mean) held for ``rest_s``; ``rest_bias_noise_rad_s``: how closely the gyroscope equals its bias at rest.
    """

    gyr_noise_rad_s: float = 0.005
    bias_walk_rad_s2: float = 2e-5
    initial_bias_rad_s: float = 0.01
    acc_noise: float = 0.2
    disturbance_gain: float = 1.0
    smooth_s: float = 0.2
    rest_gyr_rad_s: float = 0.03
    rest_acc_m_s2: float = 0.3
    rest_s: float = 1.0
    rest_bias_noise_rad_s: float = 0.01
    backward: bool = True
    lin_sd_m_s2: float = 0.01
    lin_tau_s: float = 0.1


def rest_mask(gyr: np.ndarray, acc: np.ndarray, rate_hz: float, params: SmootherParams) -> np.ndarray:
    """Samples where the sensor is at rest: the gyroscope norm and the accelerometer vector's deviation from its
    local mean (over ``rest_s``; a translation moves it even when |a| stays near g) under their thresholds for at
    least ``rest_s`` (bool, N)."""
    n = max(1, int(round(params.rest_s * rate_hz)))
    local = moving_mean(acc, n)
    still = (np.linalg.norm(gyr, axis=1) < params.rest_gyr_rad_s) & (
        np.linalg.norm(acc - local, axis=1) < params.rest_acc_m_s2
    )
    out = np.zeros(len(still), dtype=bool)
    for a, b in static_runs(still, n):  # runs of at least n samples
        out[a:b] = True
    return out


def acc_direction_noise(acc: np.ndarray, rate_hz: float, params: SmootherParams) -> np.ndarray:
    """Standard deviation (m/s²) of the accelerometer as a measurement of gravity plus the modelled linear
    acceleration, per sample: white noise plus the disturbance (relative to g) times its gain."""
    an = np.linalg.norm(acc, axis=1)
    n = max(1, int(round(params.smooth_s * rate_hz)))
    disturbance = np.abs(an - GRAVITY_M_S2) / GRAVITY_M_S2 + np.abs(an - moving_mean(an, n)) / GRAVITY_M_S2
    return params.acc_noise + params.disturbance_gain * GRAVITY_M_S2 * moving_mean(disturbance, n)


@njit(cache=True)
def _qmul(a, b):
    return np.array(
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    )


@njit(cache=True)
def _qexp(v):
    """Unit quaternion of rotation vector ``v`` (rad)."""
    angle = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if angle < 1e-12:
        q = np.array([1.0, 0.5 * v[0], 0.5 * v[1], 0.5 * v[2]])
    else:
        s = np.sin(0.5 * angle) / angle
        q = np.array([np.cos(0.5 * angle), s * v[0], s * v[1], s * v[2]])
    return q / np.sqrt(np.sum(q * q))


@njit(cache=True)
def _rotmat(q):
    w, x, y, z = q[0], q[1], q[2], q[3]
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


@njit(cache=True)
def _forward_backward(gyr, acc, sigma_acc, rest, q0, dt, q_gyr, q_bias, p_bias0, r_rest, phi, q_lin, lin_sd, backward):
    """Forward error-state filter and RTS pass. State: orientation error (global, rad), gyroscope bias (rad/s),
    linear acceleration in the global frame (m/s², AR(1) with coefficient ``phi``)."""
    n = len(gyr)
    m = 9
    quat = np.empty((n, 4))
    bias = np.empty((n, 3))
    lin_out = np.empty((n, 3))
    p_filt = np.empty((n, m, m))
    f_mats = np.empty((n, m, m))
    p_pred = np.empty((n, m, m))
    correction = np.zeros((n, m))  # the error injected by the update at each sample
    q = q0.copy()
    b = np.zeros(3)
    lin = np.zeros(3)
    p = np.zeros((m, m))
    for i in range(3):
        p[i, i] = 0.1**2
        p[3 + i, 3 + i] = p_bias0**2
        p[6 + i, 6 + i] = lin_sd**2
    eye = np.eye(m)
    g = 9.81
    for k in range(n):
        if k > 0:
            r = _rotmat(q)
            f = np.eye(m)
            f[0:3, 3:6] = -r * dt
            for i in range(3):
                f[6 + i, 6 + i] = phi
            q = _qmul(q, _qexp((gyr[k] - b) * dt))  # the rate at k carries k-1 to k (as VQF and BROAD do)
            lin = phi * lin
            p = f @ p @ f.T
            for i in range(3):
                p[i, i] += q_gyr
                p[3 + i, 3 + i] += q_bias
                p[6 + i, 6 + i] += q_lin
            f_mats[k - 1] = f
        p_pred[k] = p
        dx = np.zeros(m)
        a = acc[k]
        if np.isfinite(sigma_acc[k]) and np.isfinite(a[0] + a[1] + a[2]):
            # R a = g e_z + lin: z = R_est a - g e_z - lin ~ lin_err - g (dtheta x e_z)
            r = _rotmat(q)
            v = r @ a
            z = np.array([v[0] - lin[0], v[1] - lin[1], v[2] - g - lin[2]])
            h = np.zeros((3, m))
            h[0, 1] = -g
            h[1, 0] = g
            for i in range(3):
                h[i, 6 + i] = 1.0
            s = h @ p @ h.T
            for i in range(3):
                s[i, i] += sigma_acc[k] ** 2
            kg = p @ h.T @ np.linalg.inv(s)
            dx += kg @ z
            p = (eye - kg @ h) @ p
        if rest[k]:
            # at rest the gyroscope reads its bias: z = gyr - b, H = [0 I 0]
            h = np.zeros((3, m))
            for i in range(3):
                h[i, 3 + i] = 1.0
            z = gyr[k] - b - dx[3:6]
            s = h @ p @ h.T
            for i in range(3):
                s[i, i] += r_rest
            kg = p @ h.T @ np.linalg.inv(s)
            dx += kg @ z
            p = (eye - kg @ h) @ p
        q = _qmul(_qexp(dx[0:3]), q)  # global-frame error: q_true = exp(dtheta) * q
        b = b + dx[3:6]
        lin = lin + dx[6:9]
        correction[k] = dx
        quat[k] = q
        bias[k] = b
        lin_out[k] = lin
        p_filt[k] = p
    # RTS backward pass over the error state, relative to the filtered trajectory
    ds = np.zeros(m)
    for k in range(n - 2 if backward else -1, -1, -1):
        c = p_filt[k] @ f_mats[k].T @ np.linalg.inv(p_pred[k + 1])
        ds = c @ (ds + correction[k + 1])
        quat[k] = _qmul(_qexp(ds[0:3]), quat[k])
        bias[k] = bias[k] + ds[3:6]
        lin_out[k] = lin_out[k] + ds[6:9]
    return quat, bias, lin_out


def smooth_orientation(
    gyr: np.ndarray, acc: np.ndarray, rate_hz: float, params: SmootherParams = SmootherParams()
) -> tuple[np.ndarray, np.ndarray]:
    """Sensor-to-global quaternions (N, 4; w, x, y, z; z up, arbitrary heading) and gyroscope bias (N, 3, rad/s)
    of a 6D recording (gyr rad/s, acc m/s², uniform ``rate_hz``), smoothed over the whole recording."""
    gyr = np.ascontiguousarray(gyr, dtype=np.float64)
    acc = np.ascontiguousarray(acc, dtype=np.float64)
    if gyr.shape != acc.shape or gyr.ndim != 2 or gyr.shape[1] != 3:
        raise ValueError(f"gyr and acc must both be (N, 3), got {gyr.shape} and {acc.shape}")
    if len(gyr) == 0:
        return np.empty((0, 4)), np.empty((0, 3))
    dt = 1.0 / float(rate_hz)
    sigma = acc_direction_noise(acc, rate_hz, params)
    rest = rest_mask(gyr, acc, rate_hz, params)
    a0 = acc[: max(1, int(rate_hz * 0.5))].mean(axis=0)
    q0 = _tilt_quaternion(a0)
    phi = float(np.exp(-dt / params.lin_tau_s))
    quat, bias, _ = _forward_backward(
        gyr,
        acc,
        sigma,
        rest,
        q0,
        dt,
        (params.gyr_noise_rad_s * dt) ** 2,
        params.bias_walk_rad_s2**2 * dt,
        params.initial_bias_rad_s,
        params.rest_bias_noise_rad_s**2,
        phi,
        params.lin_sd_m_s2**2 * (1.0 - phi**2),
        params.lin_sd_m_s2,
        params.backward,
    )
    return quat, bias


def _tilt_quaternion(acc: np.ndarray) -> np.ndarray:
    """The smallest rotation taking the sensor's measured gravity direction to global z (zero heading)."""
    a = acc / np.linalg.norm(acc)
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(a, z)
    s = np.linalg.norm(axis)
    angle = np.arctan2(s, float(a @ z))
    if s < 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0]) if angle < 1.0 else np.array([0.0, 1.0, 0.0, 0.0])
    axis /= s
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
