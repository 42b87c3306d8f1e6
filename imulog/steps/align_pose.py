"""Reprocessing step ``align`` on an optical rigid body's poses (``/poses/NAME``: OptiTrack rigid bodies, BROAD's
``opt_quat``/``opt_pos``) instead of markers: the body's angular velocity from its orientations, then the same
clock fit and IMU-to-body rotation as for a marker cluster (:func:`imulog.process.alignment.align`).

Writes what the marker alignment writes (``imulog.alignment`` with ``reference`` = the pose channel and
``cluster.pose``; ``/derived/vicon/cluster_pose`` = the low-passed poses, ``/derived/vicon/angular_velocity``, the
``/derived/reference/...`` channels), so ``imulog evaluate`` and the viewer use a pose reference as they use a
cluster (docs/alignment.md).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from imulog.process import alignment as al
from imulog.process.alignment_cluster import ClusterKinematics, pose_kinematics
from imulog.steps.align import (
    _jsonable,
    alignment_streams,
    imu_span,
    orientation_at,
    params_dict,
    read_derived_pair,
    with_wide_search,
)
from imulog.steps.common import alignment_result, mean_rate_hz, names_trial

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "align"
#: a pose channel with fewer valid (finite) orientations than this fraction is refused: tracking was lost most of
#: the time, and what remains is not the IMU's body's motion over the trial
MIN_POSE_FRACTION = 0.5


def pose_channels(topics: list[str]) -> list[str]:
    """The trial's optical pose channels (``/poses/NAME``)."""
    return [t for t in topics if t.startswith("/poses/")]


def aligns_on_poses(topics: list[str], markers: str | None = None, poses: str | None = None) -> bool:
    """True when the alignment is on a pose channel: one is named (``poses``), or the trial has poses and no
    marker channel (and none is named)."""
    has_markers = any(t.startswith("/markers/") for t in topics)
    return poses is not None or (markers is None and not has_markers and bool(pose_channels(topics)))


def pick_poses(topics: list[str], poses: str | None) -> str:
    """The pose channel to align on: ``/poses/{poses}`` when given, else the trial's only one."""
    names = [t.split("/", 2)[2] for t in pose_channels(topics)]
    if poses is not None:
        if poses not in names:
            raise ValueError(f"no channel /poses/{poses} in the trial (pose channels: {', '.join(names) or 'none'})")
        return f"/poses/{poses}"
    if len(names) == 1:
        return f"/poses/{names[0]}"
    if not names:
        raise ValueError("no /markers/* or /poses/* channel in the trial: align needs an optical reference")
    raise ValueError(f"choose a pose channel with --poses among: {', '.join(names)}")


def check_poses(topic: str, quat_b2w: np.ndarray, min_fraction: float) -> float:
    """The fraction of ``quat_b2w``'s rows that are valid poses (finite); a one-line ValueError naming the channel
    when it is under ``min_fraction`` (tracking lost most of the time: nothing to align on)."""
    q = np.asarray(quat_b2w, dtype=np.float64)
    n = len(q)
    valid = int(np.count_nonzero(np.all(np.isfinite(q), axis=1) & (np.linalg.norm(np.nan_to_num(q), axis=1) > 0)))
    fraction = valid / n if n else 0.0
    if fraction < min_fraction:
        raise ValueError(
            f"{topic}: only {valid} of its {n} poses ({100 * fraction:.1f} %) have an orientation (tracking lost in "
            f"the rest); aligning needs at least {100 * min_fraction:.0f} %: is this the IMU's rigid body?"
        )
    return fraction


@dataclass(frozen=True)
class PoseBody:
    """One pose channel ready to align on: its kinematics (:func:`imulog.process.alignment_cluster.pose_kinematics`,
    low-passed like markers, angular velocity rad/s in the body frame), its rate (Hz) and the fraction of valid
    poses. Made once per body, whatever the number of IMUs aligned on it."""

    topic: str
    t_ns: np.ndarray
    rate_hz: float
    kinematics: ClusterKinematics
    valid_fraction: float


def pose_body(
    pose_topic: str,
    t_pose_ns: np.ndarray,
    position_m: np.ndarray | None,
    quat_b2w: np.ndarray,
    params: al.AlignmentParams,
    min_pose_fraction: float = MIN_POSE_FRACTION,
) -> PoseBody:
    """The :class:`PoseBody` of a pose channel; a one-line ValueError naming it when its poses are mostly missing
    (:func:`check_poses`)."""
    fraction = check_poses(pose_topic, quat_b2w, min_pose_fraction)
    t_pose = np.asarray(t_pose_ns, dtype=np.int64)
    rate = mean_rate_hz(t_pose)
    ck = pose_kinematics(t_pose, position_m, quat_b2w, rate, params, pose_topic)
    return PoseBody(pose_topic, t_pose, rate, ck, fraction)


def align_on_body(
    imu_name: str,
    t_imu_ns: np.ndarray,
    gyr: np.ndarray | None,
    body: PoseBody,
    params: al.AlignmentParams,
    orientation: tuple[np.ndarray, np.ndarray] | None = None,
) -> dict:
    """The ``imulog.alignment`` record of one IMU on one body (no streams, no I/O). Raises a one-line ValueError
    when the IMU has no gyroscope or the body does not turn like the IMU (correlation under
    ``params.min_valid_score``)."""
    if gyr is None:
        raise ValueError(f"/imu/{imu_name} has no gyroscope columns: aligning on poses compares angular velocities")
    pose_topic = body.topic
    q_s2g = orientation_at(orientation, t_imu_ns)

    def compute(p: al.AlignmentParams) -> tuple[list, dict]:
        try:
            record = al.align(t_imu_ns, gyr, body.kinematics, p, q_imu_s2g=q_s2g)
        except ValueError as exc:  # the clock fit's reason, naming the channel it was fitted against
            raise ValueError(f"{pose_topic}: {exc}") from None
        score = float(record.get("score") or 0.0)
        if score < p.min_valid_score:
            raise ValueError(
                f"{pose_topic}: the rigid body does not turn like /imu/{imu_name} (correlation {score:.2f} < "
                f"{p.min_valid_score:g}); did the IMU move, and is it on this body?"
            )
        info = {
            "markers": [],
            "pose": pose_topic,
            "selection": "pose",
            "valid_fraction": round(body.valid_fraction, 4),
            "vector_match": round(float(record["vector_match"]), 4),
            "runner_up": None,
        }
        record = {"reference": pose_topic, "imu": f"/imu/{imu_name}", **record, "cluster": info}
        record["method"] = str(record.get("method", "")).replace(f"cluster={p.cluster}", "pose")
        record["quality"], record["quality_reasons"] = al.assess_quality(record, p)
        return [], _jsonable(record)

    return with_wide_search(compute, t_imu_ns, body.t_ns, params, True)[1]


def pose_streams(
    imu_name: str,
    body: PoseBody,
    record: dict,
    t_imu_ns: np.ndarray,
    gyr: np.ndarray,
    orientation: tuple[np.ndarray, np.ndarray] | None = None,
    acc_global: tuple[np.ndarray, np.ndarray] | None = None,
    resample: bool = True,
) -> list:
    """The step's streams for one IMU aligned on ``body`` with ``record`` (:func:`imulog.steps.align.alignment_streams`)."""
    return alignment_streams(
        imu_name, body.kinematics, record, t_imu_ns, gyr, body.t_ns, body.rate_hz, orientation, acc_global, resample
    )


def compute_pose_alignment(
    imu_name: str,
    t_imu_ns: np.ndarray,
    gyr: np.ndarray | None,
    pose_topic: str,
    t_pose_ns: np.ndarray,
    position_m: np.ndarray | None,
    quat_b2w: np.ndarray,
    params: al.AlignmentParams,
    orientation: tuple[np.ndarray, np.ndarray] | None = None,
    acc_global: tuple[np.ndarray, np.ndarray] | None = None,
    resample: bool = True,
    min_pose_fraction: float = MIN_POSE_FRACTION,
) -> tuple[list, dict]:
    """Pure part of the pose alignment: streams and the ``imulog.alignment`` record (no I/O). Raises a one-line
    ValueError when the IMU has no gyroscope, the poses are mostly missing or the
    body does not turn like the IMU (correlation under ``params.min_valid_score``); ``min_pose_fraction``: see
    :data:`MIN_POSE_FRACTION`."""
    if gyr is None:
        raise ValueError(f"/imu/{imu_name} has no gyroscope columns: aligning on poses compares angular velocities")
    body = pose_body(pose_topic, t_pose_ns, position_m, quat_b2w, params, min_pose_fraction)
    record = align_on_body(imu_name, t_imu_ns, gyr, body, params, orientation)
    return pose_streams(imu_name, body, record, t_imu_ns, gyr, orientation, acc_global, resample), record


@names_trial
def run_align_pose(
    path: str | os.PathLike[str],
    *,
    imu: str | None = None,
    poses: str | None = None,
    params: al.AlignmentParams | None = None,
    resample: bool = True,
    force: bool = False,
) -> StepOutcome:
    """Run the step for one IMU of a trial file against a pose channel; the :func:`imulog.steps.base.run_step`
    outcome."""
    from imulog.archive import TrialReader
    from imulog.steps.base import StepResult, run_step
    from imulog.steps.common import pick_imu

    params = params or al.AlignmentParams()
    with TrialReader(path) as trial:
        topics = trial.topics()
    name = pick_imu(topics, imu)
    pose_topic = pick_poses(topics, poses)
    imu_topic = f"/imu/{name}"
    o_topic, a_topic = f"/derived/orientation/{name}", f"/derived/acc_global/{name}"
    inputs = [imu_topic, pose_topic] + [t for t in (o_topic, a_topic) if t in topics]

    def compute(trial) -> StepResult:
        lo, hi = imu_span(trial, imu_topic, pose_topic, params.max_lag_s)  # a week's IMU: the poses' span only
        imu_stream = trial.read(imu_topic, lo, hi)
        pose = trial.read(pose_topic)
        orientation, acc_global = read_derived_pair(trial, [t for t in (o_topic, a_topic) if t in inputs], lo, hi)
        streams, record = compute_pose_alignment(
            name,
            imu_stream.t_ns,
            imu_stream.gyr,
            pose_topic,
            pose.t_ns,
            pose.position,
            pose.orientation,
            params,
            orientation,
            acc_global,
            resample,
        )
        return alignment_result(trial, name, streams, record)

    return run_step(
        path,
        step=STEP,
        algorithm="imulog.alignment.xcorr_wahba",
        params={"imu": name, "poses": pose_topic, "resample": resample, **params_dict(params)},
        inputs=inputs,
        compute=compute,
        force=force,
    )
