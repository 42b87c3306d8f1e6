"""The ``kinematics`` step beyond one window (:mod:`imulog.steps.kinematics`): the upper-arm IMU's orientation
samples in half-hour windows, the other IMUs' by time, each window solved warm-started from the previous one.

The orientations are the orientation step's channels read chunk by chunk, or computed core by core as that step
would when a trial has none; the calibration is the first window's. Memory: one window and its neighbours'
blocks, whatever the length.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from imulog.console import window_progress
from imulog.model import PoseStream, SignalStream
from imulog.process import quaternion as quat
from imulog.process.kinematics.dh import JOINT_NAMES
from imulog.process.kinematics.pipeline import KinematicsConfig, KinematicsEstimate, estimate_kinematics
from imulog.process.orientation import OrientationParams
from imulog.steps.windows import WindowParams, channel_rate_hz

PREFIX = "/derived/kinematics"


def resample_onto(t_src: np.ndarray, q: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    if len(t_src) == len(t_dst) and np.array_equal(t_src, t_dst):
        return q
    from imulog.process.resample import ResampleParams, resample_quaternions

    return resample_quaternions(t_src, q, t_dst, ResampleParams(cutoff_ratio=0.0))


def calibration_record(
    ua: str, fa: str, trunk: str | None, config: KinematicsConfig, q_global_to_trunk: dict[str, Any]
) -> dict[str, Any]:
    """The ``imulog.kinematics_calibration`` record: the IMUs, the neutral-pose calibration's settings and the
    global-to-trunk rotations (w,x,y,z) it found."""
    return {
        "upper_arm_imu": ua,
        "forearm_imu": fa,
        "trunk_imu": trunk,
        "mode": config.calibration.mode,
        "neutral_pose_deg": list(config.calibration.pose_deg),
        "neutral_window_s": list(config.calibration.window_s),
        "q_global_to_trunk": {k: [float(x) for x in v] for k, v in q_global_to_trunk.items()},
    }


def kinematics_streams(est: KinematicsEstimate, q_ref: np.ndarray | None) -> list:
    t = est.t_ns
    units = ["deg"] * len(JOINT_NAMES)
    con = est.constrained
    fk = est.fk_constrained
    active = con.active
    mask = np.column_stack([con.any_active, active[:, 0], active[:, 1], active[:, 2], est.t_out]).astype(np.float64)
    nan_rows = ~np.all(np.isfinite(con.q_rad), axis=1)
    mask[nan_rows] = np.nan
    q_ua = np.full((len(t), 4), np.nan)
    q_fa = np.full((len(t), 4), np.nan)
    ok = ~nan_rows
    if ok.any():
        q_ua[ok] = quat.from_rotation_matrix(fk.r_upper_arm[ok])
        q_fa[ok] = quat.from_rotation_matrix(fk.r_forearm[ok])
    streams = [
        SignalStream(
            f"{PREFIX}/joint_angles_unconstrained",
            t,
            list(JOINT_NAMES),
            units,
            np.degrees(est.unconstrained.q_rad),
            frame_id="trunk",
        ),
        SignalStream(
            f"{PREFIX}/joint_angles_constrained", t, list(JOINT_NAMES), units, np.degrees(con.q_rad), frame_id="trunk"
        ),
        PoseStream(f"{PREFIX}/elbow", t, fk.elbow_m, q_ua, frame_id="trunk"),
        PoseStream(f"{PREFIX}/wrist", t, fk.wrist_m, q_fa, frame_id="trunk"),
        SignalStream(
            f"{PREFIX}/constraint_active",
            t,
            ["active", "joint_limit", "elbow_box", "wrist_box", "outside_unconstrained"],
            ["1"] * 5,
            mask,
            frame_id="trunk",
        ),
    ]
    if q_ref is not None:
        streams.append(
            SignalStream(
                f"{PREFIX}/joint_angles_reference", t, list(JOINT_NAMES), units, np.degrees(q_ref), frame_id="trunk"
            )
        )
    return streams


class _TimeCursor:
    """Samples ``(t_ns, q)`` of a channel read block by block, handed out by time range (forward only)."""

    def __init__(self, blocks) -> None:
        self.blocks = blocks
        self.parts: list[tuple[np.ndarray, np.ndarray]] = []
        self.done = False

    def get(self, t_lo: int, t_hi: int) -> tuple[np.ndarray, np.ndarray]:
        while not self.done and (not self.parts or self.parts[-1][0][-1] < t_hi):
            try:
                t, q = next(self.blocks)
            except StopIteration:
                self.done = True
                break
            if len(t):
                self.parts.append((t, q))
        while len(self.parts) > 1 and self.parts[0][0][-1] < t_lo:
            self.parts.pop(0)
        if not self.parts:
            return np.zeros(0, np.int64), np.zeros((0, 4))
        t = np.concatenate([p[0] for p in self.parts])
        q = np.concatenate([p[1] for p in self.parts])
        keep = (t >= t_lo) & (t <= t_hi)
        return t[keep], q[keep]


def _quaternion_blocks(trial: Any, topic: str):
    for b in trial.iter_blocks(topic):
        cols = [b.columns.index(c) for c in ("qw", "qx", "qy", "qz")]
        yield np.asarray(b.t_ns, np.int64), np.asarray(b.values[:, cols], dtype=np.float64)


def _orientation_blocks(path, trial: Any, imu: str, params: OrientationParams):
    """``(t_ns, q_s2g)`` blocks of an IMU's orientation: the orientation step's channel read chunk by chunk when
    the trial has it, else computed core by core as that step computes it (its default windows, ``params``)."""
    topic = f"/derived/orientation/{imu}"
    if topic in trial.topics():
        yield from _quaternion_blocks(trial, topic)
        return
    from imulog.steps.orientation import read_orientation_windows

    ch = trial.channel(f"/imu/{imu}")
    total = int(ch.sample_count or 0)
    plan = WindowParams().plan(total, channel_rate_hz(total, ch.start_ns, ch.end_ns, ch.rate_hz))
    for s in read_orientation_windows(path, f"/imu/{imu}", imu, params, None, plan, total):
        if s.topic == topic:
            cols = [s.columns.index(c) for c in ("qw", "qx", "qy", "qz")]
            yield np.asarray(s.t_ns, np.int64), np.asarray(s.values[:, cols], dtype=np.float64)


def _last_finite(q: np.ndarray) -> np.ndarray | None:
    ok = np.flatnonzero(np.all(np.isfinite(q), axis=1))
    return None if len(ok) == 0 else q[ok[-1]].copy()


def kinematics_pieces(
    path,
    ua: str,
    fa: str,
    trunk: str | None,
    orientation: OrientationParams,
    plan,
    record: dict,
    config: KinematicsConfig,
    cfg_record: dict,
):
    """The step window by window (``plan``: :class:`~imulog.steps.windows.Window` s over the upper-arm IMU's
    orientation samples): the neutral-posture calibration from the first window, every later window warm-started
    from the previous one's last solution, so each sample's angles are the whole computation's. An IMU without
    the orientation step's channel gets its orientation computed core by core as that step would
    (:func:`_orientation_blocks`). Yields the streams of each window; fills ``record``
    (``imulog.kinematics_calibration``) at the end."""
    from imulog.archive import TrialReader
    from imulog.heap import bound_heap
    from imulog.process.kinematics.pipeline import calibrate_kinematics
    from imulog.steps.sample_window import SampleWindow

    bound_heap()  # the same temporaries window after window: keep them out of the heap (imulog.heap)
    margin_ns = 1_000_000_000  # forearm/trunk samples this far beyond the window, for the resampling
    sums = {"n": 0, "active": 0.0, "t_out": 0.0, "infeasible": 0, "ms": {}}
    with TrialReader(path) as trial:
        total = plan[-1].hi
        ua_buf = SampleWindow(_orientation_blocks(path, trial, ua, orientation), total)
        others = {
            k: _TimeCursor(_orientation_blocks(path, trial, n, orientation))
            for k, n in (("fa", fa), ("tr", trunk))
            if n
        }
        calibrated, warm = None, {}
        for w in window_progress(plan, "kinematics"):
            t, q_ua = ua_buf.take(w.lo, w.hi)
            t_fa, q_fa = others["fa"].get(int(t[0]) - margin_ns, int(t[-1]) + margin_ns)
            q_fa = resample_onto(t_fa, q_fa, t)
            q_tr = None
            if "tr" in others:
                t_tr, q_tr = others["tr"].get(int(t[0]) - margin_ns, int(t[-1]) + margin_ns)
                q_tr = resample_onto(t_tr, q_tr, t)
            if calibrated is None:
                calibrated = calibrate_kinematics(q_ua, q_fa, t, config, q_trunk_s2g=q_tr)
            est = estimate_kinematics(q_ua, q_fa, t, config, q_trunk_s2g=q_tr, calibrated=calibrated, warm_start=warm)
            for key, res in (("unconstrained", est.unconstrained), ("constrained", est.constrained)):
                last = _last_finite(res.q_rad)
                if last is not None:
                    warm[key] = last
            n = len(t)
            sums["n"] += n
            sums["active"] += float(np.sum(est.constrained.any_active))
            sums["t_out"] += float(np.sum(est.t_out))
            sums["infeasible"] += int(est.constrained.extra.get("n_infeasible", 0))
            for k, v in est.timing_ms_per_sample.items():
                sums["ms"][k] = sums["ms"].get(k, 0.0) + float(v) * n
            yield from kinematics_streams(est, None)
    n = max(sums["n"], 1)
    record.update(
        {
            **calibration_record(ua, fa, trunk, config, calibrated[0]),
            "ms_per_sample": {k: v / n for k, v in sums["ms"].items()},
            "constraint_active_fraction": sums["active"] / n,
            "infeasible_samples": sums["infeasible"],
            "t_out_fraction": sums["t_out"] / n,
            "config": cfg_record,
            "windows": len(plan),
            "reference": "marker reference angles are computed for recordings of one window (lab trials)",
        }
    )
