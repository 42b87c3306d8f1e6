"""``imulog evaluate`` on a walking trial: per stride, per foot, against the foot's own markers (issue 27).

A trial is walking when its ``imulog.trial`` task says so (``walk``, ``walking``, ``gait``, ``treadmill``), or,
with no task declared, when an IMU's gyroscope repeats with a stride's period
(:func:`imulog.process.gait.walking_period`, strength at least ``PERIODIC``) and rests once per period (its
zero-velocity strides last the period within 20 %). Then every IMU aligned with a marker cluster (``imulog.alignment.{imu}`` from ``imulog process
align``) that shows strides is evaluated like gaitmap's stride-level evaluation:

* zero velocity where the gyroscope norm stays under 0.6 rad/s for 50 ms, strides from one mid-stance to the
  next (:func:`imulog.process.gait.strides_from_rests`), the ZUPT trajectory with linear de-drift;
* the reference is the point of the foot's cluster where the IMU sits: the cluster pose from the align step
  (``/derived/vicon/cluster_pose/{imu}``) carried by the IMU's place on the cluster, found from accelerations
  alone (:func:`imulog.process.gait.lever_arm`), on the IMU's samples through the alignment's clock;
* per stride: stride length, time, foot clearance and the position error per axis
  (:func:`imulog.process.gait.stride_errors`).

Writes ``imulog.evaluation`` with ``kind: strides``, ``walking`` (why the trial is walking), per IMU its summary
and strides, and ``skipped`` (IMUs not evaluated, and why).
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.steps.common import names_trial

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

WALK_TASKS = ("walk", "walking", "gait", "treadmill")
PERIODIC = 0.5  # autocorrelation at the stride period above which the gyroscope says "walking"
MIN_STRIDES = 3


def walking_trial(metadata: dict[str, Any], gyros: dict[str, tuple[np.ndarray, float]]) -> dict[str, Any] | None:
    """Why the trial is a walking trial (``{"source": "task" | "gyroscope", ...}``), or None.

    ``gyros``: IMU name -> (gyroscope (N, 3) rad/s, rate Hz)."""
    from imulog.process.gait import strides_from_rests, walking_period, zero_velocity

    task = str((metadata.get("imulog.trial") or {}).get("task", "")).lower()
    if task in WALK_TASKS:
        return {"source": "task", "task": task}
    if task:
        return None  # a declared task that is not walking (a drinking task, arm movements)
    best = None
    for name, (gyr, rate) in gyros.items():
        if gyr is None or len(gyr) < 10:
            continue
        period, strength = walking_period(gyr, rate)
        if strength < PERIODIC:
            continue
        # a foot rests once per stride: its strides (mid-stance to mid-stance) last about the period
        st = strides_from_rests(zero_velocity(gyr, rate), rate)
        if len(st) < MIN_STRIDES or abs(np.median(np.diff(st, axis=1)) / rate / period - 1) > 0.2:
            continue
        if best is None or strength > best["strength"]:
            best = {"source": "gyroscope", "imu": name, "period_s": round(period, 3), "strength": round(strength, 3)}
    return best


FOOT_STILL_MPS = 0.15  # median speed of the IMU's point on its cluster while its gyroscope is still, m/s


def evaluate_foot(imu, alignment: dict[str, Any], pose, acc_global: tuple[np.ndarray, np.ndarray] | None) -> dict:
    """Per-stride evaluation of one foot IMU (``imu`` an ImuStream, ``pose`` its cluster's PoseStream on the
    reference clock, ``acc_global`` (t_ns, gravity-free acceleration) from the orientation step or None to
    compute it here with the default orientation filter)."""
    from imulog.process import quaternion as quat
    from imulog.process.alignment_clock import device_to_reference
    from imulog.process.gait import lever_arm, stride_errors, strides_from_rests, zero_velocity
    from imulog.process.integration import ZuptParams, zupt
    from imulog.process.resample import resample_quaternions
    from imulog.steps.common import mean_rate_hz

    rate = mean_rate_hz(imu.t_ns)
    t_s = (imu.t_ns - imu.t_ns[0]) / 1e9
    if acc_global is not None and np.array_equal(acc_global[0], imu.t_ns):
        a_g, source = acc_global[1], "orientation step"
    else:
        from imulog.process.orientation import estimate_orientation, gravity_free_acceleration

        est = estimate_orientation(imu.gyr, imu.acc, rate, t_ns=imu.t_ns)
        a_g, source = gravity_free_acceleration(est.quat, imu.acc, est.static), "default orientation filter"
    still = zero_velocity(imu.gyr, rate)
    strides = strides_from_rests(still, rate)
    if len(strides) < MIN_STRIDES:
        raise ValueError(f"{len(strides)} strides (zero-velocity intervals 0.5-3 s apart): not a walking foot")
    _, pos = zupt(np.nan_to_num(a_g), t_s, still, ZuptParams())
    t_ref = device_to_reference(imu.t_ns, alignment)
    origin = np.column_stack([np.interp(t_ref, pose.t_ns, pose.position[:, j], np.nan, np.nan) for j in range(3)])
    q_wc = resample_quaternions(pose.t_ns, pose.orientation, t_ref)
    q_i2c = np.asarray(alignment["rotation_imu_to_cluster"], dtype=float)
    q_ws = quat.multiply(q_wc, np.tile(q_i2c, (len(q_wc), 1)))
    r, resid = lever_arm(imu.acc, q_ws, origin, q_wc, rate)
    ref = origin + quat.rotate(q_wc, np.tile(r, (len(q_wc), 1)))
    walking = np.zeros(len(still), bool)  # the still samples of the strides (not the standing before/after)
    for a, b in strides:
        walking[a : b + 1] = True
    speed = np.linalg.norm(np.gradient(ref, t_s, axis=0), axis=1)[still & walking]
    still_speed = float(np.nanmedian(speed)) if np.isfinite(speed).any() else float("nan")
    if not still_speed <= FOOT_STILL_MPS:  # a foot is flat on the floor when its gyroscope is still
        raise ValueError(
            f"not a foot: its point on the markers moves at {still_speed:.2f} m/s (median) while its gyroscope is "
            f"still in its strides (a foot on the floor: under {FOOT_STILL_MPS:g} m/s)"
        )
    keep = np.all(np.isfinite(ref[strides[:, 0]]), axis=1) & np.all(np.isfinite(ref[strides[:, 1]]), axis=1)
    out = stride_errors(pos, ref, t_s, strides[keep])
    out["lever_arm_m"] = [round(float(v), 4) for v in r]
    out["lever_arm_residual_mps2"] = round(resid, 3)
    out["still_speed_mps"] = round(still_speed, 3)
    out["acc_global"] = source
    return out


def foot_span(trial, imu_topic: str, pose_topic: str, alignment: dict[str, Any]) -> tuple[int | None, int | None]:
    """(start_ns, end_ns) on the device clock of the IMU samples a foot's evaluation reads: the cluster pose's
    span mapped through the alignment, with :data:`imulog.steps.align.MARGIN_S` either side; (None, None), the
    whole channel, when the IMU lies within that (a lab trial, read as before) or a span is unknown. A week's
    foot with an hour of markers is read over that hour only (bounded memory, issue 24)."""
    from imulog.process.alignment_clock import reference_to_device
    from imulog.steps.align import MARGIN_S

    pose, imu = trial.channel(pose_topic), trial.channel(imu_topic)
    if None in (pose.start_ns, pose.end_ns, imu.start_ns, imu.end_ns):
        return None, None
    margin = int(MARGIN_S * 1e9)
    lo, hi = (int(v) for v in reference_to_device(np.array([pose.start_ns, pose.end_ns], np.int64), alignment))
    lo, hi = lo - margin, hi + margin
    if lo <= int(imu.start_ns) and int(imu.end_ns) < hi:
        return None, None
    return lo, hi + 1


def compute_gait_evaluation(trial, names: list[str], walking: dict[str, Any]) -> dict[str, Any]:
    """The ``imulog.evaluation`` record of a walking trial (see the module docstring)."""
    from imulog.steps.common import alignment_for, cluster_pose_topic

    topics = trial.topics()
    feet, skipped = {}, {}
    for name in names:
        rec = alignment_for(trial.metadata, f"/imu/{name}")
        if not rec or not rec.get("rotation_imu_to_cluster"):
            skipped[name] = "no marker cluster aligned with it (run `imulog process align`)"
            continue
        topic = cluster_pose_topic(name, topics, trial.metadata)
        if topic is None:
            skipped[name] = "no cluster pose from the align step"
            continue
        a_topic = f"/derived/acc_global/{name}"
        lo, hi = foot_span(trial, f"/imu/{name}", topic, rec)
        acc_global = None
        if a_topic in topics:
            s = trial.read(a_topic, lo, hi)
            acc_global = (s.t_ns, s.values)
        imu = trial.read(f"/imu/{name}", lo, hi)
        if len(imu.t_ns) < 2:
            skipped[name] = "no IMU samples within its cluster's span"
            continue
        try:
            r = evaluate_foot(imu, rec, trial.read(topic), acc_global)
        except ValueError as exc:
            skipped[name] = str(exc)
            continue
        r["reference"] = f"{topic} + lever arm"
        r["markers"] = (rec.get("cluster") or {}).get("markers")
        feet[name] = r
    if not feet:
        raise ValueError(
            "walking trial, but no foot IMU could be evaluated per stride: "
            + "; ".join(f"{n}: {why}" for n, why in skipped.items())
        )
    return {"kind": "strides", "walking": walking, "feet": feet, "skipped": skipped, "units": {"*_cm": "cm"}}


def stride_table(record: dict[str, Any]) -> str:
    """One row per foot IMU: strides, mean absolute position error per axis, stride length/time, clearance."""
    head = "imu                 strides  x cm   y cm   z cm   length err cm  clearance err cm  stride time s"
    lines = [head]
    for name, r in (record.get("feet") or {}).items():
        m = r["mean_abs_cm"]
        lines.append(
            f"{name:<20}{r['count']:>7}  {m['x']:>5.2f}  {m['y']:>5.2f}  {m['z']:>5.2f}  {r['length_error_cm']:>13.2f}"
            f"  {r['clearance_error_cm']:>16.2f}  {r['stride_time_s']:>13.2f}"
        )
    for name, why in (record.get("skipped") or {}).items():
        lines.append(f"{name}: not evaluated: {why}")
    return "\n".join(lines)


@names_trial
def run_gait_evaluate(
    path: str | os.PathLike[str], *, imus: list[str] | None = None, walking: dict | None = None, force: bool = False
) -> tuple[StepOutcome, dict[str, Any]]:
    """Evaluate a walking trial per stride; returns ``(outcome, record)``."""
    from imulog.archive import TrialReader
    from imulog.steps.base import run_record_step

    with TrialReader(path) as trial:
        topics = trial.topics()
        names = [t[len("/imu/") :] for t in topics if t.startswith("/imu/")]
        if imus:
            missing = [n for n in imus if n not in names]
            if missing:
                raise ValueError(f"no channel /imu/{missing[0]} in the trial (IMUs: {', '.join(names)})")
            names = list(imus)
        metadata = trial.metadata
    if walking is None:
        walking = {"source": "asked"}
    records = [k for k in metadata if k == "imulog.alignment" or k.startswith("imulog.alignment.")]
    inputs = [f"/imu/{n}" for n in names]
    inputs += [t for t in topics if t.startswith("/derived/vicon/cluster_pose")]
    inputs += [f"/derived/acc_global/{n}" for n in names if f"/derived/acc_global/{n}" in topics]

    def compute(trial) -> dict[str, Any]:
        record = compute_gait_evaluation(trial, names, walking)
        return record

    return run_record_step(
        path,
        record_name="imulog.evaluation",
        compute_record=compute,
        step="evaluate",
        algorithm="imulog.evaluation.strides",
        params={"imus": names, "walking": walking},
        inputs=inputs,
        metadata_inputs=tuple(records),
        force=force,
    )
