"""IMU-to-Vicon alignment: cluster orientation, angular velocity, time lag, drift and frames.

The R2G thesis (section 2.3.1) aligns the wrist IMU with the Vicon marker cluster by

1. low-pass filtering the marker trajectories (6 Hz, 2nd-order Butterworth, Bergamini et al.),
2. building the cluster frame from markers O, X, Y (x = X - O; z = x cross (Y - O); y = z cross x),
3. computing the cluster's angular velocity from consecutive rotation matrices (Chardonnens et al.),
4. cross-correlating the angular-velocity norms of both systems over the first two minutes (the
   protocol's static period plus wave movement) to find the time lag.

Here this is extended by sub-sample lag refinement, an optional clock drift from two windows, an
SVD (Kabsch) cluster fit for any >= 3 markers, and the constant IMU-to-cluster rotation by least
squares on the two angular-velocity signals (Chardonnens et al., J Biomech 2012).

Clock model (docs/architecture.md, ``imulog.alignment``)::

    t_ref_ns = t_dev_ns + offset_ns + drift_ppm * 1e-6 * (t_dev_ns - t0_ns)

Positions in m, angular velocity in rad/s, times in int64 ns unless named ``_s``.
"""

from __future__ import annotations

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.alignment_clock import NS, device_to_reference, reference_to_device
from imulog.process.alignment_cluster import (
    ClusterKinematics,
    _gyro_bias,
    _interp_rows,
    cluster_kinematics,
    kinematics_from_filtered,
    vector_match,
)
from imulog.process.alignment_fit import (
    assess_quality,
    fit_clock,
    fit_window_lags,
)
from imulog.process.alignment_frames import (
    FilterParams,
    angular_velocity_from_rotations,
    cluster_frame_oxy,
    cluster_frame_svd,
    lowpass_markers,
)
from imulog.process.alignment_lag import (
    LagEstimate,
    _wahba,
    estimate_lag,
    estimate_rotation_imu_to_cluster,
    rotation_global_to_world,
)
from imulog.process.alignment_params import AlignmentParams
from imulog.process.alignment_search import SearchParams, base_name, resolve_markers

__all__ = [
    "NS",
    "SearchParams",
    "base_name",
    "resolve_markers",
    "align",
    "align_frames",
    "align_marker",
    "AlignmentParams",
    "angular_velocity_from_rotations",
    "assess_quality",
    "cluster_frame_oxy",
    "cluster_frame_svd",
    "cluster_kinematics",
    "ClusterKinematics",
    "device_to_reference",
    "estimate_lag",
    "estimate_rotation_imu_to_cluster",
    "FilterParams",
    "fit_clock",
    "fit_norm_correction",
    "fit_window_lags",
    "gyro_like_markers",
    "kinematics_from_filtered",
    "LagEstimate",
    "lowpass_markers",
    "reference_to_device",
    "rotation_global_to_world",
    "vector_match",
]


# --------------------------------------------------------------------------------------------
# the whole alignment


def align(
    t_imu_ns: np.ndarray,
    gyr_rad_s: np.ndarray,
    cluster: ClusterKinematics,
    params: AlignmentParams = AlignmentParams(),
    q_imu_s2g: np.ndarray | None = None,
    coarse_offset_ns: int | None = None,
) -> dict:
    """Full alignment of one IMU with one marker cluster; returns the ``imulog.alignment`` fields.

    ``t_imu_ns``/``gyr_rad_s`` on the device clock; ``cluster`` from :func:`cluster_kinematics` on
    the reference clock; ``q_imu_s2g`` (optional, the IMU orientation on the device clock) enables
    ``rotation_global_to_world``. Keys: offset_ns, drift_ppm, t0_ns and their uncertainties (see
    :func:`fit_clock`), rotation_imu_to_cluster, rotation_global_to_world (None without ``q_imu_s2g``),
    method, signal, score, vector_match, plus diagnostics (rotation_residual_rad_s, windows, gyr_bias_rad_s).
    """
    t_imu = np.asarray(t_imu_ns, dtype=np.int64)
    gyr = np.asarray(gyr_rad_s, dtype=np.float64)
    wn_dev = np.linalg.norm(gyro_like_markers(t_imu, gyr, params), axis=1)
    wn_ref = np.linalg.norm(cluster.omega_local_rad_s, axis=1)
    result = fit_clock(t_imu, wn_dev, cluster.t_ns, wn_ref, params, coarse_offset_ns)
    return align_frames(t_imu, gyr, cluster, result, params, q_imu_s2g)


def gyro_like_markers(t_imu_ns: np.ndarray, gyr_rad_s: np.ndarray, params: AlignmentParams) -> np.ndarray:
    """The gyroscope low-passed like the markers (``params.filter``: same cutoff and order, zero phase) when
    ``params.gyro_lowpass``: the cluster's angular velocity comes from 6-Hz markers, and comparing it with the
    raw gyroscope biased the lag (the gaitmap feet: -3.8 and -5.4 ms on data synchronised by its authors,
    -0.2 and +0.3 ms filtered alike) and lowered the vector match (0.89 -> 0.97)."""
    gyr = np.asarray(gyr_rad_s, dtype=np.float64)
    if not params.gyro_lowpass or len(gyr) < 20:
        return gyr
    from imulog.process.alignment_search import lowpass_vector

    t = np.asarray(t_imu_ns, dtype=np.int64)
    rate = (len(t) - 1) / ((t[-1] - t[0]) * 1e-9)
    return lowpass_vector(gyr, rate, params.filter.cutoff_hz, params.filter.order)


def align_frames(
    t_imu_ns: np.ndarray,
    gyr_rad_s: np.ndarray,
    cluster: ClusterKinematics,
    clock: dict,
    params: AlignmentParams = AlignmentParams(),
    q_imu_s2g: np.ndarray | None = None,
) -> dict:
    """The frame part of :func:`align` on a given clock (``clock``: the fields of :func:`fit_clock`, e.g. the
    clock shared by the IMUs of one recording): the record with ``rotation_imu_to_cluster``, ``vector_match``
    and, with ``q_imu_s2g``, ``rotation_global_to_world``."""
    t_imu = np.asarray(t_imu_ns, dtype=np.int64)
    gyr = np.asarray(gyr_rad_s, dtype=np.float64)
    result = dict(clock)
    result["signal"] = "angular-velocity-norm"
    # IMU samples on the reference clock, gyro resampled at the Vicon times
    t_imu_ref = device_to_reference(t_imu, result)
    bias = _gyro_bias(t_imu, gyr, params)
    result["gyr_bias_rad_s"] = [float(v) for v in bias]
    gyr_at_ref = _interp_rows(t_imu_ref, gyro_like_markers(t_imu, gyr - bias, params), cluster.t_ns)
    q_i2c, resid = estimate_rotation_imu_to_cluster(gyr_at_ref, cluster.omega_local_rad_s)
    result["rotation_imu_to_cluster"] = [float(v) for v in q_i2c]
    result["rotation_residual_rad_s"] = resid
    result["vector_match"] = vector_match(gyr_at_ref, cluster.omega_local_rad_s, q_i2c)
    result["rotation_global_to_world"] = None
    if q_imu_s2g is not None:
        from imulog.process.resample import resample_quaternions

        q_at_ref = resample_quaternions(t_imu_ref, np.asarray(q_imu_s2g, dtype=np.float64), cluster.t_ns)
        ok = np.all(np.isfinite(q_at_ref), axis=1) & np.all(np.isfinite(cluster.quat_c2w), axis=1)
        q_g2w = rotation_global_to_world(q_at_ref[ok], cluster.quat_c2w[ok], q_i2c)
        result["rotation_global_to_world"] = [float(v) for v in q_g2w]
    result["method"] = (
        f"xcorr-angular-velocity-norm(windows={params.window_s:g}s{', drift' if params.drift else ''})"
        f"+wahba-angular-velocity;cluster={params.cluster}"
    )
    return result


def fit_norm_correction(
    a_dev: np.ndarray,
    t_dev_on_ref_ns: np.ndarray,
    norm_ref: np.ndarray,
    t_ref_ns: np.ndarray,
    max_samples: int = 20000,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Per-axis bias (m/s^2) and scale of an accelerometer such that ``|scale * (a - bias)|`` matches the
    marker's specific-force norm ``norm_ref`` on the time-aligned samples (least squares; bias within
    +-3 m/s^2, scale 0.8-1.2). None when there are too few samples or the fit does not reduce the misfit
    by at least 10 %."""
    from scipy.optimize import least_squares

    at = _interp_rows(np.asarray(t_dev_on_ref_ns, dtype=np.int64), np.asarray(a_dev, dtype=np.float64), t_ref_ns)
    ok = np.all(np.isfinite(at), axis=1) & np.isfinite(norm_ref)
    idx = np.flatnonzero(ok)
    if len(idx) < 100:
        return None
    idx = idx[np.unique(np.linspace(0, len(idx) - 1, min(len(idx), max_samples)).astype(int))]
    a, m = at[idx], norm_ref[idx]

    def resid(p: np.ndarray) -> np.ndarray:
        return np.linalg.norm(p[3:] * (a - p[:3]), axis=1) - m

    x0 = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])
    fit = least_squares(resid, x0, bounds=([-3, -3, -3, 0.8, 0.8, 0.8], [3, 3, 3, 1.2, 1.2, 1.2]))
    if not fit.success or np.sum(fit.fun**2) > 0.81 * np.sum(resid(x0) ** 2):
        return None
    return fit.x[:3], fit.x[3:]


def align_marker(
    t_imu_ns: np.ndarray,
    acc_mps2: np.ndarray,
    t_ref_ns: np.ndarray,
    marker_m: np.ndarray,
    rate_hz: float,
    params: AlignmentParams = AlignmentParams(),
    *,
    vertical: tuple[float, float, float] | None = (0.0, 0.0, 1.0),
    acc_global: tuple[np.ndarray, np.ndarray] | None = None,
    coarse_offset_ns: int | None = None,
) -> dict:
    """Clock alignment on one marker's acceleration (no rigid cluster in view).

    ``acc_mps2`` the accelerometer (specific force, sensor frame) on the device clock and ``marker_m``
    (N, 3) the raw marker positions on the reference clock. Compared: ``|a_marker + g up|`` with the
    accelerometer norm (``vertical`` = up in the marker frame), or, with ``acc_global`` = (t_dev_ns,
    gravity-free acceleration in the IMU global frame), the gravity-free norms; both low-passed alike
    (``params.filter``). With ``acc_global`` the constant rotation global-to-world is also fitted (Wahba on
    the accelerations). No IMU-to-cluster rotation. Keys as :func:`align` plus ``vertical``.
    """
    from imulog.process.alignment_search import acceleration_norm, away_from_gaps, lowpass_vector

    t_imu = np.asarray(t_imu_ns, dtype=np.int64)
    filt, gaps = lowpass_markers(np.asarray(marker_m, dtype=np.float64), rate_hz, params.filter)
    trusted = away_from_gaps(gaps, rate_hz)
    imu_rate = (len(t_imu) - 1) / ((t_imu[-1] - t_imu[0]) * 1e-9)
    if acc_global is not None:
        t_src = np.asarray(acc_global[0], dtype=np.int64)
        a_dev = lowpass_vector(acc_global[1], imu_rate, params.filter.cutoff_hz, params.filter.order)
        n_ref = acceleration_norm(filt, rate_hz, None)
    else:
        t_src = t_imu
        a_dev = lowpass_vector(acc_mps2, imu_rate, params.filter.cutoff_hz, params.filter.order)
        n_ref = acceleration_norm(filt, rate_hz, None if vertical is None else np.asarray(vertical, dtype=np.float64))
    n_ref[~trusted] = np.nan
    act = params.min_window_activity_mps2
    result = fit_clock(t_src, np.linalg.norm(a_dev, axis=1), t_ref_ns, n_ref, params, coarse_offset_ns, act)
    if acc_global is None:
        # the accelerometer's bias and scale errors change |acc| with the orientation, in step with the
        # movement: fit them to the marker's specific force on the aligned samples, then align again
        fix = fit_norm_correction(a_dev, device_to_reference(t_src, result), n_ref, np.asarray(t_ref_ns, np.int64))
        if fix is not None:
            bias, scale = fix
            corrected = np.linalg.norm(scale * (a_dev - bias), axis=1)
            result = fit_clock(t_src, corrected, t_ref_ns, n_ref, params, result["offset_ns"], act)
            result["acc_correction"] = {"bias_mps2": [float(v) for v in bias], "scale": [float(v) for v in scale]}
    result["signal"] = "marker-acceleration"
    result["vertical"] = None if acc_global is not None or vertical is None else [float(v) for v in vertical]
    result["rotation_imu_to_cluster"] = None
    result["rotation_global_to_world"] = None
    if acc_global is not None:
        dt = 1.0 / rate_hz
        a_ref = np.full_like(filt, np.nan)
        a_ref[1:-1] = (filt[2:] - 2 * filt[1:-1] + filt[:-2]) / dt**2
        a_at = _interp_rows(device_to_reference(t_src, result), a_dev, np.asarray(t_ref_ns, dtype=np.int64))
        ok = np.all(np.isfinite(a_at), axis=1) & np.all(np.isfinite(a_ref), axis=1) & trusted
        if ok.sum() > 10:
            result["rotation_global_to_world"] = [
                float(v) for v in quat.from_rotation_matrix(_wahba(a_at[ok], a_ref[ok]))
            ]
    result["method"] = (
        f"xcorr-marker-acceleration-norm(windows={params.window_s:g}s{', drift' if params.drift else ''})"
        f";{'gravity-free' if acc_global is not None else 'specific-force'}"
    )
    return result
