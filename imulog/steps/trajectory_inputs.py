"""The trajectory step's inputs on one clock and in one frame: pure functions (no I/O).

* :func:`to_reference`, :func:`sample_onto`: device-clock time stamps onto the reference clock, a channel's
  samples onto another channel's time stamps;
* :func:`phase_bounds_by_repetition`: the phases of each repetition as start/end s;
* :func:`world_acceleration`: the gravity-free acceleration with the orientation re-integrated through every
  movement and anchored at its rests, rotated into the world frame of the alignment.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from imulog.model import Intervals
from imulog.process import quaternion as quat
from imulog.process.anchor_heading import restart_rests
from imulog.process.integration import rest_anchored_orientation
from imulog.process.trajectory_opt import TrajectoryParams


def to_reference(t_dev_ns: np.ndarray, alignment: dict[str, Any] | None) -> np.ndarray:
    """Device-clock ns on the reference clock (int64 ns, rounded); unchanged without an alignment."""
    if alignment is None:
        return np.asarray(t_dev_ns, dtype=np.int64)
    from imulog.process.alignment import device_to_reference

    return np.asarray(np.round(device_to_reference(np.asarray(t_dev_ns, dtype=np.int64), alignment)), dtype=np.int64)


def sample_onto(t_src: np.ndarray, values: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Nearest-sample lookup (exact when the clocks are the same)."""
    if len(t_src) == len(t_dst) and np.array_equal(t_src, t_dst):
        return values
    idx = np.clip(np.searchsorted(t_src, t_dst), 1, len(t_src) - 1)
    left = t_dst - t_src[idx - 1] <= t_src[idx] - t_dst
    return values[np.where(left, idx - 1, idx)]


def phase_bounds_by_repetition(phases: Intervals, t0_ns: int) -> dict[int, np.ndarray]:
    """{repetition: (P, 2) start/end s relative to ``t0_ns``}, phases sorted by start."""
    out: dict[int, list[tuple[float, float]]] = {}
    for s, e, k in zip(phases.start_ns, phases.end_ns, phases.task_index, strict=True):
        if k < 0:
            continue
        out.setdefault(int(k), []).append(((s - t0_ns) / 1e9, (e - t0_ns) / 1e9))
    return {k: np.asarray(sorted(v)) for k, v in out.items()}


def world_acceleration(
    acc: np.ndarray,
    q_world: np.ndarray | None,
    *,
    imu: str,
    t_dev: np.ndarray,
    t_ref: np.ndarray,
    rest: np.ndarray | None,
    given_rest: np.ndarray | None,
    gyr: tuple[np.ndarray, np.ndarray] | None,
    phases: Intervals | None,
    alignment: dict[str, Any] | None,
    params: TrajectoryParams,
    chain_rest_s: float,
    acc_sensor: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray | None, bool, str, str]:
    """``(acc, q_world, anchored, frame, clock)``: ``acc`` (N, 3) m/s^2 gravity-free in the IMU global frame.

    With the gyroscope ``gyr`` (``(t_ns, (N, 3) rad/s)``, device clock), the orientation ``q_world`` and the rest
    mask ``rest`` (the accelerometer-checked rests; ``given_rest`` the phases step's), the orientation is
    re-integrated through every movement and anchored at its rests (``params.anchor``; the heading chain restarts
    at rests of at least ``chain_rest_s`` s outside the repetitions) and ``acc`` rotated with it (``anchored``).
    With an alignment, ``acc`` and ``q_world`` are rotated into its ``world`` frame and the clock is
    ``reference``; else the frame is ``{imu}_global`` on the ``device`` clock. ``acc_sensor`` (N, 3) m/s^2: the
    accelerometer in the sensor frame for ``AnchorParams.rest_tilt``, when known (else rebuilt from ``acc``).
    """
    frame, clock, anchored = f"{imu}_global", "device", False
    if q_world is not None and gyr is not None and params.anchor.enabled and rest is not None:
        w = sample_onto(np.asarray(gyr[0], np.int64), np.asarray(gyr[1], float), t_dev)
        t_s = (t_ref - t_ref[0]) / 1e9  # where a window may be cut: the heading chain restarts there
        bounds = phase_bounds_by_repetition(phases, int(t_ref[0])) if phases is not None and len(phases) else {}
        spans = [(float(b[:, 0].min()), float(b[:, 1].max())) for b in bounds.values()]
        restart = restart_rests(given_rest, t_s, chain_rest_s, spans)
        g_up = np.array([0.0, 0.0, 9.81])  # (any g: the correction rotations are small, its error ~1e-4 m/s^2)
        acc_s = quat.rotate_inverse(q_world, acc + g_up) if acc_sensor is None else acc_sensor  # for rest_tilt
        t_s_dev = (t_dev - t_dev[0]) / 1e9
        q_anchored = rest_anchored_orientation(q_world, w, t_s_dev, rest, params.anchor, restart, acc_s)
        acc = quat.rotate(quat.multiply(q_anchored, quat.conjugate(q_world)), acc + g_up) - g_up
        q_world, anchored = q_anchored, True
    if alignment is not None:
        clock = "reference"
        rotation = alignment.get("rotation_global_to_world", [1, 0, 0, 0])
        if rotation is not None:  # None: an IMU of a setup on the shared clock without a cluster of its own
            g2w = np.asarray(rotation, dtype=np.float64)
            acc = quat.rotate(g2w, acc)
            if q_world is not None:
                q_world = quat.multiply(g2w, q_world)
            frame = "world"
    return acc, q_world, anchored, frame, clock
