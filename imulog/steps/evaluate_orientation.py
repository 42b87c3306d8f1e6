"""Reprocessing step ``evaluate`` of an IMU's orientation against an optical rigid body's poses (BROAD's
``opt_quat``, an OptiTrack rigid body): the BROAD paper's errors, inclination and heading-free RMSE in degrees
(:func:`imulog.process.orientation.orientation_errors`, the metric ``benchmarks/broad_orientation.py`` reports).

Reads ``/derived/orientation/{imu}`` (sensor-to-global, device clock), the pose channel the alignment used
(``imulog.alignment`` ``reference`` = ``/poses/NAME``) and, when present, ``/events/movement`` (BROAD's movement
phases: the samples its authors evaluate). The estimate is put on the reference clock (the alignment's offset and
drift) and resampled at the poses' time stamps. The optical body is turned into the IMU's frame by the
alignment's ``rotation_imu_to_cluster``, unless the pose channel's device record declares the two frames aligned
(``imu_frame_aligned``: BROAD's converter, as its files say), then by none. Writes ``imulog.orientation_evaluation``
(``kind`` = ``orientation``; ``imulog.orientation_evaluation.IMU`` for an IMU other than the trial's primary one),
its own record and step (``evaluate_orientation``): the trajectory evaluation of the same trial
(``imulog.evaluation``) and this one never replace each other. Trials of an older imulog hold it in
``imulog.evaluation`` (:func:`orientation_record_of` reads either).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.alignment_clock import device_to_reference
from imulog.process.orientation import orientation_errors
from imulog.process.resample import resample_quaternions
from imulog.steps.common import names_trial

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "evaluate_orientation"
RECORD = "imulog.orientation_evaluation"
MOVEMENT_TOPIC = "/events/movement"


def orientation_record_of(metadata: dict[str, Any]) -> dict[str, Any]:
    """The trial's (primary IMU's) orientation evaluation: ``imulog.orientation_evaluation``, else the
    ``imulog.evaluation`` of an older imulog when it is one (``kind`` = ``orientation``), else ``{}``."""
    record = metadata.get(RECORD)
    if isinstance(record, dict) and record:
        return record
    legacy = metadata.get("imulog.evaluation")
    return legacy if isinstance(legacy, dict) and legacy.get("kind") == "orientation" else {}


def pose_reference(metadata: dict[str, Any], imu: str | None = None, own_only: bool = False) -> str | None:
    """The pose channel (``/poses/NAME``) the IMU's alignment was made on, else None (``own_only``: None when the
    IMU has no alignment record of its own, instead of the trial's main record)."""
    from imulog.steps.common import alignment_for

    own = alignment_for(metadata, f"/imu/{imu}") if imu else None
    record = own or ({} if own_only else metadata.get("imulog.alignment")) or {}
    reference = str(record.get("reference") or "")
    return reference if reference.startswith("/poses/") else None


def in_intervals(t_ns: np.ndarray, start_ns: np.ndarray, end_ns: np.ndarray) -> np.ndarray:
    """(N,) bool: ``t_ns`` inside any interval ``[start_ns, end_ns]`` (ends included)."""
    t = np.asarray(t_ns, dtype=np.int64)
    mask = np.zeros(len(t), dtype=bool)
    for a, b in zip(np.asarray(start_ns, dtype=np.int64), np.asarray(end_ns, dtype=np.int64), strict=True):
        mask |= (t >= a) & (t <= b)
    return mask


def orientation_evaluation(
    t_est_ns: np.ndarray,
    q_est_s2g: np.ndarray,
    t_ref_ns: np.ndarray,
    q_ref_b2w: np.ndarray,
    alignment: dict[str, Any],
    *,
    imu_to_body: np.ndarray | None = None,
    mask: np.ndarray | None = None,
) -> dict[str, Any]:
    """Errors (degrees) of an orientation estimate against a rigid body's orientations (pure, no I/O).

    ``t_est_ns`` device clock, ``q_est_s2g`` (N, 4) sensor-to-global; ``t_ref_ns`` reference clock, ``q_ref_b2w``
    (M, 4) body-to-world (NaN where tracking was lost); ``alignment``: the clock (``offset_ns``, ``drift_ppm``,
    ``t0_ns``); ``imu_to_body`` (w,x,y,z) the IMU-to-body rotation (None: identity, the frames are one);
    ``mask`` (M,) the reference samples to evaluate (None: all). The estimate is resampled at the reference's time
    stamps; :func:`orientation_errors` does the rest (one implementation with the BROAD benchmark)."""
    t_est_ref = device_to_reference(np.asarray(t_est_ns, dtype=np.int64), alignment)
    q_est = resample_quaternions(t_est_ref, q_est_s2g, t_ref_ns)
    q_ref = np.asarray(q_ref_b2w, dtype=np.float64)
    if imu_to_body is not None:  # the IMU's orientation as the optical system sees it: body-to-world * IMU-to-body
        q_ref = quat.multiply(q_ref, np.broadcast_to(np.asarray(imu_to_body, dtype=np.float64), q_ref.shape))
    errors = orientation_errors(q_est, q_ref, mask)
    if errors["samples"] < 2:
        raise ValueError("no sample where the estimate and the optical orientation overlap (inside the mask)")
    return errors


@names_trial
def run_evaluate_orientation(
    path: str | os.PathLike[str], imu: str | None = None, force: bool = False
) -> tuple[StepOutcome, dict[str, Any]]:
    """Run the orientation evaluation on a trial whose alignment is on a pose channel; ``(outcome, record)``.
    One-line ValueErrors naming the command to run when the orientation or the alignment is missing."""
    from imulog.archive import TrialReader
    from imulog.steps.align import require_alignment
    from imulog.steps.base import run_record_step
    from imulog.steps.common import alignment_note, alignment_record, pick_imu, record_for

    with TrialReader(path) as trial:
        topics = trial.topics()
        metadata = trial.metadata
    name = pick_imu(
        topics, imu, prefix="/derived/orientation/", missing_hint=f"run `imulog process orientation {path}` first"
    )
    alignment = require_alignment(
        metadata, path, f"/imu/{name}", needed_for="evaluate (the IMU's orientation against the optical poses)"
    )
    pose_topic = pose_reference(metadata, name)
    if pose_topic is None or pose_topic not in topics:
        poses = [t for t in topics if t.startswith("/poses/")]
        raise ValueError(
            f"the orientation is evaluated against a rigid body's poses, and the alignment of /imu/{name} is on "
            f"{alignment.get('reference')} "
            + (
                f"(align on the poses: imulog process align {path} --poses {poses[0].rsplit('/', 1)[-1]})"
                if poses
                else "(the trial has no /poses/* channel)"
            )
        )
    o_topic = f"/derived/orientation/{name}"
    device = metadata.get(f"imulog.device.{pose_topic.rsplit('/', 1)[-1]}") or {}
    declared = bool(device.get("imu_frame_aligned"))
    q_i2b = None if declared else alignment.get("rotation_imu_to_cluster")
    movement = MOVEMENT_TOPIC in topics
    inputs = [o_topic, pose_topic] + ([MOVEMENT_TOPIC] if movement else [])

    def compute(trial) -> dict[str, Any]:
        est = trial.read(o_topic)
        pose = trial.read(pose_topic)
        mask = None
        if movement:
            ev = trial.read(MOVEMENT_TOPIC)
            mask = in_intervals(pose.t_ns, ev.start_ns, ev.end_ns)
        errors = orientation_evaluation(
            est.t_ns,
            est.values,
            pose.t_ns,
            pose.orientation,
            alignment,
            imu_to_body=None if q_i2b is None else np.asarray(q_i2b, dtype=np.float64),
            mask=mask,
        )
        record = {
            "kind": "orientation",
            "reference": pose_topic,
            "imu": f"/imu/{name}",
            "orientation": o_topic,
            "orientation_run": (trial.channel(o_topic).metadata or {}).get("algorithm", ""),
            "over": "movement phases (/events/movement)" if movement else "all samples",
            "imu_to_reference": (
                "none: the source declares the IMU and optical body frames aligned"
                if declared
                else "the alignment's rotation_imu_to_cluster"
            ),
            **{k: round(float(v), 4) if isinstance(v, float) else v for k, v in errors.items()},
            "units": {"inclination_rmse_deg": "deg", "heading_free_rmse_deg": "deg", "heading_offset_deg": "deg"},
            "alignment": alignment_note(alignment),
        }
        return record

    record_name = record_for(RECORD, name, topics, metadata)
    return run_record_step(
        path,
        record_name=record_name,
        compute_record=compute,
        step=STEP if record_name == RECORD else f"{STEP}:{name}",
        algorithm="imulog.evaluation.orientation",
        params={"imu": name, "reference": pose_topic, "imu_frame_aligned": declared},
        inputs=inputs,
        metadata_inputs=(alignment_record(metadata, f"/imu/{name}"),),  # this IMU's record, not the main one
        force=force,
    )


@names_trial
def run_evaluate_orientations(
    path: str | os.PathLike[str], imus: list[str] | None = None, force: bool = False
) -> tuple[StepOutcome, dict[str, Any]]:
    """The orientation evaluation of one IMU (``imus`` names one, or the trial has one) as
    :func:`run_evaluate_orientation` does it; of several (named, or by default every oriented IMU whose alignment is
    on a pose channel: rigid bodies aligned per IMU) one run and record each, returning the last outcome and
    ``{"kind": "orientations", "imus": {imu: record, or {"failed": why}}, "skipped": {imu: why}}``: an oriented IMU
    with no alignment on a rigid body (one that no body turns like) is skipped with why, not failed."""
    from imulog.archive import TrialReader
    from imulog.steps.common import imu_names

    with TrialReader(path) as trial:
        topics, metadata = trial.topics(), trial.metadata
    oriented = imu_names(topics, "/derived/orientation/")
    if imus and len(imus) == 1 or (not imus and len(oriented) <= 1):
        return run_evaluate_orientation(path, imu=imus[0] if imus else None, force=force)
    chosen = list(imus) if imus else [n for n in oriented if pose_reference(metadata, n, own_only=True)]
    skipped = {n: "no alignment on a rigid body's poses" for n in oriented if not imus and n not in chosen}
    if not chosen:
        return run_evaluate_orientation(path, imu=None, force=force)  # its one-line error says what is missing
    records: dict[str, Any] = {}
    outcome = None
    for name in chosen:
        try:
            outcome, records[name] = run_evaluate_orientation(path, imu=name, force=force)
        except ValueError as exc:
            records[name] = {"failed": str(exc)}
    if outcome is None:
        raise ValueError("; ".join(f"{n}: {r['failed']}" for n, r in records.items()))
    return outcome, {"kind": "orientations", "imus": records, "skipped": skipped}


def orientation_lines(record: dict[str, Any]) -> list[str]:
    """Human-readable lines of an orientation ``imulog.evaluation`` record."""
    lines = [
        f"inclination RMSE {record['inclination_rmse_deg']:.2f} deg, heading-free RMSE "
        f"{record['heading_free_rmse_deg']:.2f} deg (global heading offset {record['heading_offset_deg']:.1f} deg "
        f"removed), {record['samples']} samples",
        f"over {record.get('over')}; IMU to optical body: {record.get('imu_to_reference')}",
    ]
    aligned = record.get("alignment") or {}
    if "offset_ns" in aligned:
        lines.append(
            f"clock: offset {aligned['offset_ns'] / 1e6:.2f} ms, drift {float(aligned.get('drift_ppm') or 0):.1f} ppm "
            f"(imulog process align), quality {aligned.get('quality', '?')}"
        )
    return lines
