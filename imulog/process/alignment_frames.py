"""Markers to cluster frames and angular velocity: low-pass filtering with gap handling, OXY and SVD (Kabsch)
cluster frames, angular velocity from consecutive rotations (Chardonnens et al.). Positions in m, rad/s.
Split from :mod:`imulog.process.alignment` (issue 24).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.param_rules import check_rules
from imulog.process import quaternion as quat

# marker filtering with gap handling


@dataclass(frozen=True)
class FilterParams:
    """Marker low-pass: ``cutoff_hz`` 6 and ``order`` 2 (R2G thesis, after Bergamini et al.),
    zero-phase (forward-backward); gaps up to ``max_gap_s`` (0.1 s) are interpolated (cubic),
    longer gaps stay NaN and are reported."""

    cutoff_hz: float = 6.0
    order: int = 2
    max_gap_s: float = 0.1
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


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
    h = np.matmul(a.transpose(0, 2, 1), b)  # sum local_i * world_j
    ok = cnt >= 3
    r = np.full((n, 3, 3), np.nan)
    if ok.any():
        u, _, vt = np.linalg.svd(h[ok])
        d = np.sign(np.linalg.det(np.matmul(u, vt)))
        vt[:, 2, :] *= d[:, None]
        # R = V D U^T maps local to world
        r[ok] = np.matmul(vt.transpose(0, 2, 1), u.transpose(0, 2, 1))
    origin = np.full((n, 3), np.nan)
    origin[ok] = cw[ok] - np.matmul(r[ok], cl[ok][:, :, None])[:, :, 0]
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
