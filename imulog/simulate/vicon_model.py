"""Vicon marker cluster rigidly mounted on the IMU: geometry, marker noise and occlusion gaps.

Cluster frame: origin at marker ``O`` (= the IMU's sensing origin, no lever arm), ``X`` on its
+x axis, ``Y`` on its +y axis, ``A`` an asymmetric fourth marker (so the cluster can be labelled
unambiguously). A cluster pose computed as ``x = unit(X - O)``, ``z = unit(x × (Y - O))``,
``y = z × x`` reproduces the cluster frame exactly. The IMU sensor frame is turned into the
cluster frame by the constant ``rotation_imu_to_cluster`` (``v_cluster = R_ic v_imu``), so the
cluster's orientation in the world is ``q_world_sensor * conj(q_ic)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imulog.process import quaternion as quat

LABELS = ("O", "X", "Y", "A")


@dataclass(frozen=True)
class ViconParams:
    marker_offsets_m: tuple[tuple[float, float, float], ...] = (
        (0.0, 0.0, 0.0),
        (0.045, 0.0, 0.0),
        (0.0, 0.035, 0.0),
        (0.03, 0.025, 0.012),
    )  # O, X, Y, A in the cluster frame: a BlueBuddy-sized (~5 x 4 cm) box
    noise_mm: float = 0.2  # per coordinate; Vicon T-series residuals are sub-millimetre
    imu_to_cluster_sd_deg: float = 3.0  # mounting misalignment of the cluster on the IMU box
    gap_rate_per_min: float = 1.0  # occlusions per marker per minute
    gap_duration_s: tuple[float, float] = (0.05, 0.6)  # uniform range
    subject_name: str = (
        ""  # 'Subject:' prefix of the Nexus marker names ('' -> plain O, X, Y, A as the conventions name them)
    )
    decimals: int = 3  # mm decimals written in the CSV (1 um; Nexus writes ~6 significant digits)
    marker_names: tuple[str, ...] = LABELS  # names of the cluster markers; fewer names keep the first offsets
    extra_segments: tuple[str, ...] = ()  # markers on other segments too: "trunk", "upper_arm" (extra_markers)


def draw_imu_to_cluster(params: ViconParams, rng: np.random.Generator) -> np.ndarray:
    """Constant rotation IMU sensor frame -> cluster frame (a few degrees about a random axis)."""
    rv = rng.normal(0.0, np.radians(params.imu_to_cluster_sd_deg), 3)
    return quat.from_rotation_vector(rv)


def marker_positions(
    position_m: np.ndarray, q_world_sensor: np.ndarray, q_imu_to_cluster: np.ndarray, params: ViconParams
) -> np.ndarray:
    """True marker positions (N, 4, 3) m."""
    q_cluster = quat.multiply(q_world_sensor, quat.conjugate(q_imu_to_cluster))
    offsets = np.asarray(params.marker_offsets_m, dtype=float)
    out = np.empty((len(position_m), len(offsets), 3))
    for k, off in enumerate(offsets):
        out[:, k] = position_m + quat.rotate(q_cluster, np.broadcast_to(off, position_m.shape))
    return out


def all_markers(
    t_s: np.ndarray,
    position_m: np.ndarray,
    q_world_sensor: np.ndarray,
    q_imu_to_cluster: np.ndarray,
    params: ViconParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[str]]:
    """True positions (N, M, 3) m and names of the cluster markers (``marker_names``) and of the markers on
    the ``extra_segments`` (:mod:`imulog.simulate.extra_markers`)."""

    def as_list(v) -> list[str]:  # "--set marker_names=WRIST" or "A,B,C" arrive as one string
        return [x.strip() for x in v.split(",") if x.strip()] if isinstance(v, str) else list(v)

    names = as_list(params.marker_names)
    if not 1 <= len(names) <= len(params.marker_offsets_m) or len(set(names)) != len(names):
        raise ValueError(f"marker_names must be 1 to {len(params.marker_offsets_m)} distinct names, got {names}")
    pos = marker_positions(position_m, q_world_sensor, q_imu_to_cluster, params)[:, : len(names)]
    if params.extra_segments:
        from imulog.simulate.extra_markers import segment_markers

        rate = (len(t_s) - 1) / (t_s[-1] - t_s[0]) if len(t_s) > 1 else 100.0
        extra = segment_markers(t_s, position_m, tuple(as_list(params.extra_segments)), rng, rate_hz=rate)
        pos = np.concatenate([pos, np.stack(list(extra.values()), axis=1)], axis=1)
        names += list(extra)
    return pos, names


def add_noise_and_gaps(
    pos_m: np.ndarray, rate_hz: float, params: ViconParams, rng: np.random.Generator, noise_free: bool
) -> np.ndarray:
    """Measured markers (N, M, 3) m: white noise, NaN gaps, quantised to the CSV's decimals of mm."""
    out = pos_m.copy()
    n, m, _ = out.shape
    if not noise_free:
        out += rng.normal(0.0, params.noise_mm * 1e-3, out.shape)
        duration_min = n / rate_hz / 60.0
        for k in range(m):
            n_gaps = rng.poisson(params.gap_rate_per_min * duration_min)
            for _ in range(n_gaps):
                start = int(rng.integers(1, max(2, n - 1)))
                length = max(1, int(round(rng.uniform(*params.gap_duration_s) * rate_hz)))
                out[start : min(n - 1, start + length), k] = np.nan
    scale = 10**params.decimals
    return np.round(out * 1e3 * scale) / scale * 1e-3
