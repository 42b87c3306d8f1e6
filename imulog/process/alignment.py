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

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.alignment_clock import NS, device_to_reference, reference_to_device
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
from imulog.process.alignment_search import SearchParams, base_name, resolve_markers

__all__ = [
    "AlignmentParams",
    "FilterParams",
    "LagEstimate",
    "align",
    "align_frames",
    "align_marker",
    "assess_quality",
    "fit_clock",
    "fit_window_lags",
    "angular_velocity_from_rotations",
    "cluster_frame_oxy",
    "cluster_frame_svd",
    "device_to_reference",
    "estimate_lag",
    "estimate_rotation_imu_to_cluster",
    "lowpass_markers",
    "reference_to_device",
    "rotation_global_to_world",
    "vector_match",
]

# clock fit over windows across the trial


@dataclass(frozen=True)
class AlignmentParams:
    """IMU-to-Vicon alignment settings.

    Clock: a coarse lag over the whole recording (``coarse_hz`` grid, +-``max_lag_s``), then one lag per
    ``window_s`` (30 s) window across the trial, starting ``window_start_s`` after the reference's first
    sample, each searched +-``fine_lag_s`` around the coarse lag on a ``grid_hz`` grid; windows scoring under
    ``min_window_score`` or without movement (reference signal sd under ``min_window_activity``, in the
    signal's unit: ``min_window_activity`` rad/s for angular velocity, ``min_window_activity_mps2`` m/s^2 for
    a marker's acceleration) are left out; with ``drift`` (default) a straight line offset + drift x time is fitted
    to the windows (outliers beyond ``outlier_k`` robust sd and ``outlier_floor_s`` rejected), else their
    median offset is used. The uncertainties pool the windows' scatter with ``window_lag_sd_s`` (0.5 ms, the
    per-window lag scatter of simulated trials) counted as two windows. ``filter``: marker low-pass (6 Hz, 2nd order); ``cluster``: ``auto`` (search the
    rigid marker set that moves with the IMU, :mod:`imulog.process.alignment_search`), ``oxy`` (markers
    O, X, Y as in the thesis) or ``svd`` (the ``markers`` given, >= 3; one marker aligns on its
    acceleration); ``markers`` names with or without the ``Subject:`` prefix; ``bias_min_static_s``: static
    periods (gyro norm < 0.1 rad/s) at least this long give the gyroscope bias removed before the rotation
    fit. A trial too short for three windows is cut into up to ``short_windows`` windows of at least
    ``short_window_s`` (5 s) for the drift, which is applied only when its standard error is at most
    ``max_drift_uncertainty_ppm`` (20 ppm), else reported as not estimable. ``gyro_lowpass`` (off by default
    until the tests built on the old behaviour are reviewed): the gyroscope is low-passed like the markers before
    it is compared with them (:func:`gyro_like_markers`). ``poor_*`` thresholds flag a poor alignment (``quality``); under ``min_valid_score`` there is no
    alignment at all (the step fails and writes nothing).
    """

    window_s: float = 30.0
    window_start_s: float = 0.0
    max_lag_s: float = 60.0
    drift: bool = True
    drift_end_margin_s: float = 0.0
    filter: FilterParams = FilterParams()
    cluster: str = "auto"
    markers: tuple[str, ...] = ()
    grid_hz: float = 200.0
    coarse_hz: float = 50.0
    fine_lag_s: float = 0.5
    min_window_score: float = 0.5
    min_window_activity: float = 0.05
    min_window_activity_mps2: float = 0.1
    outlier_k: float = 4.0
    outlier_floor_s: float = 0.002
    window_lag_sd_s: float = 0.0005
    bias_min_static_s: float = 1.0
    search: SearchParams = SearchParams()
    min_valid_score: float = 0.5
    poor_score: float = 0.8
    poor_spread_s: float = 0.003
    poor_min_windows: int = 3
    poor_vector_match: float = 0.9
    short_window_s: float = 5.0
    short_windows: int = 6
    max_drift_uncertainty_ppm: float = 20.0
    gyro_lowpass: bool = False


def _fit_line(
    t_s: np.ndarray, y_s: np.ndarray, prior_sd_s: float = 0.0, prior_n: float = 0.0
) -> tuple[float, float, float, float, float]:
    """Least-squares ``y = a + b t`` with ``t`` centred: (a, b, se_a, se_b, residual sd) (NaN se when n < 3).

    The residual variance is pooled with a prior ``prior_sd_s`` counted as ``prior_n`` observations, so that
    three or four windows that happen to line up do not claim a precision their scatter cannot show.
    """
    n = len(t_s)
    b = float(np.polyfit(t_s, y_s, 1)[0]) if n >= 2 and np.ptp(t_s) > 0 else 0.0
    a = float(np.mean(y_s - b * t_s))
    r = y_s - a - b * t_s
    if n < 3:
        return a, b, float("nan"), float("nan"), float(np.std(r)) if n else float("nan")
    sd = float(np.sqrt((np.sum(r**2) + prior_n * prior_sd_s**2) / (n - 2 + prior_n)))
    return a, b, sd / np.sqrt(n), sd / np.sqrt(np.sum(t_s**2)), sd


def _theil_sen(t_s: np.ndarray, y_s: np.ndarray) -> tuple[float, float]:
    """Robust line ``y = a + b t``: b the median of the pairwise slopes, a the median of ``y - b t``."""
    i, j = np.triu_indices(len(t_s), k=1)
    dt = t_s[j] - t_s[i]
    ok = dt != 0
    b = float(np.median((y_s[j] - y_s[i])[ok] / dt[ok])) if ok.any() else 0.0
    return float(np.median(y_s - b * t_s)), b


def fit_clock(
    t_dev_ns: np.ndarray,
    x_dev: np.ndarray,
    t_ref_ns: np.ndarray,
    x_ref: np.ndarray,
    params: AlignmentParams = AlignmentParams(),
    coarse_offset_ns: int | None = None,
    min_activity: float | None = None,
) -> dict:
    """Clock offset and drift from two signals that should match (e.g. angular-velocity norms).

    ``min_activity`` (default ``params.min_window_activity``): windows whose reference signal varies less
    (sd, the signal's unit) are left out.

    ``x_dev`` on the device clock, ``x_ref`` on the reference clock. Returns the clock fields of
    ``imulog.alignment``: ``offset_ns`` (at ``t0_ns``), ``drift_ppm``, ``t0_ns`` (device time of the mean
    window centre, so offset and drift are uncorrelated), ``offset_uncertainty_ns`` and
    ``drift_uncertainty_ppm`` (standard errors of the line fit, None with fewer than 3 windows),
    ``drift_estimated``, ``score`` (median peak correlation of the windows used), ``coarse_score``,
    ``residual_spread_ns`` (sd of the used windows' residual lag) and ``windows`` (per window: device-time
    centre, offset, score, residual_ns, used, and why not).
    """
    t_dev = np.asarray(t_dev_ns, dtype=np.int64)
    t_ref = np.asarray(t_ref_ns, dtype=np.int64)
    span_s = (int(t_ref[-1]) - int(t_ref[0])) / NS
    coarse = estimate_lag(
        t_dev,
        x_dev,
        t_ref,
        x_ref,
        window_start_s=params.window_start_s,
        window_s=span_s,
        max_lag_s=params.max_lag_s,
        grid_hz=params.coarse_hz,
        prior_offset_ns=None,
    )
    prior = coarse.offset_ns if coarse_offset_ns is None else int(coarse_offset_ns)
    usable = span_s - params.window_start_s - params.drift_end_margin_s
    n_win = _n_windows(usable, params)
    width = usable / n_win
    windows = []
    x_ref = np.asarray(x_ref, dtype=np.float64)
    for k in range(n_win):
        start = params.window_start_s + k * width
        w = {"start_s": round(start, 3), "width_s": round(width, 3), "used": False}
        sel = (t_ref >= t_ref[0] + start * NS) & (t_ref <= t_ref[0] + (start + width) * NS)
        activity = float(np.nanstd(x_ref[sel])) if np.isfinite(x_ref[sel]).sum() > 10 else 0.0
        try:
            est = estimate_lag(
                t_dev,
                x_dev,
                t_ref,
                x_ref,
                window_start_s=start,
                window_s=width,
                max_lag_s=params.fine_lag_s,
                grid_hz=params.grid_hz,
                min_overlap=0.8,
                prior_offset_ns=prior,
            )
        except ValueError:
            w["why"] = "no overlap"
            windows.append(w)
            continue
        w.update(t_dev_center_ns=est.t_dev_center_ns, offset_ns=est.offset_ns, score=round(est.score, 4))
        if activity < (params.min_window_activity if min_activity is None else min_activity):
            w["why"] = "no movement"
        elif est.score < params.min_window_score:
            w["why"] = "low score"
        elif abs(est.offset_ns - prior) >= 0.98 * params.fine_lag_s * NS:
            w["why"] = "lag at the search limit"
        else:
            w["used"] = True
        windows.append(w)
    result: dict = {"coarse_offset_ns": int(coarse.offset_ns), "coarse_score": round(coarse.score, 4)}
    if n_win > 1 and n_win * params.window_s > usable + 1e-9:
        result["short_trial_windows_s"] = round(width, 3)
    if not any(w["used"] for w in windows):
        # nothing better than the coarse lag over the whole recording
        result.update(
            offset_ns=int(coarse.offset_ns),
            drift_ppm=0.0,
            t0_ns=int(coarse.t_dev_center_ns),
            offset_uncertainty_ns=None,
            drift_uncertainty_ppm=None,
            drift_estimated=False,
            score=float(coarse.score),
            residual_spread_ns=None,
            windows=windows,
        )
        return result
    result.update(fit_window_lags(windows, width, params))
    result["windows"] = windows
    return result


def _n_windows(usable_s: float, params: AlignmentParams) -> int:
    """Windows across ``usable_s`` seconds: about ``window_s`` each; a trial too short for three of them
    (with ``drift``) is cut into windows of at least ``short_window_s`` so that the drift is estimated from
    the whole trial (at most ``short_windows``), its uncertainty deciding whether it is applied."""
    n = max(1, int(np.floor(usable_s / params.window_s + 0.5)))
    if params.drift and n < 3 and usable_s >= 3 * params.short_window_s:
        n = max(n, min(params.short_windows, int(usable_s // params.short_window_s)))
    return n


def fit_window_lags(windows: list[dict], width_s: float, params: AlignmentParams = AlignmentParams()) -> dict:
    """Offset and drift fitted to the lags of the ``used`` windows (dicts with ``t_dev_center_ns``,
    ``offset_ns``, ``score``; from one IMU, or pooled from every IMU of one recording, which share a clock).

    Robust line (Theil-Sen, then least squares without outliers beyond ``outlier_k`` robust sd and
    ``outlier_floor_s``); windows found outliers get ``used = False, why = "outlier"`` and every used one its
    ``residual_ns`` (in place). The drift is fitted with at least 3 windows spanning 1.5 widths; when its
    standard error exceeds ``max_drift_uncertainty_ppm`` it is not estimable: drift 0, ``drift_estimated``
    False, the uncertainty kept and ``drift_note`` saying why. Returns the clock fields of :func:`fit_clock`.
    """
    used = [w for w in windows if w.get("used")]
    if not used:
        raise ValueError("no usable window to fit the clock")
    keep = np.ones(len(used), dtype=bool)
    tc = np.array([w["t_dev_center_ns"] for w in used], dtype=np.int64)
    off = np.array([w["offset_ns"] for w in used], dtype=np.int64)
    t0 = int(np.round(np.mean(tc)))
    ts = (tc - t0) / NS
    ys = (off - off[0]) / NS  # s, relative (float precision)
    can_drift = params.drift and len(used) >= 3 and np.ptp(ts) >= 1.5 * width_s
    for it in range(3):
        if can_drift and keep.sum() >= 3:
            # first pass Theil-Sen (median of pairwise slopes): one bad window at an end of the trial has the
            # leverage to tilt a least-squares line towards itself and hide from the outlier test
            a, b = _theil_sen(ts[keep], ys[keep]) if it == 0 else _fit_line(ts[keep], ys[keep])[:2]
        else:
            a, b = float(np.median(ys[keep])), 0.0
        r = ys - a - b * ts
        mad = 1.4826 * float(np.median(np.abs(r[keep] - np.median(r[keep]))))
        new = np.abs(r) <= max(params.outlier_k * mad, params.outlier_floor_s)
        if new.sum() < 2 or np.array_equal(new, keep):
            break
        keep = new
    t0 = int(np.round(np.mean(tc[keep])))
    ts = (tc - t0) / NS
    drift_ok = can_drift and keep.sum() >= 3
    note = None
    if drift_ok:
        a, b, se_a, se_b, _ = _fit_line(ts[keep], ys[keep], params.window_lag_sd_s, 2.0)
        if np.isfinite(se_b) and se_b * 1e6 > params.max_drift_uncertainty_ppm:
            note = (
                f"drift not estimable: {b * 1e6:.0f} ± {se_b * 1e6:.0f} ppm over {np.ptp(ts[keep]):.0f} s "
                f"(uncertainty > {params.max_drift_uncertainty_ppm:g} ppm)"
            )
            drift_ok, b = False, 0.0
            a = float(np.mean(ys[keep]))
    else:
        a, b = float(np.median(ys[keep])), 0.0
        n = int(keep.sum())
        sd = (
            float(np.sqrt((np.sum((ys[keep] - a) ** 2) + 2 * params.window_lag_sd_s**2) / (n + 1)))
            if n >= 3
            else float("nan")
        )
        se_a, se_b = sd / np.sqrt(n) if n >= 3 else float("nan"), float("nan")
    r = ys - a - b * ts
    for w, ri, ki in zip(used, r, keep, strict=True):
        w["residual_ns"] = int(round(ri * NS))
        if not ki:
            w["used"] = False
            w["why"] = "outlier"
    scores = [w["score"] for w in used if w["used"]]
    spread = float(np.std(r[keep], ddof=1)) if keep.sum() >= 3 else float("nan")
    out = {
        "offset_ns": int(off[0] + round(a * NS)),
        "drift_ppm": float(b * 1e6),
        "t0_ns": t0,
        "offset_uncertainty_ns": None if not np.isfinite(se_a) else int(round(se_a * NS)),
        "drift_uncertainty_ppm": None if not np.isfinite(se_b) else float(se_b * 1e6),
        "drift_estimated": bool(drift_ok),
        "score": float(np.median(scores)),
        "residual_spread_ns": None if not np.isfinite(spread) else int(round(spread * NS)),
    }
    if note:
        out["drift_note"] = note
    return out


def assess_quality(record: dict, params: AlignmentParams = AlignmentParams()) -> tuple[str, list[str]]:
    """``("good" | "poor", reasons)`` of an ``imulog.alignment`` record, graded from its residuals and their
    uncertainty (:func:`imulog.process.alignment_quality.grade`; caveats that do not make it poor, such as a
    drift not estimated on a short trial, go into ``record["quality_notes"]``)."""
    from imulog.process.alignment_quality import grade

    quality, reasons, notes = grade(
        record,
        poor_score=params.poor_score,
        poor_spread_s=params.poor_spread_s,
        poor_vector_match=params.poor_vector_match,
    )
    if notes:
        record["quality_notes"] = notes
    return quality, reasons


# --------------------------------------------------------------------------------------------
# the whole alignment


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
