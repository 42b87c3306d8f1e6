"""A small analytic reach-to-grasp trial with everything the viewer can show (for demos, tests, benchmarks).

Motion (reference clock, seconds): 2 s rest, then repetitions of 5 s: ``reach``, ``lift``, ``return_bottle``,
``return_hand`` (1 s each, minimum-jerk between waypoints) and 1 s rest. The wrist rotates about a fixed axis
``u`` by ``theta(t)``, so the gyroscope is exactly ``u * dtheta/dt`` (rad/s) in both sensor and world frames.
The IMU runs on its own device clock, ``t_ref = t_dev + offset_ns + drift_ppm*1e-6*(t_dev - t0_ns)``; the
true alignment is written to ``imulog.alignment``. Derived channels (orientation, static mask, phases) are on
the IMU device clock, Vicon-derived channels and trajectories on the reference clock, as in the archive.

This is not the project simulator (:mod:`imulog.simulate`); it exists so the viewer can be exercised and
benchmarked on a trial of any length with known timing, independently of the other layers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from imulog.model import ImuStream, Intervals, MarkerStream, PoseStream, Recording, SignalStream
from imulog.process.alignment import device_to_reference

G = 9.81  # m/s^2
PHASES = ("reach", "lift", "return_bottle", "return_hand")
LEAD_S = 2.0
REP_S = 5.0
WAYPOINTS_M = np.array([[0.0, 0.0, 0.8], [0.3, 0.05, 0.8], [0.3, 0.05, 0.9], [0.3, 0.05, 0.8], [0.0, 0.0, 0.8]])
ANGLES_RAD = np.array([0.0, 0.6, 0.9, 0.6, 0.0])
AXIS = np.array([0.2, 0.3, 1.0]) / np.linalg.norm([0.2, 0.3, 1.0])


@dataclass(frozen=True)
class SampleTrialParams:
    """Timing of the analytic trial: rates in Hz, clock offset in ns, drift in ppm."""

    duration_s: float = 30.0
    imu_rate_hz: float = 115.0
    vicon_rate_hz: float = 100.0
    offset_ns: int = 1_234_567_890
    drift_ppm: float = 40.0
    methods: tuple[str, ...] = ("zupt", "ekf", "minjerk")
    gyr_noise_rad_s: float = 0.01
    seed: int = 0
    alignment: dict = field(default_factory=dict)  # overrides of the *written* alignment (to fake a wrong one)


def n_repetitions(duration_s: float) -> int:
    """Complete repetitions that fit in ``duration_s`` seconds."""
    return max(int(np.floor((duration_s - LEAD_S) / REP_S)), 0)


def _profile(t_s: np.ndarray, duration_s: float) -> tuple[np.ndarray, ...]:
    """Phase index (-1 at rest), position (N,3) m, velocity, acceleration, angle rad, rate rad/s."""
    tau = t_s - LEAD_S
    rep = np.floor(tau / REP_S)
    within = tau - rep * REP_S
    moving = (tau >= 0) & (within < 4.0) & (rep < n_repetitions(duration_s))
    phase = np.where(moving, np.floor(within), -1).astype(np.int64)
    x = np.where(moving, within - np.floor(within), 0.0)
    s = 10 * x**3 - 15 * x**4 + 6 * x**5
    ds = 30 * x**2 - 60 * x**3 + 30 * x**4
    dds = 60 * x - 180 * x**2 + 120 * x**3
    k = np.where(moving, phase, 0)
    w0, w1 = WAYPOINTS_M[k], WAYPOINTS_M[k + 1]
    a0, a1 = ANGLES_RAD[k], ANGLES_RAD[k + 1]
    m = moving[:, None]
    pos = np.where(m, w0 + (w1 - w0) * s[:, None], WAYPOINTS_M[0])
    vel = np.where(m, (w1 - w0) * ds[:, None], 0.0)
    acc = np.where(m, (w1 - w0) * dds[:, None], 0.0)
    angle = np.where(moving, a0 + (a1 - a0) * s, 0.0)
    rate = np.where(moving, (a1 - a0) * ds, 0.0)
    return phase, pos, vel, acc, angle, rate


def _quat(angle: np.ndarray) -> np.ndarray:
    half = angle / 2
    return np.column_stack([np.cos(half), np.sin(half)[:, None] * AXIS])


def _rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate world vectors ``v`` (N,3) into the sensor frame of sensor-to-world quaternions ``q`` (N,4)."""
    w, u = q[:, :1], -q[:, 1:]
    t = 2 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def phase_intervals_ref_ns(duration_s: float) -> tuple[np.ndarray, np.ndarray, list[str], np.ndarray]:
    """True phases on the reference clock: start ns, end ns, labels, task index (1-based)."""
    n_rep = n_repetitions(duration_s)
    starts, labels, tasks = [], [], []
    for r in range(n_rep):
        for p, label in enumerate(PHASES):
            starts.append(LEAD_S + r * REP_S + p)
            labels.append(label)
            tasks.append(r + 1)
    start = np.rint(np.asarray(starts) * 1e9).astype(np.int64)
    return start, start + 1_000_000_000, labels, np.asarray(tasks, np.int64)


def _ref_to_device(t_ref_ns: np.ndarray, alignment: dict) -> np.ndarray:
    """Inverse of the alignment formula (exact to 1 ns for small drift)."""
    t = t_ref_ns - alignment["offset_ns"]
    for _ in range(2):
        t = t_ref_ns - (device_to_reference(t, alignment) - t)
    return t


def sample_recording(params: SampleTrialParams | None = None) -> Recording:
    """Build the analytic trial as an :class:`imulog.model.Recording` with derived channels."""
    p = params or SampleTrialParams()
    rng = np.random.default_rng(p.seed)
    true_alignment = {
        "reference": "/markers/vicon",
        "imu": "/imu/wrist",
        "offset_ns": int(p.offset_ns),
        "drift_ppm": float(p.drift_ppm),
        "t0_ns": 0,
        "rotation_imu_to_cluster": [1.0, 0.0, 0.0, 0.0],
        "rotation_global_to_world": [1.0, 0.0, 0.0, 0.0],
        "method": "truth",
        "score": 1.0,
    }
    # IMU on its device clock, covering the reference window [0, duration] with 0.5 s margins
    t_dev0 = _ref_to_device(np.array([-500_000_000], np.int64), true_alignment)[0]
    n_imu = int((p.duration_s + 1.0) * p.imu_rate_hz)
    t_dev = t_dev0 + np.rint(np.arange(n_imu) * (1e9 / p.imu_rate_hz)).astype(np.int64)
    t_imu_ref = device_to_reference(t_dev, true_alignment)
    phase, _, _, acc_w, angle, rate = _profile(t_imu_ref / 1e9, p.duration_s)
    q_imu = _quat(angle)
    gyr = rate[:, None] * AXIS + rng.normal(0.0, p.gyr_noise_rad_s, (n_imu, 3))
    acc = _rotate_inverse(q_imu, acc_w + [0.0, 0.0, G]) + rng.normal(0.0, 0.02, (n_imu, 3))
    mag = _rotate_inverse(q_imu, np.tile([20.0, 0.0, -40.0], (n_imu, 1)))
    imu = ImuStream("wrist", t_dev, acc=acc, gyr=gyr, mag=mag, meta={"rate_hz": p.imu_rate_hz})

    # Vicon on the reference clock
    n_v = int(p.duration_s * p.vicon_rate_hz)
    t_v = np.rint(np.arange(n_v) * (1e9 / p.vicon_rate_hz)).astype(np.int64)
    _, pos, _, _, angle_v, rate_v = _profile(t_v / 1e9, p.duration_s)
    q_v = _quat(angle_v)
    offsets = np.array([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0.03, 0.03, 0.02]], dtype=float)
    # rotate marker offsets sensor->world: v' = v + w t + u x t with t = 2 u x v
    markers = np.empty((n_v, 4, 3))
    for i, off in enumerate(offsets):
        v = np.tile(off, (n_v, 1))
        w, u = q_v[:, :1], q_v[:, 1:]
        t = 2 * np.cross(u, v)
        markers[:, i] = pos + v + w * t + np.cross(u, t)
    gap = (t_v > 7e9) & (t_v < 7.3e9)  # an occluded marker
    markers[gap, 3] = np.nan
    vicon = MarkerStream("vicon", t_v, ["O", "X", "Y", "A"], markers)

    derived_signals = [
        SignalStream("/derived/orientation/wrist", t_dev, ["qw", "qx", "qy", "qz"], ["1"] * 4, q_imu),
        SignalStream("/derived/static/wrist", t_dev, ["static"], ["1"], (phase < 0).astype(float)),
        SignalStream("/derived/vicon/angular_velocity", t_v, ["wx", "wy", "wz"], ["rad/s"] * 3, rate_v[:, None] * AXIS),
    ]
    for i, method in enumerate(p.methods):
        drift = np.outer(t_v / 1e9, [0.0006 * (i + 1), -0.0004 * i, 0.0002])  # m/s
        derived_signals.append(
            SignalStream(f"/derived/trajectory/{method}", t_v, ["x", "y", "z"], ["m"] * 3, pos + drift, "world")
        )
    start_ref, end_ref, labels, tasks = phase_intervals_ref_ns(p.duration_s)
    phases = Intervals(
        "/derived/phases/wrist",
        _ref_to_device(start_ref, true_alignment),
        _ref_to_device(end_ref, true_alignment),
        labels,
        tasks,
    )
    cluster = PoseStream("/derived/vicon/cluster_pose", t_v, pos, q_v)
    written_alignment = {**true_alignment, **p.alignment}
    evaluation = {
        f"rmse_{m}_cm": float(100 * np.sqrt(np.mean(np.sum((s.values - pos) ** 2, axis=1))))
        for m, s in zip(p.methods, derived_signals[3:], strict=True)
    }
    return Recording(
        imus=[imu],
        markers=[vicon],
        signals=derived_signals,
        events=[phases],
        poses=[cluster],
        metadata={
            "imulog.trial": {"subject": "S00", "trial": "1", "task": "r2g", "side": "right"},
            "imulog.alignment": written_alignment,
            "imulog.evaluation": evaluation,
            "imulog.timing": {"imu": "/imu/wrist", "clock": "device"},  # phases written on the device clock
        },
    )
