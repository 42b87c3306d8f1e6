"""Vectorised unit-quaternion utilities (scalar-first ``w, x, y, z``).

Convention (see :mod:`imulog.model`): a quaternion ``q`` describing a sensor's orientation rotates
sensor-frame vectors into the global frame, ``v_global = q * v_sensor * q^-1``
(:func:`rotate`). Composition follows the Hamilton product: ``q_a_to_c = q_b_to_c * q_a_to_b``.

Every function accepts a single quaternion of shape ``(4,)`` or a stack ``(N, 4)`` and broadcasts
one against many. Angles are in radians.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "IDENTITY",
    "angle",
    "angle_between",
    "canonical",
    "conjugate",
    "from_axis_angle",
    "from_rotation_matrix",
    "from_rotation_vector",
    "from_two_vectors",
    "heading_offset",
    "inclination_error",
    "multiply",
    "normalize",
    "average",
    "rotate",
    "slerp",
    "to_rotation_matrix",
    "to_rotation_vector",
]

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
_MIN_ROWS = 4096  # rows from which rotate and multiply use the compiled loops (quaternion_kernels.MIN_ROWS)


def _q(q: np.ndarray) -> np.ndarray:
    a = np.asarray(q, dtype=np.float64)
    if a.shape[-1] != 4:
        raise ValueError(f"quaternions must have 4 components in the last axis, got shape {a.shape}")
    return a


def normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternion(s) ``q / |q|``."""
    q = _q(q)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def canonical(q: np.ndarray) -> np.ndarray:
    """The same rotation(s) with ``w >= 0`` (q and -q are one rotation)."""
    q = _q(q)
    return np.where(q[..., :1] < 0, -q, q)


def conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate (the inverse of a unit quaternion)."""
    q = _q(q).copy()
    q[..., 1:] *= -1.0
    return q


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p * q`` (apply ``q`` first, then ``p``)."""
    p = _q(p)
    q = _q(q)
    n = max(len(p) if p.ndim == 2 else 0, len(q) if q.ndim == 2 else 0) if p.ndim + q.ndim in (3, 4) else 0
    if n >= _MIN_ROWS:  # long stacks: one compiled pass, bit-identical (imulog.process.quaternion_kernels)
        from imulog.process import quaternion_kernels as kern

        pr, qr = kern.rows_of(p, n), kern.rows_of(q, n)
        if pr is not None and qr is not None:
            return kern.multiply_rows(pr, qr, np.empty((n, 4)))
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ],
        axis=-1,
    )


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vector(s) ``v`` (..., 3) by unit quaternion(s) ``q``: ``q * v * q^-1``.

    ``v + w t + u x t`` with ``t = 2 u x v`` (``u`` the vector part), written out per component: the same
    operations in the same order as with ``np.cross`` (bit-identical results) without its temporaries, 1.6x
    faster on an hour of 100 Hz samples."""
    q = _q(q)
    v = np.asarray(v, dtype=np.float64)
    if v.ndim == 2 and len(v) >= _MIN_ROWS and v.shape[1] == 3:  # long stacks: one compiled pass, bit-identical
        from imulog.process import quaternion_kernels as kern

        qr = kern.rows_of(q, len(v))
        if qr is not None:
            return kern.rotate_rows(qr, np.ascontiguousarray(v), np.empty((len(v), 3)))
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    out = np.empty(np.broadcast_shapes(q.shape[:-1], v.shape[:-1]) + (3,))
    out[..., 0] = vx + w * tx + (y * tz - z * ty)
    out[..., 1] = vy + w * ty + (z * tx - x * tz)
    out[..., 2] = vz + w * tz + (x * ty - y * tx)
    return out


def rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``R(q)^T v``: a parent-frame vector expressed in the rotated (e.g. sensor) frame."""
    return rotate(conjugate(q), v)


def to_rotation_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix/matrices (..., 3, 3) with ``R @ v == rotate(q, v)``."""
    q = normalize(q)
    w, x, y, z = np.moveaxis(q, -1, 0)
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def from_rotation_matrix(r: np.ndarray) -> np.ndarray:
    """Unit quaternion(s) (w >= 0) of rotation matrix/matrices ``r`` (..., 3, 3).

    Uses the numerically robust branch on the largest diagonal term (Shepperd's method).
    """
    r = np.asarray(r, dtype=np.float64)
    if r.shape[-2:] != (3, 3):
        raise ValueError(f"rotation matrices must be (..., 3, 3), got {r.shape}")
    shape = r.shape[:-2]
    m = r.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    diag = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    k = np.argmax(diag, axis=1)
    q = np.empty((len(m), 4))
    # case w largest
    s = k == 0
    if np.any(s):
        t = np.sqrt(1.0 + tr[s]) * 2
        q[s] = np.stack(
            [0.25 * t, (m[s, 2, 1] - m[s, 1, 2]) / t, (m[s, 0, 2] - m[s, 2, 0]) / t, (m[s, 1, 0] - m[s, 0, 1]) / t],
            axis=1,
        )
    s = k == 1
    if np.any(s):
        t = np.sqrt(1.0 + m[s, 0, 0] - m[s, 1, 1] - m[s, 2, 2]) * 2
        q[s] = np.stack(
            [(m[s, 2, 1] - m[s, 1, 2]) / t, 0.25 * t, (m[s, 0, 1] + m[s, 1, 0]) / t, (m[s, 0, 2] + m[s, 2, 0]) / t],
            axis=1,
        )
    s = k == 2
    if np.any(s):
        t = np.sqrt(1.0 - m[s, 0, 0] + m[s, 1, 1] - m[s, 2, 2]) * 2
        q[s] = np.stack(
            [(m[s, 0, 2] - m[s, 2, 0]) / t, (m[s, 0, 1] + m[s, 1, 0]) / t, 0.25 * t, (m[s, 1, 2] + m[s, 2, 1]) / t],
            axis=1,
        )
    s = k == 3
    if np.any(s):
        t = np.sqrt(1.0 - m[s, 0, 0] - m[s, 1, 1] + m[s, 2, 2]) * 2
        q[s] = np.stack(
            [(m[s, 1, 0] - m[s, 0, 1]) / t, (m[s, 0, 2] + m[s, 2, 0]) / t, (m[s, 1, 2] + m[s, 2, 1]) / t, 0.25 * t],
            axis=1,
        )
    return canonical(normalize(q)).reshape(shape + (4,))


def from_rotation_vector(rv: np.ndarray) -> np.ndarray:
    """Quaternion(s) of rotation vector(s) ``rv`` (..., 3): axis * angle in rad."""
    rv = np.asarray(rv, dtype=np.float64)
    theta = np.linalg.norm(rv, axis=-1, keepdims=True)
    half = 0.5 * theta
    # sin(x/2)/x with its Taylor series near 0
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(theta > 1e-8, np.sin(half) / np.where(theta > 0, theta, 1.0), 0.5 - theta**2 / 48.0)
    return np.concatenate([np.cos(half), rv * k], axis=-1)


def to_rotation_vector(q: np.ndarray) -> np.ndarray:
    """Rotation vector(s) (..., 3), axis * angle in rad with angle in [0, pi]."""
    q = canonical(normalize(q))
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    theta = 2.0 * np.arctan2(s, q[..., :1])
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(s > 1e-12, theta / np.where(s > 0, s, 1.0), 2.0)
    return v * k


def from_axis_angle(axis: np.ndarray, angle_rad: np.ndarray | float) -> np.ndarray:
    """Quaternion(s) rotating by ``angle_rad`` about ``axis`` (normalised here)."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    a = np.asarray(angle_rad, dtype=np.float64)[..., None]
    return np.concatenate([np.cos(a / 2), np.sin(a / 2) * axis], axis=-1)


def from_two_vectors(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc quaternion(s) rotating direction ``a`` onto direction ``b``."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    w = 1.0 + np.sum(a * b, axis=-1, keepdims=True)
    xyz = np.cross(a, b)
    q = np.concatenate([w, xyz], axis=-1)
    # antiparallel: rotate by pi about any axis orthogonal to a
    anti = w[..., 0] < 1e-12
    if np.any(anti):
        aa = np.broadcast_to(a, q.shape[:-1] + (3,))[anti]
        ortho = np.cross(aa, np.array([1.0, 0.0, 0.0]))
        small = np.linalg.norm(ortho, axis=-1) < 1e-6
        ortho[small] = np.cross(aa[small], np.array([0.0, 1.0, 0.0]))
        q[anti] = np.concatenate([np.zeros((len(aa), 1)), ortho], axis=-1)
    return normalize(q)


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle(s) in rad, in [0, pi]."""
    q = normalize(q)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., 1:], axis=-1), np.abs(q[..., 0]))


def angle_between(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Angle(s) in rad of the rotation taking ``q`` to ``p`` (``p * q^-1``), in [0, pi]."""
    return angle(multiply(p, conjugate(q)))


def slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical linear interpolation from ``q0`` (t=0) to ``q1`` (t=1) along the shorter arc."""
    q0 = normalize(q0)
    q1 = normalize(q1)
    t = np.asarray(t, dtype=np.float64)[..., None]
    d = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(d < 0, -q1, q1)
    d = np.abs(d)
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    s = np.sin(theta)
    near = s < 1e-9
    with np.errstate(invalid="ignore", divide="ignore"):
        w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(near, 1.0, s))
        w1 = np.where(near, t, np.sin(t * theta) / np.where(near, 1.0, s))
    return normalize(w0 * q0 + w1 * q1)


def average(q: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Mean rotation of ``q`` (N, 4): principal eigenvector of sum w q q^T (Markley et al. 2007)."""
    q = normalize(np.atleast_2d(q))
    w = np.ones(len(q)) if weights is None else np.asarray(weights, dtype=np.float64)
    m = (q * w[:, None]).T @ q
    vals, vecs = np.linalg.eigh(m)
    return canonical(vecs[:, -1])


def heading_offset(q_est: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Constant rotation about global z (quaternion) that best maps ``q_est`` onto ``q_ref``.

    Least squares on the global-frame error ``q_ref * q_est^-1``: the heading (yaw) angle that
    minimises the summed squared rotation error is the circular mean of the per-sample heading of
    the error quaternions, weighted by their z-component magnitude (closed form for rotations about
    one axis). Used to compare 6D orientation (heading arbitrary) with a reference.
    """
    e = canonical(multiply(q_ref, conjugate(q_est)))
    # the z-rotation r = (cos a/2, 0, 0, sin a/2) maximising sum (r . e)^2
    m = np.stack([e[:, 0], e[:, 3]], axis=1)
    vals, vecs = np.linalg.eigh(m.T @ m)
    c, s = vecs[:, -1]
    return canonical(np.array([c, 0.0, 0.0, s]))


def inclination_error(q_est: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Inclination error(s) in rad: the non-heading part of ``q_est * q_ref^-1`` (BROAD definition)."""
    e = normalize(multiply(q_est, conjugate(q_ref)))
    return 2.0 * np.arccos(np.clip(np.sqrt(e[..., 0] ** 2 + e[..., 3] ** 2), 0.0, 1.0))


def from_euler_zyx(yaw_deg: float, pitch_deg: float, roll_deg: float) -> np.ndarray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` (intrinsic z-y'-x'') as a quaternion; angles in degrees."""
    qz = from_rotation_vector(np.array([0.0, 0.0, np.radians(yaw_deg)]))
    qy = from_rotation_vector(np.array([0.0, np.radians(pitch_deg), 0.0]))
    qx = from_rotation_vector(np.array([np.radians(roll_deg), 0.0, 0.0]))
    return multiply(multiply(qz, qy), qx)
