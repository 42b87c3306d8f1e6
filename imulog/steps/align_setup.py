"""Step ``align`` on a whole setup: every IMU of the trial against every marker (issue 27).

Run by ``imulog process align`` when the trial has several IMUs and none is named (or several are). Each IMU
is paired one to one with its rigid marker cluster (:func:`imulog.process.alignment_setup.find_setup_clusters`),
the IMUs of one recording get one clock fitted to all their windows together, and an IMU without a cluster
gets its recording's clock and is flagged ``frame_alignment: false``. Writes

* ``imulog.alignment.{imu}`` per IMU (the single-IMU record's keys, plus ``clock`` = ``shared`` or ``own``,
  ``clock_group``, ``own_clock`` (what its windows alone give) and ``frame_alignment``);
* ``imulog.alignment``: the record of the first paired IMU with ``setup`` (every IMU's offset, markers,
  quality), so that readers of one alignment keep working;
* per paired IMU ``/derived/vicon/cluster_pose/{imu}``, ``/derived/vicon/angular_velocity/{imu}`` and, with
  ``resample``, ``/derived/reference/{gyr,orientation,acc_global}/{imu}``.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from imulog.process import alignment as al
from imulog.process.resample import resample_quaternions
from imulog.steps.align import (
    STEP,
    _jsonable,
    alignment_streams,
    compute_alignment,
    imu_span,
    params_dict,
)
from imulog.steps.align_summary import setup_summary
from imulog.steps.common import mean_rate_hz, names_trial, renamed
from imulog.steps.recording_clock import CLOCK_KEYS, channel_span, recording_clock_record

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome


def _own_clock(record: dict) -> dict:
    return {k: record.get(k) for k in ("offset_ns", "drift_ppm", "offset_uncertainty_ns", "score") if k in record}


def compute_setup_alignment(
    imus: dict[str, dict],
    marker_topic: str,
    t_vic_ns: np.ndarray,
    labels: list[str],
    pos_m: np.ndarray,
    params: al.AlignmentParams,
    device_meta: dict[str, dict],
    resample: bool = True,
    spans: dict[str, tuple[int, int, int]] | None = None,
) -> tuple[list, dict[str, dict], dict]:
    """Pure part: ``imus`` name -> {t_ns, gyr, acc, orientation, acc_global} (the last two (t_ns, values) or
    None); ``spans``: each IMU's whole channel (count, first ns, last ns) when ``t_ns`` is only a stretch of it
    (:func:`imulog.steps.recording_clock.channel_span`). Returns (streams, records by IMU name, search summary)."""
    from imulog.process.alignment_setup import find_setup_clusters, pooled_clock, recording_groups

    vic_rate = mean_rate_hz(t_vic_ns)
    usable = {n: d for n, d in imus.items() if d.get("gyr") is not None}
    matches, summary = find_setup_clusters(
        {n: (d["t_ns"], d["gyr"]) for n, d in usable.items()}, t_vic_ns, labels, pos_m, vic_rate, params
    )
    groups = recording_groups(list(imus), device_meta, spans or {n: d["t_ns"] for n, d in imus.items()})
    summary["recordings"] = groups
    records: dict[str, dict] = {}
    streams: list = []
    for group in groups:
        paired = [n for n in group if n in matches]
        clock = None
        if paired:
            clock = pooled_clock([{**matches[n].record, "imu": n} for n in paired], params)
        for name in group:
            d = imus[name]
            q_s2g = None
            if d.get("orientation") is not None:
                t_o, q_o = d["orientation"]
                q_s2g = q_o if np.array_equal(t_o, d["t_ns"]) else resample_quaternions(t_o, q_o, d["t_ns"])
            base = {"reference": marker_topic, "imu": f"/imu/{name}", "clock_group": list(group)}
            if clock is None:
                # no IMU of this recording has a cluster: each aligns on its own (a marker's acceleration)
                try:
                    s, rec = compute_alignment(
                        name,
                        d["t_ns"],
                        d["gyr"],
                        marker_topic,
                        t_vic_ns,
                        labels,
                        pos_m,
                        params,
                        d.get("orientation"),
                        d.get("acc_global"),
                        resample,
                        acc=d.get("acc"),
                    )
                except ValueError as exc:
                    records[name] = {**base, "quality": "failed", "quality_reasons": [str(exc)]}
                    continue
                rec.update(
                    clock="own", clock_group=list(group), frame_alignment=rec.get("rotation_imu_to_cluster") is not None
                )
                records[name] = rec
                streams += renamed(s, f"/{name}")
                continue
            clock_fields = {k: clock[k] for k in CLOCK_KEYS if k in clock}
            if name in matches:
                m = matches[name]
                rec = al.align_frames(d["t_ns"], d["gyr"], m.kinematics, clock_fields, params, q_imu_s2g=q_s2g)
                rec.update(
                    base,
                    windows=[w for w in clock["windows"] if w.get("imu") == name],
                    own_clock=_own_clock(m.record),
                    clock="shared" if len(paired) > 1 else "own",
                    frame_alignment=True,
                    cluster={**m.info, "vector_match": round(float(rec["vector_match"]), 4)},
                )
                rec["method"] = m.record.get("method", "") + ";setup"
                ck = m.kinematics
            else:
                rec = recording_clock_record(base, clock, paired, "no rigid marker cluster moves with this IMU")
                ck = None
            rec = {**base, **rec}
            if ck is not None:
                rec["quality"], rec["quality_reasons"] = al.assess_quality(rec, params)
            records[name] = _jsonable(rec)
            streams += alignment_streams(
                name,
                ck,
                rec,
                d["t_ns"],
                d["gyr"],
                t_vic_ns,
                vic_rate,
                d.get("orientation"),
                d.get("acc_global"),
                resample,
                suffix=f"/{name}",
            )
    return streams, records, summary


@names_trial
def run_align_setup(
    path: str | os.PathLike[str],
    *,
    imus: list[str] | None = None,
    markers: str | None = None,
    params: al.AlignmentParams | None = None,
    resample: bool = True,
    force: bool = False,
) -> StepOutcome:
    """Align every IMU of the trial (or those named) with the markers; returns the run_step outcome."""
    params = params or al.AlignmentParams()
    from imulog.archive import TrialReader
    from imulog.steps.align import pick_markers
    from imulog.steps.base import StepResult, run_step

    with TrialReader(path) as trial:
        topics = trial.topics()
    all_imus = [t[len("/imu/") :] for t in topics if t.startswith("/imu/")]
    names = list(imus) if imus else all_imus
    missing = [n for n in names if n not in all_imus]
    if missing:
        raise ValueError(f"no channel /imu/{missing[0]} in the trial (IMUs: {', '.join(all_imus) or 'none'})")
    if not names:
        raise ValueError("no /imu/* channel in the trial")
    mname = pick_markers(topics, markers)
    marker_topic = f"/markers/{mname}"
    inputs = [f"/imu/{n}" for n in names] + [marker_topic]
    inputs += [
        f"/derived/{k}/{n}" for n in names for k in ("orientation", "acc_global") if f"/derived/{k}/{n}" in topics
    ]

    def compute(trial) -> StepResult:
        mk = trial.read(marker_topic)
        data = {}
        device_meta = {}
        for n in names:
            lo, hi = imu_span(trial, f"/imu/{n}", marker_topic, params.max_lag_s)  # around the markers' span
            s = trial.read(f"/imu/{n}", lo, hi)
            d = {"t_ns": s.t_ns, "gyr": s.gyr, "acc": s.acc, "orientation": None, "acc_global": None}
            for k, key in (("orientation", "orientation"), ("acc_global", "acc_global")):
                topic = f"/derived/{k}/{n}"
                if topic in inputs:
                    x = trial.read(topic, lo, hi)
                    d[key] = (x.t_ns, x.values)
            data[n] = d
            device_meta[n] = dict(trial.metadata.get(f"imulog.device.{n}") or {})
        spans = {n: channel_span(trial, f"/imu/{n}") for n in names}
        streams, records, summary = compute_setup_alignment(
            data, marker_topic, mk.t_ns, mk.labels, mk.pos, params, device_meta, resample, spans
        )
        ok = [n for n in names if records[n].get("quality") != "failed"]
        if not ok:
            raise ValueError(
                f"{marker_topic}: no IMU could be aligned ("
                + "; ".join(f"{n}: {records[n]['quality_reasons'][0]}" for n in names)
                + ")"
            )
        primary = next((n for n in ok if records[n].get("frame_alignment")), ok[0])
        table = setup_summary(records)
        main = {**records[primary], "setup": table, "search": _jsonable(summary)}
        metadata = {"imulog.alignment": main, **{f"imulog.alignment.{n}": records[n] for n in names}}
        return StepResult(streams=streams, metadata=metadata)

    return run_step(
        path,
        step=STEP,
        algorithm="imulog.alignment.xcorr_wahba.setup",
        params={"imus": names, "markers": mname, "resample": resample, **params_dict(params)},
        inputs=inputs,
        compute=compute,
        force=force,
    )


@names_trial
def run_align_trial(
    path: str | os.PathLike[str],
    *,
    imu: str | None = None,
    markers: str | None = None,
    params: al.AlignmentParams | None = None,
    resample: bool = True,
    force: bool = False,
    poses: str | None = None,
) -> StepOutcome:
    """The align step as ``imulog process align`` runs it: on a rigid body's poses when the trial has poses and no
    markers, or ``poses`` is named (:func:`imulog.steps.align_pose.run_align_pose`); else one IMU when named or
    when the trial has one, else every IMU (:func:`run_align_setup`). Keywords as
    :func:`imulog.steps.align.run_align`."""
    from imulog.archive import TrialReader
    from imulog.steps.align import run_align
    from imulog.steps.align_pose import aligns_on_poses, run_align_pose

    with TrialReader(path) as trial:
        topics = trial.topics()
    n = sum(t.startswith("/imu/") for t in topics)
    if aligns_on_poses(topics, markers, poses):  # a rigid body's poses (docs/alignment.md): one IMU
        if imu is None and n > 1:  # every IMU with its own body, paired by the data
            from imulog.steps.align_pose_setup import run_align_pose_setup

            return run_align_pose_setup(path, params=params, resample=resample, force=force)
        return run_align_pose(path, imu=imu, poses=poses, params=params, resample=resample, force=force)
    kw = {"markers": markers, "params": params, "resample": resample, "force": force}
    if imu is None and n > 1:
        return run_align_setup(path, **kw)
    return run_align(path, imu=imu, **kw)
