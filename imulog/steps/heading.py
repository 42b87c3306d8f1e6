"""Step ``heading``: one heading frame for the oriented IMUs of a trial (:mod:`imulog.process.heading`).

Reads ``/derived/orientation/{imu}`` (and its ``global_frame`` param), ``/imu/{imu}`` for the magnetometer and
the alignment records (``rotation_global_to_world``). Writes metadata ``imulog.heading``: ``source``
(``magnetometer``, ``optical``, ``static pose`` or ``none``), ``frame`` (what the common frame is), per IMU its
``correction`` (quaternion w,x,y,z, the IMU's global frame to the common one: ``q_common = correction *
q_s2g``) and ``global_frame``, and ``rejected`` (why each better source did not apply). With one IMU there is
nothing to relate and the step says so. :func:`common_heading` is what exports that combine IMUs read.
"""

from __future__ import annotations

import os
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.steps.common import names_trial

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "heading"


def common_heading(metadata: dict[str, Any], imus: list[str]) -> tuple[dict[str, list[float]] | None, str]:
    """Per IMU the correction into the trial's common heading frame, or None and a one-line warning (no
    ``imulog.heading`` record, source ``none``, or an IMU it does not cover)."""
    rec = metadata.get("imulog.heading") or {}
    if not rec:
        return None, "the IMUs' headings are not related (run `imulog process heading`)"
    if rec.get("source") == "none":
        return None, "the IMUs' headings are not related: " + "; ".join(rec.get("rejected") or [])
    missing = [n for n in imus if n not in (rec.get("imus") or {})]
    if missing:
        return None, f"no common heading for {', '.join(missing)} (run `imulog process heading` again)"
    return {n: rec["imus"][n]["correction"] for n in imus}, ""


def global_to_world_from_pose(
    t_ns: np.ndarray, q_s2g: np.ndarray, alignment: dict[str, Any], pose_t_ns: np.ndarray, pose_q_c2w: np.ndarray
) -> list[float] | None:
    """The IMU's ``rotation_global_to_world`` (w,x,y,z) from its orientation (device clock), its alignment record
    (clock and ``rotation_imu_to_cluster``) and its cluster's poses (reference clock): what the align step
    records when the orientation existed before it. None without the rotation or common samples."""
    from imulog.process.alignment import device_to_reference
    from imulog.process.alignment_lag import rotation_global_to_world
    from imulog.process.resample import resample_quaternions

    q_i2c = alignment.get("rotation_imu_to_cluster")
    if q_i2c is None or pose_q_c2w is None:
        return None
    q_at = resample_quaternions(device_to_reference(np.asarray(t_ns, np.int64), alignment), q_s2g, pose_t_ns)
    ok = np.all(np.isfinite(q_at), axis=1) & np.all(np.isfinite(pose_q_c2w), axis=1)
    if ok.sum() < 10:
        return None
    q = rotation_global_to_world(q_at[ok], pose_q_c2w[ok], np.asarray(q_i2c, np.float64))
    return [float(v) for v in q]


POSE_MARGIN_S = 60.0  # orientation read either side of the cluster's poses (the resampling filter's edges)


def pose_span_on_device(pose_t_ns: np.ndarray, alignment: dict[str, Any]) -> tuple[int, int]:
    """The device-clock span [lo, hi) (ns) holding the cluster poses' times ``pose_t_ns`` (reference clock)
    and :data:`POSE_MARGIN_S` either side."""
    from imulog.process.alignment_clock import reference_to_device

    ends = reference_to_device(np.array([pose_t_ns.min(), pose_t_ns.max()], np.int64), alignment)
    margin = int(POSE_MARGIN_S * 1e9)
    return int(ends[0]) - margin, int(ends[1]) + margin + 1


def compute_heading(
    orientations: dict[str, tuple[np.ndarray, np.ndarray, str]],
    mags: dict[str, tuple[np.ndarray, np.ndarray] | None],
    alignments: dict[str, dict | None],
    static_s: tuple[float, float] | None = None,
    declared_deg: dict[str, float] | None = None,
    devices: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
) -> dict[str, Any]:
    """The ``imulog.heading`` record. ``devices``: name -> (t_ns, the device's own orientation, sensor to the
    device's global frame) when the IMUs are of one recording: the last source, the device's frame. ``orientations``: name -> (t_ns, q_s2g, global_frame); ``mags``: name ->
    (t_ns, field uT) or None; ``alignments``: name -> alignment record or None; ``static_s``: a declared pose
    (s from each IMU's first sample)."""
    from imulog.process import heading as hd
    from imulog.process.orientation import GLOBAL_FRAME_9D
    from imulog.process.resample import resample_quaternions

    names = list(orientations)
    rejected: list[str] = []
    frames = {n: orientations[n][2] for n in names}

    def record(source: str, frame: str, corr: dict[str, np.ndarray] | None, **extra) -> dict[str, Any]:
        imus = {
            n: {
                "global_frame": frames[n],
                **({"correction": [float(v) for v in corr[n]]} if corr is not None else {}),
            }
            for n in names
        }
        return {"source": source, "frame": frame, "imus": imus, "rejected": rejected, **extra}

    fields = {}
    if all(mags.get(n) is not None for n in names):
        try:
            for n in names:
                t_o, q, _ = orientations[n]
                t_m, m = mags[n]
                qm = q if np.array_equal(t_o, t_m) else resample_quaternions(t_o, q, t_m)
                fields[n] = hd.field_in_global(qm, m)
            corr, why = hd.magnetic_corrections(fields)
        except ValueError as exc:
            corr, why = None, str(exc)
        if corr is not None and all(frames[n] == GLOBAL_FRAME_9D for n in names):
            return record("magnetometer", "ENU (magnetic north; every orientation fused the field)", corr, field=fields)
        if corr is None:
            rejected.append(f"magnetometer: {why}")
    else:
        rejected.append("magnetometer: not every IMU has one")
        corr = None
    g2w = {n: (alignments.get(n) or {}).get("rotation_global_to_world") for n in names}
    if all(v is not None for v in g2w.values()):
        return record("optical", "the optical world (markers' frame)", {n: np.asarray(v) for n, v in g2w.items()})
    no = [n for n, v in g2w.items() if v is None]
    rejected.append(f"optical: no rotation global-to-world for {', '.join(no)} (align after orientation)")
    if corr is not None:
        return record("magnetometer", "ENU (magnetic north, from each IMU's field)", corr, field=fields)
    if static_s is not None:
        a, b = static_s
        in_pose = {}
        for n in names:
            t, q, _ = orientations[n]
            ts = (t - t[0]) / 1e9
            in_pose[n] = q[(ts >= a) & (ts <= b)]
        corr = hd.static_pose_corrections(in_pose, declared_deg)
        return record(
            "static pose",
            f"sensor x headings in the pose {a:g}-{b:g} s set to "
            + ("the declared ones" if declared_deg else f"{names[0]}'s"),
            corr,
        )
    rejected.append("static pose: none declared (--static-pose START,END)")
    if devices and all(devices.get(n) is not None for n in names):
        corr, spread = {}, {}
        for n in names:
            t_o, q, _ = orientations[n]
            t_d, q_d = devices[n]
            yaw, sd = device_yaw(t_o, q, t_d, q_d)
            corr[n], spread[n] = hd.yaw_quaternion(yaw), sd
        worst = max(spread, key=lambda n: spread[n])
        if spread[worst] <= DEVICE_YAW_SD_DEG:
            return record(
                "device",
                "the device's global frame (its own orientations of one recording)",
                corr,
                yaw_sd_deg={n: round(v, 2) for n, v in spread.items()},
            )
        rejected.append(
            f"device: {worst}'s own orientation turns against imulog's by {spread[worst]:.1f} deg (sd) over the "
            f"trial (at most {DEVICE_YAW_SD_DEG:g})"
        )
    else:
        rejected.append("device: not every IMU has the device's own orientation (/orientation/IMU) of one recording")
    return record("none", "none: each IMU keeps its own heading", None)


DEVICE_YAW_SD_DEG = 5.0  # the heading between imulog's and the device's orientation may wander this much (sd)


def device_yaw(t_ns: np.ndarray, q_s2g: np.ndarray, t_dev_ns: np.ndarray, q_dev: np.ndarray) -> tuple[float, float]:
    """The rotation about the vertical (rad) from imulog's global frame to the device's, its circular mean over
    the trial, and how much it wanders (circular sd, deg)."""
    from imulog.process import quaternion as quat
    from imulog.process.resample import resample_quaternions

    qd = q_dev if np.array_equal(t_ns, t_dev_ns) else resample_quaternions(t_dev_ns, q_dev, t_ns)
    e = quat.multiply(quat.normalize(qd), quat.conjugate(q_s2g))
    ok = np.all(np.isfinite(e), axis=1)
    x = quat.rotate(e[ok], np.array([1.0, 0.0, 0.0]))
    z = np.exp(1j * np.arctan2(x[:, 1], x[:, 0]))
    r = abs(z.mean())
    sd = float(np.degrees(np.sqrt(max(-2.0 * np.log(max(r, 1e-12)), 0.0))))
    return float(np.angle(z.mean())), sd


@names_trial
def run_heading(
    path: str | os.PathLike[str],
    *,
    imus: list[str] | None = None,
    static_s: tuple[float, float] | None = None,
    declared_deg: dict[str, float] | None = None,
    force: bool = False,
) -> tuple[StepOutcome, dict[str, Any]]:
    """Run the step on a trial file; returns ``(outcome, record)``."""
    from imulog.archive import TrialReader
    from imulog.steps.base import run_record_step
    from imulog.steps.common import alignment_for, cluster_pose_topic

    with TrialReader(path) as trial:
        topics = trial.topics()
        oriented = [t.rsplit("/", 1)[1] for t in topics if t.startswith("/derived/orientation/")]
        metadata = trial.metadata
    names = list(imus) if imus else oriented
    missing = [n for n in names if n not in oriented]
    if missing:
        raise ValueError(
            f"no /derived/orientation/{missing[0]}: run `imulog process orientation {path} --imu {missing[0]}` first"
        )
    if not names:
        raise ValueError(f"no /derived/orientation/* channel: run `imulog process orientation {path}` first")
    inputs = [f"/derived/orientation/{n}" for n in names] + [f"/imu/{n}" for n in names if f"/imu/{n}" in topics]
    inputs += [t for n in names if (t := cluster_pose_topic(n, topics, metadata)) is not None]
    inputs += [f"/orientation/{n}" for n in names if f"/orientation/{n}" in topics]
    meta_inputs = tuple(k for k in metadata if k == "imulog.alignment" or k.startswith("imulog.alignment."))

    def compute(trial) -> dict[str, Any]:
        orientations, mags, aligns = {}, {}, {}
        # the orientations and magnetometers are read only for a source that uses them (the field, a declared
        # pose, the device's own orientations): the optical source and none need neither, so they are not read
        # whole (a week of two IMUs' quaternions is 4 GB; issue 24)
        with_mag = all(_has_mag(trial, n, topics) for n in names)
        series = with_mag or static_s is not None or all(f"/orientation/{n}" in topics for n in names)
        for n in names:
            ch = trial.channel(f"/derived/orientation/{n}")
            params = ch.metadata.get("params") or {}
            if isinstance(params, str):
                import json

                params = json.loads(params)
            aligns[n] = alignment_for(trial.metadata, f"/imu/{n}")
            pose = cluster_pose_topic(n, topics, trial.metadata)
            late = aligns[n] and aligns[n].get("rotation_global_to_world") is None and pose is not None
            none = SimpleNamespace(t_ns=np.zeros(0, np.int64), values=np.zeros((0, 4)))
            s = trial.read(f"/derived/orientation/{n}") if series else none
            orientations[n] = (s.t_ns, s.values, str(params.get("global_frame", "")))
            mags[n] = None
            if with_mag:
                imu = trial.read(f"/imu/{n}")
                if imu.mag is not None and np.isfinite(imu.mag).any():
                    mags[n] = (imu.t_ns, imu.mag)
            if late:
                # aligned before it was oriented: the same rotation from the cluster's poses, from the
                # orientation over the poses' span only (a lab hour of a week: issue 24)
                ps = trial.read(pose)
                if not series and len(ps.t_ns):
                    lo, hi = pose_span_on_device(ps.t_ns, aligns[n])
                    s = trial.read(f"/derived/orientation/{n}", lo, hi)
                g2w = global_to_world_from_pose(s.t_ns, s.values, aligns[n], ps.t_ns, ps.orientation)
                if g2w is not None:
                    aligns[n] = {**aligns[n], "rotation_global_to_world": g2w}
        devices = {n: _device_orientation(trial, n, topics) for n in names}
        record = compute_heading(orientations, mags, aligns, static_s, declared_deg, devices)
        if len(names) == 1:
            record["note"] = "one IMU: nothing to relate"
        return record

    return run_record_step(
        path,
        record_name="imulog.heading",
        compute_record=compute,
        step=STEP,
        algorithm="imulog.heading",
        params={"imus": names, "static_s": list(static_s) if static_s else None, "declared_deg": declared_deg},
        inputs=inputs,
        metadata_inputs=meta_inputs,
        force=force,
    )


def _has_mag(trial, name: str, topics: list[str]) -> bool:
    """Whether ``/imu/{name}`` records a magnetometer (its channel's columns; nothing read)."""
    import json

    if f"/imu/{name}" not in topics:
        return False
    columns = trial.channel(f"/imu/{name}").metadata.get("columns") or "[]"
    return "mag" in (json.loads(columns) if isinstance(columns, str) else columns)


def _device_orientation(trial, name: str, topics: list[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """The device's own orientation of IMU ``name`` (``/orientation/{name}``: t_ns, w,x,y,z), or None."""
    topic = f"/orientation/{name}"
    if topic not in topics:
        return None
    s = trial.read(topic)
    return s.t_ns, np.asarray(s.values, np.float64)[:, :4]


def refresh_heading(path, names: list[str] | None = None) -> dict[str, Any] | None:
    """Relate the headings of ``names`` (default: every oriented IMU; two or more) after the orientation or the align step:
    the heading step again with the options of its last run (a declared pose is kept), skipped when nothing it
    reads changed. Returns the record, or None with fewer than two oriented IMUs."""
    from imulog.archive import TrialReader

    with TrialReader(path) as trial:
        oriented = [t.rsplit("/", 1)[1] for t in trial.topics() if t.startswith("/derived/orientation/")]
        runs = trial.runs()
        last = next((runs[n] for n in sorted(runs, reverse=True) if runs[n].get("step") == STEP), {})
    names = [n for n in (oriented if names is None else names) if n in oriented]
    if len(names) < 2:
        return None
    params = last.get("params") or {}
    if isinstance(params, str):
        import json

        params = json.loads(params)
    static = params.get("static_s")
    _, record = run_heading(
        path, imus=names, static_s=tuple(static) if static else None, declared_deg=params.get("declared_deg")
    )
    return record


def heading_status(path, names: list[str], frame: str) -> str:
    """One line after orienting several IMUs: whether they share one heading frame, and what to run.

    Shared when an ``imulog.heading`` record covers ``names`` and its run read the orientation channels as they
    are now; otherwise the line says why not (6D: each heading arbitrary; 9D: magnetic north, not yet checked
    to agree) and names ``imulog process heading``."""
    from imulog.archive import TrialReader

    with TrialReader(path) as trial:
        record = trial.metadata.get("imulog.heading") or {}
        runs = trial.runs()
        last = next((runs[n] for n in sorted(runs, reverse=True) if runs[n].get("step") == STEP), {})
        inputs = last.get("inputs") or {}
        fresh = bool(record) and all(
            n in (record.get("imus") or {})
            and inputs.get(f"/derived/orientation/{n}") == trial.channel_hash(f"/derived/orientation/{n}")
            for n in names
        )
    listed = ", ".join(names)
    if fresh and record.get("source") != "none":
        return f"heading: one frame for {listed}: {record.get('source')} ({record.get('frame')})"
    if fresh:
        tried = ", ".join(str(r).split(":", 1)[0] for r in record.get("rejected") or [])
        return (
            f"heading: not shared by {listed} ({STEP} step: no {tried or 'source'} applies; `imulog info` says "
            f"why); declare a pose: `imulog process {STEP} {path} --static-pose START,END`"
        )
    from imulog.process.orientation import GLOBAL_FRAME_9D

    if frame == GLOBAL_FRAME_9D:
        what = "each heading is magnetic north as its own magnetometer sees it, not yet checked to agree"
    else:
        what = "each has its own arbitrary heading, 6D"
    return f"heading: not one frame yet for {len(names)} IMUs ({what}): run `imulog process {STEP} {path}`"
