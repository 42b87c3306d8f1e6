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

__all__ = [
    "AlignmentParams",
    "FilterParams",
    "LagEstimate",
    "align",
    "angular_velocity_from_rotations",
    "cluster_frame_oxy",
    "cluster_frame_svd",
    "device_to_reference",
    "estimate_lag",
    "estimate_rotation_imu_to_cluster",
    "lowpass_markers",
    "reference_to_device",
    "rotation_global_to_world",
]

NS = 1_000_000_000


# --------------------------------------------------------------------------------------------
# clock model


def _int_ns(value) -> int:
    """An int64-ns field that may come back from metadata as int, float or string."""
    if value is None or value == "":
        return 0
    if isinstance(value, str):
        try:
            return int(value)
        except ValueError:
            return int(round(float(value)))
    return int(round(value)) if isinstance(value, float) else int(value)


def _clock(alignment: dict) -> tuple[int, float, int]:
    drift = alignment.get("drift_ppm", 0.0)
    return _int_ns(alignment.get("offset_ns", 0)), float(drift or 0.0), _int_ns(alignment.get("t0_ns", 0))


def device_to_reference(t_dev_ns: np.ndarray | int, alignment: dict) -> np.ndarray:
    """Map IMU device time to the reference clock: ``t_dev + offset + drift_ppm*1e-6*(t_dev - t0)``.

    ``alignment`` is an ``imulog.alignment`` record (keys ``offset_ns``, ``drift_ppm``, ``t0_ns``;
    missing drift or t0 mean 0). Returns int64 ns (rounded to the nearest ns).
    """
    t = np.asarray(t_dev_ns, dtype=np.int64)
    offset, drift, t0 = _clock(alignment)
    out = t + offset
    if drift != 0.0:
        out = out + np.round(drift * 1e-6 * (t - t0).astype(np.float64)).astype(np.int64)
    return out


def reference_to_device(t_ref_ns: np.ndarray | int, alignment: dict) -> np.ndarray:
    """Inverse of :func:`device_to_reference` (int64 ns)."""
    t = np.asarray(t_ref_ns, dtype=np.int64)
    offset, drift, t0 = _clock(alignment)
    k = drift * 1e-6
    # t_ref - t0 - offset = (t_dev - t0) * (1 + k)
    rel = (t - t0 - offset).astype(np.float64) / (1.0 + k)
    return t0 + np.round(rel).astype(np.int64)


# --------------------------------------------------------------------------------------------
# marker filtering with gap handling


@dataclass(frozen=True)
class FilterParams:
    """Marker low-pass: ``cutoff_hz`` 6 and ``order`` 2 (R2G thesis, after Bergamini et al.),
    zero-phase (forward-backward); gaps up to ``max_gap_s`` (0.1 s) are interpolated (cubic),
    longer gaps stay NaN and are reported."""

    cutoff_hz: float = 6.0
    order: int = 2
    max_gap_s: float = 0.1


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def _fill_short_gaps(x: np.ndarray, max_gap: int) -> tuple[np.ndarray, np.ndarray]:
    """Interpolate interior NaN runs of at most ``max_gap`` samples in the 1-D ``x``.

    Returns the filled copy and the mask of samples that stay missing (long gaps and the ends).
    """
    x = x.copy()
    bad = ~np.isfinite(x)
    if not bad.any() or bad.all():
        return x, bad
    idx = np.arange(len(x))
    good = ~bad
    starts, ends = _runs(bad)
    fill = np.zeros(len(x), dtype=bool)
    for s, e in zip(starts, ends, strict=True):
        if s > 0 and e < len(x) and e - s <= max_gap:
            fill[s:e] = True
    if fill.any():
        from scipy.interpolate import CubicSpline, interp1d

        gi = idx[good]
        if len(gi) >= 4:
            x[fill] = CubicSpline(gi, x[good])(idx[fill])
        else:
            x[fill] = interp1d(gi, x[good])(idx[fill])
    return x, bad & ~fill


def lowpass_markers(
    pos_m: np.ndarray, rate_hz: float, params: FilterParams = FilterParams()
) -> tuple[np.ndarray, np.ndarray]:
    """Zero-phase Butterworth low-pass of marker trajectories with gap handling.

    ``pos_m``: (N, M, 3) or (N, 3) positions in m with NaN gaps. Short gaps (<= max_gap_s) are
    interpolated before filtering; every finite run is then filtered separately, so long gaps
    stay NaN (never zero). Returns ``(filtered, long_gap_mask)`` with the mask (N, M) or (N,)
    True where the marker is still missing.
    """
    pos = np.asarray(pos_m, dtype=np.float64)
    squeeze = pos.ndim == 2
    p = pos[:, None, :] if squeeze else pos
    n, m, _ = p.shape
    out = np.full_like(p, np.nan)
    missing = np.zeros((n, m), dtype=bool)
    from scipy import signal  # imported here: the viewer's clock map must not pay for scipy.signal

    sos = signal.butter(params.order, params.cutoff_hz, btype="low", fs=rate_hz, output="sos")
    max_gap = int(round(params.max_gap_s * rate_hz))
    for j in range(m):
        cols = []
        miss = None
        for c in range(3):
            filled, still = _fill_short_gaps(p[:, j, c], max_gap)
            cols.append(filled)
            miss = still if miss is None else (miss | still)
        missing[:, j] = miss
        starts, ends = _runs(~miss)
        for s, e in zip(starts, ends, strict=True):
            seg = np.stack([col[s:e] for col in cols], axis=1)
            padlen = min(3 * (2 * len(sos) + 1) * 2, e - s - 1)
            if e - s > 3 * params.order + 2 and padlen > 0:
                out[s:e, j] = signal.sosfiltfilt(sos, seg, axis=0, padlen=padlen)
            else:
                out[s:e, j] = seg
    if squeeze:
        return out[:, 0], missing[:, 0]
    return out, missing


# --------------------------------------------------------------------------------------------
# cluster orientation


def cluster_frame_oxy(o: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Cluster-to-world rotation matrices (N, 3, 3) from markers O, X, Y (N, 3) each.

    The thesis's construction: x axis along X - O, z = x cross (Y - O) (normalised), y = z cross x.
    The columns of each matrix are the cluster axes in world coordinates (the thesis's
    R^{ijk}_{IJK} is the transpose). NaN where a marker is missing.
    """
    ex = np.asarray(x, dtype=np.float64) - o
    ex /= np.linalg.norm(ex, axis=-1, keepdims=True)
    sup = np.asarray(y, dtype=np.float64) - o
    ez = np.cross(ex, sup)
    ez /= np.linalg.norm(ez, axis=-1, keepdims=True)
    ey = np.cross(ez, ex)
    return np.stack([ex, ey, ez], axis=-1)


def cluster_frame_svd(pos_m: np.ndarray, local_m: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rigid fit (Kabsch/SVD) of a marker cluster in every frame.

    ``pos_m`` (N, M, 3) world positions with NaN for missing markers; ``local_m`` (M, 3) the
    markers' coordinates in the cluster frame (default: their mean shape over the frames where all
    are visible, expressed in the axes of the first such frame, so the first complete frame has
    identity orientation). Frames with fewer than 3 visible markers give NaN.
    Returns ``(R_cluster_to_world (N, 3, 3), origin_m (N, 3))`` with origin the world position of
    the local frame's origin (the shape's centroid when ``local_m`` is not given).
    """
    pos = np.asarray(pos_m, dtype=np.float64)
    n, m, _ = pos.shape
    valid = np.all(np.isfinite(pos), axis=2)
    if local_m is None:
        full = np.flatnonzero(valid.all(axis=1))
        if len(full) == 0:
            raise ValueError("no frame with all cluster markers visible: pass local_m")
        first = pos[full[0]] - pos[full[0]].mean(axis=0)
        # average shape: align every complete frame to the first one, then average
        rs, _ = cluster_frame_svd(pos[full], first)
        shapes = np.einsum("nji,nmj->nmi", rs, pos[full] - pos[full].mean(axis=1, keepdims=True))
        local = shapes.mean(axis=0)
    else:
        local = np.asarray(local_m, dtype=np.float64)
        if local.shape != (m, 3):
            raise ValueError(f"local_m must have shape ({m}, 3), got {local.shape}")
    w = valid.astype(np.float64)
    cnt = w.sum(axis=1)
    p = np.where(valid[..., None], pos, 0.0)
    # weighted centroids (local centroid over the visible subset)
    with np.errstate(invalid="ignore", divide="ignore"):
        cw = p.sum(axis=1) / cnt[:, None]
        cl = (w @ local) / cnt[:, None]
    a = (local[None] - cl[:, None]) * w[..., None]  # (N, M, 3)
    b = (p - cw[:, None]) * w[..., None]
    h = np.einsum("nmi,nmj->nij", a, b)  # sum local_i * world_j
    ok = cnt >= 3
    r = np.full((n, 3, 3), np.nan)
    if ok.any():
        u, _, vt = np.linalg.svd(h[ok])
        d = np.sign(np.linalg.det(np.einsum("nij,njk->nik", u, vt)))
        dm = np.zeros((ok.sum(), 3, 3))
        dm[:, 0, 0] = 1
        dm[:, 1, 1] = 1
        dm[:, 2, 2] = d
        # R = V D U^T maps local to world
        r[ok] = np.einsum("nji,njk,nlk->nil", vt, dm, u)
    origin = np.full((n, 3), np.nan)
    origin[ok] = cw[ok] - np.einsum("nij,nj->ni", r[ok], cl[ok])
    return r, origin


# --------------------------------------------------------------------------------------------
# angular velocity from rotation matrices


def angular_velocity_from_rotations(r_c2w: np.ndarray, rate_hz: float, *, frame: str = "local") -> np.ndarray:
    """Angular velocity (N, 3) rad/s from consecutive cluster-to-world rotation matrices.

    The thesis's eqs. 2.6-2.10 (Chardonnens): the relative rotation between samples,
    ``dR = R(t)^T R(t + dt)`` in the cluster (``local``) frame, gives axis and angle; here the
    central difference ``R(t-dt)^T R(t+dt)`` over ``2 dt`` is used (second-order accurate, no
    half-sample delay), one-sided at the ends. ``frame="world"`` returns ``R(t) w_local``.
    NaN where a neighbour is missing.
    """
    r = np.asarray(r_c2w, dtype=np.float64)
    n = len(r)
    w = np.full((n, 3), np.nan)
    if n < 2:
        return w
    q = quat.from_rotation_matrix(np.nan_to_num(r))
    bad = ~np.all(np.isfinite(r.reshape(n, 9)), axis=1)
    q[bad] = np.nan
    dt = 1.0 / rate_hz
    if n >= 3:
        d = quat.multiply(quat.conjugate(q[:-2]), q[2:])
        w[1:-1] = quat.to_rotation_vector(np.nan_to_num(d, nan=1.0)) / (2 * dt)
        w[1:-1][~np.all(np.isfinite(d), axis=1)] = np.nan
    for i, (j0, j1) in ((0, (0, 1)), (n - 1, (n - 2, n - 1))):
        d = quat.multiply(quat.conjugate(q[j0]), q[j1])
        w[i] = quat.to_rotation_vector(d) / dt if np.all(np.isfinite(d)) else np.nan
    if frame == "world":
        w = np.einsum("nij,nj->ni", r, w)
    elif frame != "local":
        raise ValueError(f"frame must be 'local' or 'world', got {frame!r}")
    return w


# --------------------------------------------------------------------------------------------
# time lag by cross-correlation


@dataclass
class LagEstimate:
    """``offset_ns``: t_ref - t_dev at the window; ``score``: peak normalised correlation (0-1);
    ``t_dev_center_ns``: device time of the window's centre."""

    offset_ns: int
    score: float
    t_dev_center_ns: int


def _uniform(t_ns: np.ndarray, x: np.ndarray, t0_ns: int, rate_hz: float, n: int) -> np.ndarray:
    """``x`` linearly interpolated at ``t0 + k / rate`` (k < n); NaN -> 0 after mean removal."""
    grid = t0_ns + np.round(np.arange(n) * (NS / rate_hz)).astype(np.int64)
    ok = np.isfinite(x)
    y = np.interp(grid.astype(np.float64), t_ns[ok].astype(np.float64), x[ok], left=np.nan, right=np.nan)
    return y


def estimate_lag(
    t_dev_ns: np.ndarray,
    w_dev_norm: np.ndarray,
    t_ref_ns: np.ndarray,
    w_ref_norm: np.ndarray,
    *,
    window_start_s: float = 0.0,
    window_s: float = 120.0,
    max_lag_s: float = 60.0,
    grid_hz: float = 200.0,
    min_overlap: float = 0.5,
) -> LagEstimate:
    """Clock offset by normalised cross-correlation of angular-velocity norms.

    The reference window is ``[t_ref[0] + window_start_s, + window_s]`` (default the first two
    minutes, the R2G protocol's static period and wave). The device signal is searched over the
    same stretch of its own clock +- ``max_lag_s``. Both are put on a ``grid_hz`` grid, mean-removed
    and correlated (normalised by the local energy of the overlapping device stretch, so a loud
    movement elsewhere does not win); the peak is refined to sub-sample precision by a parabola.
    """
    t_dev_ns = np.asarray(t_dev_ns, dtype=np.int64)
    t_ref_ns = np.asarray(t_ref_ns, dtype=np.int64)
    ws = int(round(window_start_s * NS))
    ref0 = int(t_ref_ns[0]) + ws
    # a recording shorter than the window: correlate what there is (else no lag reaches min_overlap)
    window_s = max(min(window_s, (int(t_ref_ns[-1]) - ref0) / NS), 0.0)
    na = int(window_s * grid_hz)
    a = _uniform(t_ref_ns, np.asarray(w_ref_norm, dtype=np.float64), ref0, grid_hz, na)
    dev0 = int(t_dev_ns[0]) + ws - int(round(max_lag_s * NS))
    nb = int((window_s + 2 * max_lag_s) * grid_hz)
    b = _uniform(t_dev_ns, np.asarray(w_dev_norm, dtype=np.float64), dev0, grid_hz, nb)
    a_ok = np.isfinite(a)
    if a_ok.sum() < 10:
        raise ValueError("reference angular velocity has no samples in the alignment window")
    a = np.where(a_ok, a - np.nanmean(a), 0.0)
    b_ok = np.isfinite(b)
    if b_ok.sum() < 10:
        raise ValueError("device angular velocity has no samples in the alignment window")
    b = np.where(b_ok, b - np.nanmean(b), 0.0)
    from scipy import signal

    c = signal.correlate(b, a, mode="full", method="fft")
    lags = signal.correlation_lags(len(b), len(a), mode="full")
    # local energy of b under the template, and overlap fraction
    cs = np.concatenate([[0.0], np.cumsum(b * b)])
    cok = np.concatenate([[0], np.cumsum(b_ok.astype(np.int64))])
    lo = np.clip(lags, 0, len(b))
    hi = np.clip(lags + len(a), 0, len(b))
    energy = cs[hi] - cs[lo]
    overlap = (cok[hi] - cok[lo]) / len(a)
    norm_a = np.sqrt(np.sum(a * a))
    with np.errstate(invalid="ignore", divide="ignore"):
        ncc = c / (norm_a * np.sqrt(energy))
    ncc[~np.isfinite(ncc) | (overlap < min_overlap)] = -np.inf
    if not np.isfinite(ncc).any():
        raise ValueError(
            f"no clock offset within +-{max_lag_s:g} s overlaps the {window_s:g} s reference window by "
            f">= {min_overlap:.0%}: check --window-start, --window and --max-lag against the recording"
        )
    k = int(np.argmax(ncc))
    frac = 0.0
    if 0 < k < len(ncc) - 1 and np.isfinite(ncc[k - 1]) and np.isfinite(ncc[k + 1]):
        y0, y1, y2 = ncc[k - 1], ncc[k], ncc[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            frac = 0.5 * (y0 - y2) / den
    lag = (lags[k] + frac) / grid_hz  # s: b[n + lag] ~ a[n]
    # device time dev0 + (n + lag)/grid matches reference time ref0 + n/grid
    offset_ns = int(round(ref0 - dev0 - lag * NS))
    center = int(round(ref0 + window_s * NS / 2)) - offset_ns
    return LagEstimate(offset_ns=offset_ns, score=float(ncc[k]), t_dev_center_ns=center)


# --------------------------------------------------------------------------------------------
# constant rotations


def _wahba(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation matrix R minimising sum |b_i - R a_i|^2 (SVD solution of Wahba's problem)."""
    h = a.T @ b
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def estimate_rotation_imu_to_cluster(w_imu_rad_s: np.ndarray, w_cluster_rad_s: np.ndarray) -> tuple[np.ndarray, float]:
    """Constant rotation (quaternion) from IMU sensor frame to cluster frame, and residual RMS rad/s.

    Least squares on time-aligned angular velocities, ``w_cluster ~ R w_imu`` (Chardonnens et al.
    2012 align inertial and optical frames from angular velocities); rows with NaN are skipped.
    """
    a = np.asarray(w_imu_rad_s, dtype=np.float64)
    b = np.asarray(w_cluster_rad_s, dtype=np.float64)
    ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    if ok.sum() < 10:
        raise ValueError("too few common angular-velocity samples to estimate the IMU-to-cluster rotation")
    r = _wahba(a[ok], b[ok])
    resid = b[ok] - a[ok] @ r.T
    return quat.from_rotation_matrix(r), float(np.sqrt(np.mean(np.sum(resid**2, axis=1))))


def rotation_global_to_world(
    q_imu_s2g: np.ndarray, q_cluster_to_world: np.ndarray, q_imu_to_cluster: np.ndarray
) -> np.ndarray:
    """Constant rotation from the IMU's global frame to the Vicon world frame (quaternion).

    With time-aligned samples, ``q_c2w(t) * q_i2c = q_g2w * q_s2g(t)``; the chordal mean of
    ``q_c2w * q_i2c * q_s2g^-1`` over the finite rows is returned.
    """
    e = quat.multiply(quat.multiply(q_cluster_to_world, q_imu_to_cluster), quat.conjugate(q_imu_s2g))
    ok = np.all(np.isfinite(e), axis=1)
    return quat.average(e[ok])


# --------------------------------------------------------------------------------------------
# the whole alignment


@dataclass(frozen=True)
class AlignmentParams:
    """IMU-to-Vicon alignment settings.

    ``window_s`` 120 (the thesis's first two minutes) starting ``window_start_s`` after the
    reference's first sample; ``max_lag_s`` 60 the search range; ``drift``: estimate clock drift
    from a second window of the same length ending ``drift_end_margin_s`` before the reference's
    last sample; ``filter``: marker low-pass (6 Hz, 2nd order); ``cluster``: ``oxy`` (markers
    O, X, Y as in the thesis) or ``svd`` (all markers in ``markers``, >= 3); ``grid_hz`` the
    correlation grid; ``bias_min_static_s``: static periods (gyro norm < 0.1 rad/s) at least this
    long give the gyroscope bias removed before the rotation fit.
    """

    window_s: float = 120.0
    window_start_s: float = 0.0
    max_lag_s: float = 60.0
    drift: bool = False
    drift_end_margin_s: float = 0.0
    filter: FilterParams = FilterParams()
    cluster: str = "oxy"
    markers: tuple[str, ...] = ("O", "X", "Y", "A")
    grid_hz: float = 200.0
    bias_min_static_s: float = 1.0


@dataclass
class ClusterKinematics:
    """Cluster pose and angular velocity on the reference clock."""

    t_ns: np.ndarray
    origin_m: np.ndarray
    quat_c2w: np.ndarray
    omega_local_rad_s: np.ndarray
    missing: np.ndarray  # (N,) True where the pose could not be computed


def _oxy_local(names: list[str], pos: np.ndarray) -> np.ndarray | None:
    """Marker coordinates in the thesis's O/X/Y cluster frame (mean over complete frames), so that
    the SVD fit reports the same frame as the O/X/Y construction; None without O, X and Y."""
    if not all(m in names for m in ("O", "X", "Y")):
        return None
    o, x, y = (pos[:, names.index(m)] for m in ("O", "X", "Y"))
    full = np.all(np.isfinite(pos.reshape(len(pos), -1)), axis=1)
    if not full.any():
        return None
    r = cluster_frame_oxy(o[full], x[full], y[full])
    return np.einsum("nji,nmj->mi", r, pos[full] - o[full][:, None]) / full.sum()


def cluster_kinematics(
    t_ns: np.ndarray, labels: list[str], pos_m: np.ndarray, rate_hz: float, params: AlignmentParams = AlignmentParams()
) -> ClusterKinematics:
    """Filter the markers, build the cluster pose and its angular velocity (cluster frame)."""
    if params.cluster == "oxy":
        need = ["O", "X", "Y"]
    elif params.cluster == "svd":
        need = [m for m in params.markers if m in labels]
        if len(need) < 3:
            raise ValueError(f"the SVD cluster fit needs >= 3 of the markers {params.markers}, found {need}")
    else:
        raise ValueError(f"cluster method must be 'oxy' or 'svd', got {params.cluster!r}")
    missing_labels = [m for m in need if m not in labels]
    if missing_labels:
        raise ValueError(f"marker(s) {', '.join(missing_labels)} not in the marker stream (have {', '.join(labels)})")
    idx = [labels.index(m) for m in need]
    filt, gaps = lowpass_markers(np.asarray(pos_m)[:, idx], rate_hz, params.filter)
    if params.cluster == "oxy":
        r = cluster_frame_oxy(filt[:, 0], filt[:, 1], filt[:, 2])
        origin = filt[:, 0]
    else:
        r, origin = cluster_frame_svd(filt, _oxy_local(need, filt))
    missing = ~np.all(np.isfinite(r.reshape(len(r), 9)), axis=1)
    q = np.full((len(r), 4), np.nan)
    if (~missing).any():
        q[~missing] = quat.from_rotation_matrix(r[~missing])
    omega = angular_velocity_from_rotations(r, rate_hz)
    return ClusterKinematics(np.asarray(t_ns, dtype=np.int64), origin, q, omega, missing)


def _interp_rows(t_src: np.ndarray, x: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    out = np.full((len(t_dst), x.shape[1]), np.nan)
    ok = np.all(np.isfinite(x), axis=1)
    ts = t_src[ok].astype(np.float64)
    for c in range(x.shape[1]):
        out[:, c] = np.interp(t_dst.astype(np.float64), ts, x[ok, c], left=np.nan, right=np.nan)
    return out


def align(
    t_imu_ns: np.ndarray,
    gyr_rad_s: np.ndarray,
    cluster: ClusterKinematics,
    params: AlignmentParams = AlignmentParams(),
    q_imu_s2g: np.ndarray | None = None,
) -> dict:
    """Full alignment of one IMU with one marker cluster; returns the ``imulog.alignment`` fields.

    ``t_imu_ns``/``gyr_rad_s`` on the device clock; ``cluster`` from :func:`cluster_kinematics` on
    the reference clock; ``q_imu_s2g`` (optional, the IMU orientation on the device clock) enables
    ``rotation_global_to_world``. Keys: offset_ns, drift_ppm, t0_ns, rotation_imu_to_cluster,
    rotation_global_to_world (None without ``q_imu_s2g``), method, score, plus diagnostics
    (rotation_residual_rad_s, windows).
    """
    t_imu = np.asarray(t_imu_ns, dtype=np.int64)
    gyr = np.asarray(gyr_rad_s, dtype=np.float64)
    wn_dev = np.linalg.norm(gyr, axis=1)
    wn_ref = np.linalg.norm(cluster.omega_local_rad_s, axis=1)
    kw = dict(window_s=params.window_s, max_lag_s=params.max_lag_s, grid_hz=params.grid_hz)
    first = estimate_lag(t_imu, wn_dev, cluster.t_ns, wn_ref, window_start_s=params.window_start_s, **kw)
    result = {
        "offset_ns": int(first.offset_ns),
        "drift_ppm": 0.0,
        "t0_ns": int(first.t_dev_center_ns),
        "score": first.score,
        "windows": [{"t_dev_center_ns": first.t_dev_center_ns, "offset_ns": first.offset_ns, "score": first.score}],
    }
    if params.drift:
        span_s = (cluster.t_ns[-1] - cluster.t_ns[0]) / NS
        start2 = span_s - params.drift_end_margin_s - params.window_s
        if start2 <= params.window_start_s + params.window_s:
            raise ValueError(
                f"recording of {span_s:.0f} s too short for two {params.window_s:.0f} s windows (drift estimation): "
                "shorten the window (--window) or leave out --drift"
            )
        second = estimate_lag(t_imu, wn_dev, cluster.t_ns, wn_ref, window_start_s=start2, **kw)
        dt = second.t_dev_center_ns - first.t_dev_center_ns
        result["drift_ppm"] = (second.offset_ns - first.offset_ns) / dt * 1e6
        result["score"] = min(first.score, second.score)
        result["windows"].append(
            {"t_dev_center_ns": second.t_dev_center_ns, "offset_ns": second.offset_ns, "score": second.score}
        )
    # IMU samples on the reference clock, gyro resampled at the Vicon times
    t_imu_ref = device_to_reference(t_imu, result)
    # gyroscope bias from the IMU's static periods (it would tilt the least-squares rotation)
    from imulog.process.orientation import StaticParams, detect_static

    imu_rate = (len(t_imu) - 1) / ((t_imu[-1] - t_imu[0]) * 1e-9)
    still = detect_static(
        np.nan_to_num(gyr, nan=np.inf), imu_rate, StaticParams(min_duration_s=params.bias_min_static_s)
    )
    bias = np.nanmean(gyr[still], axis=0) if still.sum() > 0 else np.zeros(3)
    result["gyr_bias_rad_s"] = [float(v) for v in bias]
    gyr_at_ref = _interp_rows(t_imu_ref, gyr - bias, cluster.t_ns)
    q_i2c, resid = estimate_rotation_imu_to_cluster(gyr_at_ref, cluster.omega_local_rad_s)
    result["rotation_imu_to_cluster"] = [float(v) for v in q_i2c]
    result["rotation_residual_rad_s"] = resid
    result["rotation_global_to_world"] = None
    if q_imu_s2g is not None:
        from imulog.process.resample import resample_quaternions

        q_at_ref = resample_quaternions(t_imu_ref, np.asarray(q_imu_s2g, dtype=np.float64), cluster.t_ns)
        ok = np.all(np.isfinite(q_at_ref), axis=1) & np.all(np.isfinite(cluster.quat_c2w), axis=1)
        q_g2w = rotation_global_to_world(q_at_ref[ok], cluster.quat_c2w[ok], q_i2c)
        result["rotation_global_to_world"] = [float(v) for v in q_g2w]
    result["method"] = (
        f"xcorr-angular-velocity-norm(window={params.window_s:g}s{', drift' if params.drift else ''})"
        f"+wahba-angular-velocity;cluster={params.cluster}"
    )
    return result
