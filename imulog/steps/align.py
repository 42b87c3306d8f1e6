"""Reprocessing step ``align``: IMU and Vicon on one clock and one frame.

Reads ``/imu/{imu}`` (gyroscope, device clock), ``/markers/{markers}`` (cluster markers, reference
clock) and, when present, ``/derived/orientation/{imu}`` and ``/derived/acc_global/{imu}``. Writes

* metadata ``imulog.alignment`` (reference, imu, offset_ns, drift_ppm, t0_ns,
  rotation_imu_to_cluster, rotation_global_to_world, method, score, plus diagnostics);
* ``/derived/vicon/cluster_pose`` (PoseStream: origin marker O (or the SVD fit's origin) in m,
  cluster-to-world orientation), reference clock;
* ``/derived/vicon/angular_velocity`` (``wx,wy,wz`` rad/s in the cluster frame), reference clock;
* with ``resample`` (default on), the IMU-derived channels on the Vicon clock and rate, anti-aliased:
  ``/derived/reference/gyr/{imu}`` (rad/s, sensor frame), ``/derived/reference/orientation/{imu}``
  and ``/derived/reference/acc_global/{imu}`` (when the orientation step has run).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from imulog.model import PoseStream, SignalStream
from imulog.process import alignment as al
from imulog.process.resample import resample_quaternions, resample_signal
from imulog.steps.common import mean_rate_hz, pick_imu

STEP = "align"


def pick_markers(topics: list[str], markers: str | None) -> str:
    names = [t.split("/", 2)[2] for t in topics if t.startswith("/markers/")]
    if markers is not None:
        if markers not in names:
            raise ValueError(
                f"no channel /markers/{markers} in the trial (marker channels: {', '.join(names) or 'none'})"
            )
        return markers
    if len(names) == 1:
        return names[0]
    if "vicon" in names:
        return "vicon"
    if not names:
        raise ValueError("no /markers/* channel in the trial: align needs optical markers (e.g. a Vicon export)")
    raise ValueError(f"choose a marker channel with --markers among: {', '.join(names)}")


def compute_alignment(
    imu_name: str,
    t_imu_ns: np.ndarray,
    gyr: np.ndarray,
    marker_topic: str,
    t_vic_ns: np.ndarray,
    labels: list[str],
    pos_m: np.ndarray,
    params: al.AlignmentParams,
    orientation: tuple[np.ndarray, np.ndarray] | None = None,
    acc_global: tuple[np.ndarray, np.ndarray] | None = None,
    resample: bool = True,
) -> tuple[list, dict]:
    """Pure part of the step: streams and the ``imulog.alignment`` record (no I/O)."""
    if gyr is None:
        raise ValueError(f"/imu/{imu_name} has no gyroscope columns")
    vic_rate = mean_rate_hz(t_vic_ns)
    try:
        ck = al.cluster_kinematics(t_vic_ns, labels, pos_m, vic_rate, params)
    except ValueError as exc:
        hint = (
            ""
            if params.cluster == "svd"
            else "; use >= 3 markers on one rigid segment: --cluster svd --cluster-markers A,B,C"
        )
        raise ValueError(f"{marker_topic}: {exc}{hint}") from None
    q_s2g = None
    if orientation is not None:
        t_o, q_o = orientation
        q_s2g = q_o if np.array_equal(t_o, t_imu_ns) else resample_quaternions(t_o, q_o, t_imu_ns)
    record = al.align(t_imu_ns, gyr, ck, params, q_imu_s2g=q_s2g)
    record = {"reference": marker_topic, "imu": f"/imu/{imu_name}", **record}
    ok = ~ck.missing
    streams: list = [
        PoseStream("/derived/vicon/cluster_pose", ck.t_ns[ok], ck.origin_m[ok], ck.quat_c2w[ok], frame_id="world"),
        SignalStream(
            "/derived/vicon/angular_velocity",
            ck.t_ns,
            ["wx", "wy", "wz"],
            ["rad/s"] * 3,
            ck.omega_local_rad_s,
            frame_id="cluster",
        ),
    ]
    if resample:
        t_ref_imu = al.device_to_reference(t_imu_ns, record)
        inside = (ck.t_ns >= t_ref_imu[0]) & (ck.t_ns <= t_ref_imu[-1])
        t_dst = ck.t_ns[inside]
        streams.append(
            SignalStream(
                f"/derived/reference/gyr/{imu_name}",
                t_dst,
                ["gx", "gy", "gz"],
                ["rad/s"] * 3,
                resample_signal(t_ref_imu, gyr, t_dst, dst_rate_hz=vic_rate),
                frame_id=imu_name,
            )
        )
        if orientation is not None:
            t_o = al.device_to_reference(orientation[0], record)
            streams.append(
                SignalStream(
                    f"/derived/reference/orientation/{imu_name}",
                    t_dst,
                    ["qw", "qx", "qy", "qz"],
                    ["1"] * 4,
                    resample_quaternions(t_o, orientation[1], t_dst, dst_rate_hz=vic_rate),
                    frame_id=f"{imu_name}_global",
                )
            )
        if acc_global is not None:
            t_a = al.device_to_reference(acc_global[0], record)
            streams.append(
                SignalStream(
                    f"/derived/reference/acc_global/{imu_name}",
                    t_dst,
                    ["ax", "ay", "az"],
                    ["m/s^2"] * 3,
                    resample_signal(t_a, acc_global[1], t_dst, dst_rate_hz=vic_rate),
                    frame_id=f"{imu_name}_global",
                )
            )
    return streams, record


def params_dict(params: al.AlignmentParams) -> dict:
    d = dataclasses.asdict(params)
    d["markers"] = list(params.markers)
    return d


def run_align(
    path,
    *,
    imu: str | None = None,
    markers: str | None = None,
    params: al.AlignmentParams | None = None,
    resample: bool = True,
    force: bool = False,
):
    """Run the step on a trial file; returns the :func:`imulog.steps.base.run_step` outcome."""
    params = params or al.AlignmentParams()
    from imulog.archive import TrialReader
    from imulog.steps.base import StepResult, run_step

    with TrialReader(path) as trial:
        topics = trial.topics()
        name = pick_imu(topics, imu)
        mname = pick_markers(topics, markers)
    imu_topic, marker_topic = f"/imu/{name}", f"/markers/{mname}"
    o_topic, a_topic = f"/derived/orientation/{name}", f"/derived/acc_global/{name}"
    inputs = [imu_topic, marker_topic] + [t for t in (o_topic, a_topic) if t in topics]

    def compute(trial) -> StepResult:
        imu_stream = trial.read(imu_topic)
        mk = trial.read(marker_topic)
        orientation = acc_global = None
        if o_topic in inputs:
            s = trial.read(o_topic)
            orientation = (s.t_ns, s.values)
        if a_topic in inputs:
            s = trial.read(a_topic)
            acc_global = (s.t_ns, s.values)
        streams, record = compute_alignment(
            name,
            imu_stream.t_ns,
            imu_stream.gyr,
            marker_topic,
            mk.t_ns,
            mk.labels,
            mk.pos,
            params,
            orientation,
            acc_global,
            resample,
        )
        return StepResult(streams=streams, metadata={"imulog.alignment": record})

    return run_step(
        path,
        step=STEP,
        algorithm="imulog.alignment.xcorr_wahba",
        params={"imu": name, "markers": mname, "resample": resample, **params_dict(params)},
        inputs=inputs,
        compute=compute,
        force=force,
    )
