"""Madgwick's gradient-descent orientation filter, compiled with numba.

Madgwick, Harrison & Vaidyanathan, "Estimation of IMU and MARG orientation using a gradient
descent algorithm", IEEE ICORR 2011, in the form of Madgwick's reference C implementation
(``MadgwickAHRSupdateIMU`` / ``MadgwickAHRSupdate``). The quaternion rotates sensor-frame vectors
into the global frame (z up; with a magnetometer, global x points to magnetic north, i.e. a
North-West-Up frame, as in the reference code).

The R2G thesis uses ``beta = 0.03`` (rad/s), "the recommended value for dynamic performance".
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["madgwick_imu", "madgwick_marg"]


@njit(cache=True, fastmath=True, nogil=True)
def _imu_kernel(gyr, acc, dt, beta, q0_init, out):  # pragma: no cover - compiled
    q0, q1, q2, q3 = q0_init[0], q0_init[1], q0_init[2], q0_init[3]
    n = gyr.shape[0]
    for i in range(n):
        gx, gy, gz = gyr[i, 0], gyr[i, 1], gyr[i, 2]
        ax, ay, az = acc[i, 0], acc[i, 1], acc[i, 2]
        qd0 = 0.5 * (-q1 * gx - q2 * gy - q3 * gz)
        qd1 = 0.5 * (q0 * gx + q2 * gz - q3 * gy)
        qd2 = 0.5 * (q0 * gy - q1 * gz + q3 * gx)
        qd3 = 0.5 * (q0 * gz + q1 * gy - q2 * gx)
        an = ax * ax + ay * ay + az * az
        if an > 0.0:
            r = 1.0 / np.sqrt(an)
            ax *= r
            ay *= r
            az *= r
            _2q0 = 2.0 * q0
            _2q1 = 2.0 * q1
            _2q2 = 2.0 * q2
            _2q3 = 2.0 * q3
            _4q0 = 4.0 * q0
            _4q1 = 4.0 * q1
            _4q2 = 4.0 * q2
            _8q1 = 8.0 * q1
            _8q2 = 8.0 * q2
            q0q0 = q0 * q0
            q1q1 = q1 * q1
            q2q2 = q2 * q2
            q3q3 = q3 * q3
            s0 = _4q0 * q2q2 + _2q2 * ax + _4q0 * q1q1 - _2q1 * ay
            s1 = _4q1 * q3q3 - _2q3 * ax + 4.0 * q0q0 * q1 - _2q0 * ay - _4q1 + _8q1 * q1q1 + _8q1 * q2q2 + _4q1 * az
            s2 = 4.0 * q0q0 * q2 + _2q0 * ax + _4q2 * q3q3 - _2q3 * ay - _4q2 + _8q2 * q1q1 + _8q2 * q2q2 + _4q2 * az
            s3 = 4.0 * q1q1 * q3 - _2q1 * ax + 4.0 * q2q2 * q3 - _2q2 * ay
            sn = s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3
            if sn > 0.0:
                r = beta / np.sqrt(sn)
                qd0 -= r * s0
                qd1 -= r * s1
                qd2 -= r * s2
                qd3 -= r * s3
        q0 += qd0 * dt
        q1 += qd1 * dt
        q2 += qd2 * dt
        q3 += qd3 * dt
        r = 1.0 / np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        q0 *= r
        q1 *= r
        q2 *= r
        q3 *= r
        out[i, 0] = q0
        out[i, 1] = q1
        out[i, 2] = q2
        out[i, 3] = q3


@njit(cache=True, fastmath=True, nogil=True)
def _marg_kernel(gyr, acc, mag, dt, beta, q0_init, out):  # pragma: no cover - compiled
    q0, q1, q2, q3 = q0_init[0], q0_init[1], q0_init[2], q0_init[3]
    n = gyr.shape[0]
    for i in range(n):
        gx, gy, gz = gyr[i, 0], gyr[i, 1], gyr[i, 2]
        ax, ay, az = acc[i, 0], acc[i, 1], acc[i, 2]
        mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
        qd0 = 0.5 * (-q1 * gx - q2 * gy - q3 * gz)
        qd1 = 0.5 * (q0 * gx + q2 * gz - q3 * gy)
        qd2 = 0.5 * (q0 * gy - q1 * gz + q3 * gx)
        qd3 = 0.5 * (q0 * gz + q1 * gy - q2 * gx)
        an = ax * ax + ay * ay + az * az
        mn = mx * mx + my * my + mz * mz
        if an > 0.0 and mn > 0.0 and np.isfinite(mn):
            r = 1.0 / np.sqrt(an)
            ax *= r
            ay *= r
            az *= r
            r = 1.0 / np.sqrt(mn)
            mx *= r
            my *= r
            mz *= r
            # earth-frame direction of the field h = q m q*, reference b = (|h_xy|, 0, h_z)
            # (Madgwick 2011 eqs. 45-46; the factor-2 slip of the reference C code, BROAD issue #1,
            # is not reproduced)
            h0 = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
            hx = h0 * mx + 2.0 * (q1 * q2 - q0 * q3) * my + 2.0 * (q1 * q3 + q0 * q2) * mz
            hy = 2.0 * (q1 * q2 + q0 * q3) * mx + (q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3) * my
            hy += 2.0 * (q2 * q3 - q0 * q1) * mz
            bz = 2.0 * (q1 * q3 - q0 * q2) * mx + 2.0 * (q2 * q3 + q0 * q1) * my
            bz += (q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3) * mz
            bx = np.sqrt(hx * hx + hy * hy)
            # objective (eq. 31) and J^T f (eqs. 32, 34)
            f1 = 2.0 * (q1 * q3 - q0 * q2) - ax
            f2 = 2.0 * (q0 * q1 + q2 * q3) - ay
            f3 = 2.0 * (0.5 - q1 * q1 - q2 * q2) - az
            f4 = 2.0 * bx * (0.5 - q2 * q2 - q3 * q3) + 2.0 * bz * (q1 * q3 - q0 * q2) - mx
            f5 = 2.0 * bx * (q1 * q2 - q0 * q3) + 2.0 * bz * (q0 * q1 + q2 * q3) - my
            f6 = 2.0 * bx * (q0 * q2 + q1 * q3) + 2.0 * bz * (0.5 - q1 * q1 - q2 * q2) - mz
            s0 = -2.0 * q2 * f1 + 2.0 * q1 * f2 - 2.0 * bz * q2 * f4
            s0 += (-2.0 * bx * q3 + 2.0 * bz * q1) * f5 + 2.0 * bx * q2 * f6
            s1 = 2.0 * q3 * f1 + 2.0 * q0 * f2 - 4.0 * q1 * f3 + 2.0 * bz * q3 * f4
            s1 += (2.0 * bx * q2 + 2.0 * bz * q0) * f5 + (2.0 * bx * q3 - 4.0 * bz * q1) * f6
            s2 = -2.0 * q0 * f1 + 2.0 * q3 * f2 - 4.0 * q2 * f3 + (-4.0 * bx * q2 - 2.0 * bz * q0) * f4
            s2 += (2.0 * bx * q1 + 2.0 * bz * q3) * f5 + (2.0 * bx * q0 - 4.0 * bz * q2) * f6
            s3 = 2.0 * q1 * f1 + 2.0 * q2 * f2 + (-4.0 * bx * q3 + 2.0 * bz * q1) * f4
            s3 += (-2.0 * bx * q0 + 2.0 * bz * q2) * f5 + 2.0 * bx * q1 * f6
            sn = s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3
            if sn > 0.0:
                r = beta / np.sqrt(sn)
                qd0 -= r * s0
                qd1 -= r * s1
                qd2 -= r * s2
                qd3 -= r * s3
        elif an > 0.0:
            r = 1.0 / np.sqrt(an)
            ax *= r
            ay *= r
            az *= r
            s0 = 4.0 * q0 * q2 * q2 + 2.0 * q2 * ax + 4.0 * q0 * q1 * q1 - 2.0 * q1 * ay
            s1 = 4.0 * q1 * q3 * q3 - 2.0 * q3 * ax + 4.0 * q0 * q0 * q1 - 2.0 * q0 * ay - 4.0 * q1
            s1 += 8.0 * q1 * q1 * q1 + 8.0 * q1 * q2 * q2 + 4.0 * q1 * az
            s2 = 4.0 * q0 * q0 * q2 + 2.0 * q0 * ax + 4.0 * q2 * q3 * q3 - 2.0 * q3 * ay - 4.0 * q2
            s2 += 8.0 * q2 * q1 * q1 + 8.0 * q2 * q2 * q2 + 4.0 * q2 * az
            s3 = 4.0 * q1 * q1 * q3 - 2.0 * q1 * ax + 4.0 * q2 * q2 * q3 - 2.0 * q2 * ay
            sn = s0 * s0 + s1 * s1 + s2 * s2 + s3 * s3
            if sn > 0.0:
                r = beta / np.sqrt(sn)
                qd0 -= r * s0
                qd1 -= r * s1
                qd2 -= r * s2
                qd3 -= r * s3
        q0 += qd0 * dt
        q1 += qd1 * dt
        q2 += qd2 * dt
        q3 += qd3 * dt
        r = 1.0 / np.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        q0 *= r
        q1 *= r
        q2 *= r
        q3 *= r
        out[i, 0] = q0
        out[i, 1] = q1
        out[i, 2] = q2
        out[i, 3] = q3


def _prep(a: np.ndarray, n: int | None, what: str) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or (n is not None and a.shape[0] != n):
        raise ValueError(f"{what} must have shape (N, 3), got {a.shape}")
    return a


def madgwick_imu(
    gyr_rad_s: np.ndarray,
    acc: np.ndarray,
    dt_s: float,
    beta: float = 0.03,
    q0: np.ndarray | None = None,
) -> np.ndarray:
    """6D Madgwick filter: (N, 4) sensor-to-global quaternions (z up, heading from ``q0``).

    ``acc`` in any unit (only its direction is used), ``gyr_rad_s`` in rad/s, ``dt_s`` the sample
    period in s, ``beta`` the gradient-step gain in rad/s, ``q0`` the initial orientation (identity
    by default). The output quaternion at sample ``i`` includes sample ``i``.
    """
    gyr = _prep(gyr_rad_s, None, "gyr")
    acc = _prep(acc, len(gyr), "acc")
    init = np.ascontiguousarray(np.array([1.0, 0, 0, 0]) if q0 is None else q0, dtype=np.float64)
    out = np.empty((len(gyr), 4))
    _imu_kernel(gyr, acc, float(dt_s), float(beta), init / np.linalg.norm(init), out)
    return out


def madgwick_marg(
    gyr_rad_s: np.ndarray,
    acc: np.ndarray,
    mag: np.ndarray,
    dt_s: float,
    beta: float = 0.03,
    q0: np.ndarray | None = None,
) -> np.ndarray:
    """9D Madgwick filter: (N, 4) sensor-to-global quaternions, global x = magnetic north, z up.

    Samples whose magnetometer reading is zero or NaN fall back to the 6D update.
    """
    gyr = _prep(gyr_rad_s, None, "gyr")
    acc = _prep(acc, len(gyr), "acc")
    mag = _prep(mag, len(gyr), "mag")
    init = np.ascontiguousarray(np.array([1.0, 0, 0, 0]) if q0 is None else q0, dtype=np.float64)
    out = np.empty((len(gyr), 4))
    _marg_kernel(gyr, acc, mag, float(dt_s), float(beta), init / np.linalg.norm(init), out)
    return out
