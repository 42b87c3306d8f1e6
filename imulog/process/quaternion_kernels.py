"""Compiled (numba) row loops of :func:`imulog.process.quaternion.rotate` and :func:`~.quaternion.multiply` for
long (N, 4) / (N, 3) arrays (an hour of 100 Hz samples and more): one pass, no temporaries.

Imported lazily by :mod:`imulog.process.quaternion` only for arrays of at least ``MIN_ROWS`` rows, so short
calls never load numba. The expressions are numpy's, term for term and in the same order, compiled without
fast-math (no reassociation, no fused multiply-add), so the results are bit-identical to the numpy path
(``tests/test_quaternion.py`` compares both). A quaternion argument of one row is used for every row.
"""

from __future__ import annotations

import numpy as np
from numba import njit

MIN_ROWS = 4096  # below: the numpy expressions (no numba import); quaternion._MIN_ROWS is this value


@njit(cache=True, nogil=True)
def rotate_rows(q, v, out):  # pragma: no cover - compiled
    """``out[i] = q[i] * v[i] * q[i]^-1`` (``q[0]`` for every row when ``q`` has one row)."""
    one = q.shape[0] == 1
    for i in range(v.shape[0]):
        k = 0 if one else i
        w, x, y, z = q[k, 0], q[k, 1], q[k, 2], q[k, 3]
        vx, vy, vz = v[i, 0], v[i, 1], v[i, 2]
        tx = 2.0 * (y * vz - z * vy)
        ty = 2.0 * (z * vx - x * vz)
        tz = 2.0 * (x * vy - y * vx)
        out[i, 0] = vx + w * tx + (y * tz - z * ty)
        out[i, 1] = vy + w * ty + (z * tx - x * tz)
        out[i, 2] = vz + w * tz + (x * ty - y * tx)
    return out


@njit(cache=True, nogil=True)
def multiply_rows(p, q, out):  # pragma: no cover - compiled
    """``out[i] = p[i] * q[i]`` (Hamilton product; an argument of one row is used for every row)."""
    p1 = p.shape[0] == 1
    q1 = q.shape[0] == 1
    for i in range(out.shape[0]):
        a = 0 if p1 else i
        b = 0 if q1 else i
        pw, px, py, pz = p[a, 0], p[a, 1], p[a, 2], p[a, 3]
        qw, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        out[i, 0] = pw * qw - px * qx - py * qy - pz * qz
        out[i, 1] = pw * qx + px * qw + py * qz - pz * qy
        out[i, 2] = pw * qy - px * qz + py * qw + pz * qx
        out[i, 3] = pw * qz + px * qy - py * qx + pz * qw
    return out


def rows_of(a: np.ndarray, n: int) -> np.ndarray | None:
    """``a`` ((k,) or (1 or n, k)) as a C-contiguous float64 (1 or n, k) array for the kernels, or None when its
    shape does not fit."""
    if a.ndim == 1:
        a = a.reshape(1, -1)
    if a.ndim != 2 or a.shape[0] not in (1, n):
        return None
    return np.ascontiguousarray(a, dtype=np.float64)
