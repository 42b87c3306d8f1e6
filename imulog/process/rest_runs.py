"""Rests and the movements between them: runs of a zero-velocity mask, the gyroscope bias at a rest, and the
orientation integrated from the gyroscope through a movement from one rest to the next (the rest-anchored
orientation of :mod:`imulog.process.integration` and the heading through rests of
:mod:`imulog.process.anchor_heading` share them). Pure numpy; times in s, rates in rad/s, quaternions w,x,y,z.
"""

from __future__ import annotations

import numpy as np


def static_runs(mask: np.ndarray, min_samples: int = 1) -> np.ndarray:
    """Runs of True in a boolean mask as an (R, 2) int array of [start, stop) indices."""
    m = np.asarray(mask, dtype=bool)
    if m.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    d = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    keep = (stops - starts) >= min_samples
    return np.stack([starts[keep], stops[keep]], axis=1).astype(np.int64)


def movement_runs(static: np.ndarray) -> np.ndarray:
    """The movements of a zero-velocity mask ``static`` (N,) as an (M, 2) int array of [start, stop) indices:
    runs of False with a rest on both sides (a movement at either end has no rest to start or end at)."""
    runs = static_runs(~static)
    n = len(static)
    return runs[(runs[:, 0] > 0) & (runs[:, 1] < n)]  # rests on both sides


def rest_bias(gyr: np.ndarray, t: np.ndarray, static: np.ndarray, a: int, window_s: float) -> np.ndarray:
    """Gyroscope bias (3,) rad/s: the mean over at most ``window_s`` s of the rest that ends at sample a - 1."""
    lo = a - 1
    while lo > 0 and static[lo - 1] and t[a - 1] - t[lo - 1] <= window_s:
        lo -= 1
    return np.mean(gyr[lo:a], axis=0)


def through_movement(
    cur: np.ndarray, gyr: np.ndarray, t: np.ndarray, bias: np.ndarray, end: np.ndarray | None, spread: str
) -> np.ndarray:
    """Orientations (M, 4) integrated from ``cur`` with the gyroscope ``gyr`` (M, 3) rad/s minus ``bias`` at
    times ``t`` (M,) s, the discrepancy with ``end`` (the orientation at the last sample; None: none) spread
    over the samples by ``spread`` (``AnchorParams.spread``: ``"time"``, ``"angle"`` or ``"mixed"``)."""
    from imulog.process import quaternion as quat

    steps = quat.from_rotation_vector(0.5 * ((gyr[1:] - bias) + (gyr[:-1] - bias)) * np.diff(t)[:, None])
    qs = np.empty((len(gyr), 4))
    qs[0] = c = cur
    for k, step in enumerate(steps, start=1):
        c = quat.multiply(c, step)
        qs[k] = c
    return qs if end is None else spread_to(qs, gyr, t, bias, end, spread)


def spread_to(
    qs: np.ndarray, gyr: np.ndarray, t: np.ndarray, bias: np.ndarray, end: np.ndarray, spread: str
) -> np.ndarray:
    """Orientations ``qs`` (M, 4) integrated through a movement (:func:`through_movement` without an end) with the
    discrepancy between their last and ``end`` spread over the samples by ``spread`` (``AnchorParams.spread``: ``"time"``, ``"angle"`` or ``"mixed"``)."""
    from imulog.process import quaternion as quat

    delta = quat.to_rotation_vector(quat.multiply(end, quat.conjugate(qs[-1])))
    by_time = (t - t[0]) / max(t[-1] - t[0], 1e-9)
    turned = np.concatenate([[0.0], np.cumsum(np.linalg.norm(gyr[1:] + gyr[:-1] - 2 * bias, axis=1))])
    by_angle = turned / max(turned[-1], 1e-12)
    alpha = {"time": by_time, "angle": by_angle, "mixed": 0.5 * (by_time + by_angle)}[spread][:, None]
    return quat.normalize(quat.multiply(quat.from_rotation_vector(alpha * delta), qs))
