"""Marker-cluster kinematics for the alignment: cluster frames and angular velocity from filtered markers, gyroscope bias, vector match."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.alignment_frames import (
    angular_velocity_from_rotations,
    cluster_frame_oxy,
    cluster_frame_svd,
    lowpass_markers,
)
from imulog.process.alignment_params import AlignmentParams
from imulog.process.alignment_search import base_name, resolve_markers


@dataclass
class ClusterKinematics:
    """Cluster pose and angular velocity on the reference clock."""

    t_ns: np.ndarray
    origin_m: np.ndarray
    quat_c2w: np.ndarray
    omega_local_rad_s: np.ndarray
    missing: np.ndarray  # (N,) True where the pose could not be computed
    markers: tuple[str, ...] = ()


def _oxy_local(names: list[str], pos: np.ndarray) -> np.ndarray | None:
    """Marker coordinates in the thesis's O/X/Y cluster frame (mean over complete frames), so that
    the SVD fit reports the same frame as the O/X/Y construction; None without O, X and Y."""
    base = [base_name(m) for m in names]
    if not all(m in base for m in ("O", "X", "Y")):
        return None
    o, x, y = (pos[:, base.index(m)] for m in ("O", "X", "Y"))
    full = np.all(np.isfinite(pos.reshape(len(pos), -1)), axis=1)
    if not full.any():
        return None
    r = cluster_frame_oxy(o[full], x[full], y[full])
    return np.einsum("nji,nmj->mi", r, pos[full] - o[full][:, None]) / full.sum()


def _first_three_local(pos: np.ndarray) -> np.ndarray | None:
    """Marker coordinates in the frame of the first three markers (origin the first, x towards the second,
    z normal to the three): the cluster frame when the markers have no O/X/Y names."""
    full = np.all(np.isfinite(pos.reshape(len(pos), -1)), axis=1)
    if not full.any():
        return None
    r = cluster_frame_oxy(pos[full, 0], pos[full, 1], pos[full, 2])
    return np.einsum("nji,nmj->mi", r, pos[full] - pos[full, 0][:, None]) / full.sum()


def cluster_kinematics(
    t_ns: np.ndarray, labels: list[str], pos_m: np.ndarray, rate_hz: float, params: AlignmentParams = AlignmentParams()
) -> ClusterKinematics:
    """Filter the markers, build the cluster pose and its angular velocity (cluster frame).

    ``cluster="oxy"`` uses markers O, X, Y; ``"svd"`` the ``params.markers`` (all given when empty); ``"auto"`` (the search is done
    by the caller) every marker given: with three markers the O/X/Y construction (on O, X, Y when so named,
    else on the markers in the order given), with more the SVD fit (in the O/X/Y frame when those names are
    among them, else in the frame of the first three markers).
    Names match with or without the ``Subject:`` prefix.
    """
    labels = list(labels)
    if params.cluster == "oxy":
        need = ["O", "X", "Y"]
    elif params.cluster == "svd":
        need = list(params.markers) or list(labels)
        if len(need) < 3:
            raise ValueError(f"the SVD cluster fit needs >= 3 markers, got {', '.join(need) or 'none'}")
    elif params.cluster == "auto":
        need = list(labels)
        if len(need) < 3:
            raise ValueError(f"a cluster needs >= 3 markers, got {', '.join(need) or 'none'}")
    else:
        raise ValueError(f"cluster method must be 'auto', 'oxy' or 'svd', got {params.cluster!r}")
    idx = resolve_markers(labels, need)
    names = [labels[i] for i in idx]
    filt, _ = lowpass_markers(np.asarray(pos_m)[:, idx], rate_hz, params.filter)
    return kinematics_from_filtered(t_ns, names, filt, rate_hz, params.cluster)


def kinematics_from_filtered(
    t_ns: np.ndarray, names: list[str], filt: np.ndarray, rate_hz: float, cluster: str = "auto"
) -> ClusterKinematics:
    """:func:`cluster_kinematics` on markers already low-passed (``filt`` (N, M, 3) m, ``names`` M labels)."""
    names = list(names)
    oxy_names = sorted(base_name(n) for n in names) == ["O", "X", "Y"]
    if cluster == "oxy" or (cluster == "auto" and len(names) == 3):
        order = [[base_name(n) for n in names].index(m) for m in ("O", "X", "Y")] if oxy_names else [0, 1, 2]
        filt = filt[:, order]
        names = [names[i] for i in order]
        r = cluster_frame_oxy(filt[:, 0], filt[:, 1], filt[:, 2])
        origin = filt[:, 0]
    else:
        local = _oxy_local(names, filt)
        if local is None:
            local = _first_three_local(filt)
        r, origin = cluster_frame_svd(filt, local)
    missing = ~np.all(np.isfinite(r.reshape(len(r), 9)), axis=1)
    q = np.full((len(r), 4), np.nan)
    if (~missing).any():
        q[~missing] = quat.from_rotation_matrix(r[~missing])
    omega = angular_velocity_from_rotations(r, rate_hz)
    return ClusterKinematics(np.asarray(t_ns, dtype=np.int64), origin, q, omega, missing, tuple(names))


#: a rigid body's frame as four virtual markers: its origin and the tips of its unit axes (body frame, m)
AXIS_MARKERS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def pose_kinematics(
    t_ns: np.ndarray,
    position_m: np.ndarray,
    quat_b2w: np.ndarray,
    rate_hz: float,
    params: AlignmentParams = AlignmentParams(),
    name: str = "pose",
) -> ClusterKinematics:
    """The kinematics of an optical rigid body's poses (OptiTrack, BROAD's ``opt_quat``) as a marker cluster's:
    the body frame is the cluster frame, so ``rotation_imu_to_cluster`` is the IMU-to-body rotation.

    ``quat_b2w`` (N, 4) w,x,y,z body-to-world (NaN where tracking was lost), ``position_m`` (N, 3) m or None. The
    orientation is low-passed like markers (``params.filter``: short gaps filled, long ones left missing) as four
    virtual markers, the body origin and its unit axes' tips (:data:`AXIS_MARKERS`), then refitted to a rotation
    (Kabsch, :func:`cluster_frame_svd`), so a pose and a marker cluster meet the gyroscope alike; the angular
    velocity is :func:`angular_velocity_from_rotations`'s (body frame, rad/s)."""
    q = np.asarray(quat_b2w, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4:
        raise ValueError(f"poses need (N, 4) quaternions, got shape {q.shape}")
    ok = np.all(np.isfinite(q), axis=1)
    r = np.full((len(q), 3, 3), np.nan)
    if ok.any():
        qn = q[ok] / np.linalg.norm(q[ok], axis=1, keepdims=True)
        r[ok] = quat.to_rotation_matrix(qn)
    virtual = np.concatenate([np.zeros((len(q), 1, 3)), r.transpose(0, 2, 1)], axis=1)  # axis tips = R's columns
    virtual[~ok] = np.nan
    filt, _ = lowpass_markers(virtual, rate_hz, params.filter)
    r_f, _ = cluster_frame_svd(filt, AXIS_MARKERS)
    missing = ~np.all(np.isfinite(r_f.reshape(len(r_f), 9)), axis=1)
    q_f = np.full((len(q), 4), np.nan)
    if (~missing).any():
        q_f[~missing] = quat.from_rotation_matrix(r_f[~missing])
    if position_m is None:
        origin = np.full((len(q), 3), np.nan)
    else:
        origin, _ = lowpass_markers(np.asarray(position_m, dtype=np.float64), rate_hz, params.filter)
    omega = angular_velocity_from_rotations(r_f, rate_hz)
    return ClusterKinematics(np.asarray(t_ns, dtype=np.int64), origin, q_f, omega, missing, (name,))


def _interp_rows(t_src: np.ndarray, x: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Linear interpolation of the finite rows of ``x`` at ``t_dst``; NaN outside and across gaps longer
    than three median sample intervals (missing samples are not bridged)."""
    out = np.full((len(t_dst), x.shape[1]), np.nan)
    ok = np.all(np.isfinite(x), axis=1)
    if ok.sum() < 2:
        return out
    ts = t_src[ok].astype(np.float64)
    td = np.asarray(t_dst, dtype=np.float64)
    for c in range(x.shape[1]):
        out[:, c] = np.interp(td, ts, x[ok, c], left=np.nan, right=np.nan)
    step = np.diff(ts)
    k = np.clip(np.searchsorted(ts, td), 1, len(ts) - 1)
    out[(ts[k] - ts[k - 1]) > 3 * np.median(step)] = np.nan
    return out


def _gyro_bias(t_imu: np.ndarray, gyr: np.ndarray, params: AlignmentParams) -> np.ndarray:
    """Gyroscope bias (rad/s) from the IMU's static periods (zeros without any)."""
    from imulog.process.orientation import StaticParams, detect_static

    imu_rate = (len(t_imu) - 1) / ((t_imu[-1] - t_imu[0]) * 1e-9)
    still = detect_static(
        np.nan_to_num(gyr, nan=np.inf), imu_rate, StaticParams(min_duration_s=params.bias_min_static_s)
    )
    return np.nanmean(gyr[still], axis=0) if still.sum() > 0 else np.zeros(3)


def vector_match(w_imu_rad_s: np.ndarray, w_cluster_rad_s: np.ndarray, q_imu_to_cluster: np.ndarray) -> float:
    """R^2 of the cluster's angular velocity explained by the rotated gyroscope: 1 - |w_c - R w_i|^2 / |w_c|^2."""
    a = np.asarray(w_imu_rad_s, dtype=np.float64)
    b = np.asarray(w_cluster_rad_s, dtype=np.float64)
    ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    if ok.sum() < 10:
        return float("nan")
    pred = quat.rotate(np.asarray(q_imu_to_cluster, dtype=np.float64), a[ok])
    den = float(np.sum(b[ok] ** 2))
    return float(1.0 - np.sum((b[ok] - pred) ** 2) / den) if den > 0 else float("nan")
