"""Strides of a foot IMU and their evaluation against foot markers, like gaitmap's stride-level evaluation.

A stride runs from one mid-stance to the next (the middle of consecutive zero-velocity intervals, as gaitmap's
``min_vel`` strides); per stride: stride length (horizontal distance between its ends), stride time, foot
clearance (highest point of the swing above the start) and the position error per axis with both trajectories
taken relative to the stride's start. Pure functions on arrays: positions in m, times in s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from imulog.process.rest_runs import static_runs


@dataclass(frozen=True)
class StrideParams:
    """Accepted strides: ``min_stride_s`` to ``max_stride_s`` long (a human stride is about 0.8-2 s), with
    zero-velocity runs of ``min_rest_s`` to ``max_rest_s`` at both ends (a longer rest is standing: the step
    out of it is a gait initiation, not a stride)."""

    min_stride_s: float = 0.5
    max_stride_s: float = 3.0
    min_rest_s: float = 0.05
    max_rest_s: float = 1.0


def strides_from_rests(static: np.ndarray, rate_hz: float, params: StrideParams = StrideParams()) -> np.ndarray:
    """Strides as an (S, 2) int array of [start, end] sample indices, mid-stance to mid-stance, from a
    zero-velocity mask (True = foot at rest). Pairs of consecutive rests too close or too far apart are left out
    (a turn, standing still), and so are those next to a rest longer than ``max_rest_s`` (standing)."""
    runs = static_runs(np.asarray(static, dtype=bool), max(1, int(round(params.min_rest_s * rate_hz))))
    if len(runs) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    mid = (runs[:, 0] + runs[:, 1] - 1) // 2
    length_s = np.diff(mid) / rate_hz
    walking_rest = (runs[:, 1] - runs[:, 0]) <= params.max_rest_s * rate_hz
    keep = (length_s >= params.min_stride_s) & (length_s <= params.max_stride_s) & walking_rest[:-1] & walking_rest[1:]
    return np.stack([mid[:-1][keep], mid[1:][keep]], axis=1).astype(np.int64)


def heading_rotation(est_xy: np.ndarray, ref_xy: np.ndarray) -> np.ndarray:
    """The 2-D rotation (2, 2) that best maps horizontal displacements ``est_xy`` onto ``ref_xy`` (N, 2), by
    least squares (a 6D orientation's heading is arbitrary; the reference's is the lab's)."""
    ok = np.all(np.isfinite(est_xy), axis=1) & np.all(np.isfinite(ref_xy), axis=1)
    a, b = est_xy[ok], ref_xy[ok]
    if len(a) == 0:
        raise ValueError("no finite displacement pairs to fit the heading")
    angle = np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]))
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def stride_parameters(pos_m: np.ndarray, t_s: np.ndarray, strides: np.ndarray) -> dict[str, np.ndarray]:
    """Per stride: ``length_m`` (horizontal), ``time_s``, ``clearance_m`` (highest point above the start)."""
    s, e = strides[:, 0], strides[:, 1]
    length = np.linalg.norm(pos_m[e, :2] - pos_m[s, :2], axis=1)
    clearance = np.array([np.nanmax(pos_m[a : b + 1, 2]) - pos_m[a, 2] for a, b in strides]) if len(strides) else []
    return {"length_m": length, "time_s": t_s[e] - t_s[s], "clearance_m": np.asarray(clearance, dtype=float)}


def stride_errors(est_m: np.ndarray, ref_m: np.ndarray, t_s: np.ndarray, strides: np.ndarray) -> dict[str, Any]:
    """Per-stride evaluation of an estimated foot trajectory ``est_m`` against a reference ``ref_m`` (N, 3, on
    the same samples ``t_s``): the estimate's heading is rotated onto the reference's (one rotation about the
    vertical for the trial, fitted on the strides' displacements), then per stride and axis the mean absolute
    error of positions relative to the stride's start, and the errors of stride length, time and clearance.

    Returns ``{"strides": [per-stride dicts], "mean_abs_cm": {x, y, z}, "length_error_cm": mean, ...}``."""
    est = np.asarray(est_m, dtype=float)
    ref = np.asarray(ref_m, dtype=float)
    if est.shape != ref.shape or est.ndim != 2 or est.shape[1] != 3:
        raise ValueError(f"estimate and reference must both be (N, 3), got {est.shape} and {ref.shape}")
    if len(strides) == 0:
        raise ValueError("no strides: the zero-velocity intervals give no stride between 0.5 and 3 s")
    s, e = strides[:, 0], strides[:, 1]
    rot = heading_rotation(est[e, :2] - est[s, :2], ref[e, :2] - ref[s, :2])
    est = np.column_stack([est[:, :2] @ rot.T, est[:, 2]])
    rows = []
    for a, b in strides:
        de = est[a : b + 1] - est[a]
        dr = ref[a : b + 1] - ref[a]
        err = np.abs(de - dr)
        rows.append(
            {
                "start_s": float(t_s[a]),
                "time_s": float(t_s[b] - t_s[a]),
                **{f"{ax}_mae_cm": float(np.nanmean(err[:, i]) * 100) for i, ax in enumerate("xyz")},
            }
        )
    p_est = stride_parameters(est, t_s, strides)
    p_ref = stride_parameters(ref, t_s, strides)
    for k, row in enumerate(rows):
        row["length_m"] = float(p_est["length_m"][k])
        row["length_ref_m"] = float(p_ref["length_m"][k])
        row["clearance_m"] = float(p_est["clearance_m"][k])
        row["clearance_ref_m"] = float(p_ref["clearance_m"][k])
    return {
        "strides": rows,
        "count": len(rows),
        "heading_deg": float(np.degrees(np.arctan2(rot[1, 0], rot[0, 0]))),
        "mean_abs_cm": {ax: float(np.mean([r[f"{ax}_mae_cm"] for r in rows])) for ax in "xyz"},
        "length_error_cm": float(np.mean(np.abs(p_est["length_m"] - p_ref["length_m"])) * 100),
        "clearance_error_cm": float(np.mean(np.abs(p_est["clearance_m"] - p_ref["clearance_m"])) * 100),
        "stride_time_s": float(np.mean(p_est["time_s"])),
    }


def zero_velocity(
    gyr_rad_s: np.ndarray, rate_hz: float, threshold_rad_s: float = 0.6, min_s: float = 0.05
) -> np.ndarray:
    """Foot at rest (N,) bool: the gyroscope norm stays under ``threshold_rad_s`` for ``min_s`` around the
    sample (a moving window entirely under it); NaN samples are not at rest."""
    g = np.linalg.norm(np.asarray(gyr_rad_s, dtype=float), axis=1)
    under = np.nan_to_num(g, nan=np.inf) < threshold_rad_s
    k = max(1, int(round(min_s * rate_hz)))
    return np.convolve(under.astype(float), np.ones(k) / k, mode="same") > 1 - 1e-9


def walking_period(
    gyr_rad_s: np.ndarray, rate_hz: float, min_s: float = 0.7, max_s: float = 2.5, span_s: float = 120.0
) -> tuple[float, float]:
    """Stride period (s) and its strength: the highest autocorrelation of the gyroscope norm at a lag between
    ``min_s`` and ``max_s`` (a stride of walking), over at most ``span_s`` from the middle of the recording at
    about 25 Hz. Strength near 1 for steady walking; a drinking task or a still sensor stays well under 0.5."""
    g = np.linalg.norm(np.asarray(gyr_rad_s, dtype=float), axis=1)
    step = max(1, int(rate_hz // 25))
    g, rate = g[::step], rate_hz / step
    n = min(len(g), int(span_s * rate))
    mid = (len(g) - n) // 2
    x = np.nan_to_num(g[mid : mid + n], nan=0.0)
    x = x - x.mean()
    lo, hi = int(min_s * rate), int(max_s * rate)
    if n < 2 * hi or not np.any(x):
        return float("nan"), 0.0
    den = float(np.dot(x, x))
    ac = np.array([np.dot(x[:-k], x[k:]) / den * n / (n - k) for k in range(lo, hi + 1)])
    k = int(np.argmax(ac))
    return (lo + k) / rate, float(ac[k])


def lever_arm(
    acc_sensor_mps2: np.ndarray,
    q_world_sensor: np.ndarray,
    origin_m: np.ndarray,
    q_world_cluster: np.ndarray,
    rate_hz: float,
    cutoff_hz: float = 6.0,
) -> tuple[np.ndarray, float]:
    """Where the IMU sits in its marker cluster's frame (m), from accelerations alone.

    On common samples (``rate_hz``): the accelerometer rotated into the world (``q_world_sensor``, i.e. the
    cluster orientation times the IMU-to-cluster rotation) plus gravity is the IMU's acceleration, which equals
    the cluster origin's acceleration plus the second derivative of ``R_world_cluster(t) r``: linear in ``r``,
    solved by least squares over the trial (both sides low-passed at ``cutoff_hz``). Independent of any
    integrated trajectory. Returns ``(r (3,), rms residual m/s^2)``."""
    from imulog.process import quaternion as quat
    from imulog.process.alignment_search import lowpass_vector

    a_w = quat.rotate(np.asarray(q_world_sensor, dtype=float), np.asarray(acc_sensor_mps2, dtype=float))
    a_w = lowpass_vector(a_w - np.array([0.0, 0.0, 9.80665]), rate_hz, cutoff_hz)
    dt = 1.0 / rate_hz

    def second(x: np.ndarray) -> np.ndarray:
        y = np.full_like(x, np.nan)
        y[1:-1] = (x[2:] - 2 * x[1:-1] + x[:-2]) / dt**2
        return y

    a_o = second(np.asarray(origin_m, dtype=float))
    r_wc = quat.to_rotation_matrix(np.asarray(q_world_cluster, dtype=float)).reshape(-1, 9)
    r_dd = second(r_wc).reshape(-1, 3, 3)
    ok = np.all(np.isfinite(a_w), 1) & np.all(np.isfinite(a_o), 1) & np.all(np.isfinite(r_dd.reshape(-1, 9)), 1)
    if ok.sum() < 50:
        raise ValueError("too few samples with both the IMU and the cluster to place the IMU on the cluster")
    a_mat, b = r_dd[ok].reshape(-1, 3), (a_w[ok] - a_o[ok]).reshape(-1)
    r, *_ = np.linalg.lstsq(a_mat, b, rcond=None)
    return r, float(np.sqrt(np.mean((a_mat @ r - b) ** 2)))
