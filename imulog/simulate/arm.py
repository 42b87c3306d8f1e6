"""Two-segment arm: IMUs on the upper arm and forearm with known shoulder and elbow angles.

The true joint angles (the five free angles of :mod:`imulog.process.kinematics.dh`) start in a static
neutral posture, then blend (minimum-jerk, 2 s) into smooth sinusoids with per-joint frequencies
(0.05-0.25 Hz) inside the physiological limits. Elbow flexion and pronation-supination touch their
lower limits (0 deg) once per cycle, so the joint-limit constraint matters; the workspace boxes are
the bounding boxes of the true elbow and wrist centres (plus ``workspace_margin_m``), so the true
centres touch every face and any orientation error pushes the unconstrained solution outside.

Segment orientations come from the same DH model; each IMU is mounted with its axes on the DH segment
axes (optionally with a random ``mounting_error_deg``), the Vicon cluster on each IMU exactly as
in :mod:`imulog.simulate.vicon_model` (markers ``{segment}_O/X/Y/A``). IMU signals go through the
LSM9DS1-like error model of :mod:`imulog.simulate.imu_model` (no dropped samples). IMUs and Vicon
share one clock (a cable-synchronised station, as in the paper), both at ``rate_hz``.

The trunk frame (x lateral, y anterior, z up, origin in the shoulder centre) sits at ``shoulder_m``
in the Vicon world, turned by ``trunk_heading_deg`` about the vertical. By default the trunk is still
(the paper's assumption); ``trunk_sway_deg`` > 0 makes it turn about the vertical and lean forward
and sideways (pivot ``trunk_pivot_below_m`` under the shoulder) after the neutral posture, and
``trunk_imu=True`` adds a ``trunk`` IMU (axes on the trunk frame) with its own marker cluster.

    python -m imulog.simulate.arm arm.mcap --seconds 60 --seed 0     # writes an MCAP trial
    imulog simulate arm -o sim/ --seconds 60 --seed 0               # raw export files + truth

:func:`write_arm_files` writes a trial as a lab would have it (``imulog convert`` reads it back into
the same Recording): ``<stem>_imu.csv`` + ``<stem>_imu.mapping.json`` (both IMUs of the synchronised
station in one file, a sensor row naming each IMU's columns), ``<stem>_vicon.csv`` (Nexus CSV with
every cluster's markers), ``<stem>_meta.json`` (``imulog.trial``, ``imulog.anthropometrics``,
``imulog.kinematics``) and the truth ``<stem>_truth.json`` + ``<stem>_truth.npz``
(:func:`save_arm_truth`, read back with :func:`load_arm_truth`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from imulog.model import ImuStream, MarkerStream, Recording
from imulog.process import quaternion as quat
from imulog.process.kinematics.dh import JOINT_NAMES, ArmModel, JointLimits, forward_kinematics
from imulog.simulate import imu_model, minjerk, vicon_model
from imulog.simulate.arm_files import TRUTH_FORMAT, load_arm_truth, save_arm_truth, write_arm_files
from imulog.simulate.arm_params import (
    SEGMENTS,
    TRUNK,
    VICON_NAME,
    ArmParams,
    ArmTrial,
    ArmTruth,
    _split_overrides,
    arm_parameter_names,
)

__all__ = [
    "arm_parameter_names",
    "ArmParams",
    "ArmTrial",
    "ArmTruth",
    "load_arm_truth",
    "main",
    "save_arm_truth",
    "SEGMENTS",
    "simulate_arm",
    "simulate_arm_to_folder",
    "TRUNK",
    "TRUTH_FORMAT",
    "VICON_NAME",
    "write_arm_files",
]


def _joint_law(params: ArmParams, rng: np.random.Generator):
    lo, hi = JointLimits().as_rad()
    qn = np.radians(params.neutral_pose_deg)
    c = np.radians(params.centre_deg)
    a = np.radians(params.amplitude_deg)
    if np.any(c - a < lo - 1e-12) or np.any(c + a > hi + 1e-12) or np.any(qn < lo) or np.any(qn > hi):
        raise ValueError("arm movement or neutral posture outside the physiological joint limits")
    f = rng.uniform(*params.frequency_hz, 5)
    t_move = params.neutral_s + params.blend_s
    # phase so that the movement starts at the centre, moving (sin(0)=0) for a smooth blend
    phi = rng.uniform(0, 2 * np.pi, 5)

    def q_of_t(t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)[:, None]
        move = c + a * np.sin(2 * np.pi * f * (t - params.neutral_s) + phi)
        tau = np.clip((t - params.neutral_s) / params.blend_s, 0.0, 1.0)
        b = minjerk.profile(tau)[0]
        return qn + b * (move - qn)

    return q_of_t, {"frequency_hz": f.tolist(), "phase_rad": phi.tolist(), "movement_start_s": t_move}


def _trunk_law(params: ArmParams, rng: np.random.Generator):
    """Trunk-to-world quaternion (N, 4) of times (s): heading, then sway blended in after the posture."""
    psi0 = math.radians(params.trunk_heading_deg)
    amp = math.radians(params.trunk_sway_deg)
    f = rng.uniform(0.03, 0.12, 3)
    phi = rng.uniform(0, 2 * np.pi, 3)

    def q_of_t(t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=np.float64)
        tau = np.clip((t - params.neutral_s) / params.blend_s, 0.0, 1.0)
        b = minjerk.profile(tau)[0] * amp
        yaw = psi0 + b * np.sin(2 * np.pi * f[0] * (t - params.neutral_s) + phi[0])
        fwd = 0.5 * b * (1 - np.cos(2 * np.pi * f[1] * (t - params.neutral_s)))  # forward lean >= 0
        side = 0.5 * b * np.sin(2 * np.pi * f[2] * (t - params.neutral_s) + phi[2])
        z = np.zeros_like(t)
        q_yaw = quat.from_rotation_vector(np.column_stack([z, z, yaw]))
        q_fwd = quat.from_rotation_vector(np.column_stack([-fwd, z, z]))  # about -x (lateral): leaning toward +y
        q_side = quat.from_rotation_vector(np.column_stack([z, side, z]))
        return quat.normalize(quat.multiply(quat.multiply(q_yaw, q_fwd), q_side))

    return q_of_t


def _segment_offsets(model: ArmModel, lever_m: float) -> dict[str, np.ndarray]:
    """IMU origin in each segment frame (m): mid upper arm / distal third of the forearm, off-axis."""
    fk = forward_kinematics(np.zeros(5), model)
    to_shoulder = fk.r_upper_arm.T @ (np.zeros(3) - fk.elbow_m)  # constant in frame 3
    to_elbow = fk.r_forearm.T @ (fk.elbow_m - fk.wrist_m)  # constant in frame 6

    def perp(v: np.ndarray) -> np.ndarray:
        u = np.cross(v, [1.0, 0.0, 0.0])
        if np.linalg.norm(u) < 1e-6 * np.linalg.norm(v):
            u = np.cross(v, [0.0, 1.0, 0.0])
        return u / np.linalg.norm(u)

    return {
        "upper_arm": 0.5 * to_shoulder + lever_m * perp(to_shoulder),
        "forearm": 0.3 * to_elbow + lever_m * perp(to_elbow),
    }


def simulate_arm(
    *,
    seed: int = 0,
    subject: int = 0,
    trial: int = 0,
    imu: imu_model.ImuParams | None = None,
    **overrides: Any,
) -> ArmTrial:
    """Simulate one arm trial; ``overrides`` set :class:`ArmParams` fields (e.g. ``duration_s=30``)
    or :class:`~imulog.simulate.imu_model.ImuParams` fields (e.g. ``gyr_noise_dps=0.01``).

    ``subject`` and ``trial`` select independent draws for the same ``seed`` (subject 0, trial 0
    gives the draws of ``seed`` alone)."""
    arm_overrides, imu_overrides = _split_overrides(overrides)
    params = ArmParams(**arm_overrides)
    base = [int(seed)] if (subject, trial) == (0, 0) else [int(seed), int(subject), int(trial)]

    def seeds(tag: int) -> np.random.SeedSequence:
        return np.random.SeedSequence([*base, tag])

    rng = np.random.default_rng(seeds(0xA53))
    model = ArmModel(
        params.upper_arm_length_m, params.forearm_length_m, params.styloid_distance_m, params.carrying_angle_deg
    )
    if imu is None:
        imu = imu_model.ImuParams.ideal() if params.noise_free else imu_model.ImuParams()
    imu = dataclasses.replace(imu, **{**imu_overrides, "drop_probability": 0.0})
    q_of_t, law_info = _joint_law(params, rng)

    n = int(round(params.duration_s * params.rate_hz)) + 1
    # whole microseconds (the IMU file writes ms with 3 decimals); exact ns for 100 Hz
    t_ns = np.round(np.arange(n) / params.rate_hz * 1e6).astype(np.int64) * 1000
    t_s = t_ns / 1e9
    offsets = _segment_offsets(model, params.imu_lever_m)
    mount = {
        s: quat.from_rotation_vector(rng.normal(0.0, math.radians(params.mounting_error_deg), 3)) for s in SEGMENTS
    }
    q_ic = {
        s: vicon_model.draw_imu_to_cluster(
            vicon_model.ViconParams(imu_to_cluster_sd_deg=params.imu_to_cluster_sd_deg), rng
        )
        for s in (*SEGMENTS, TRUNK)
    }
    trunk_of_t = _trunk_law(params, np.random.default_rng(seeds(0xA57)))
    pivot = np.asarray(params.shoulder_m, dtype=np.float64) - np.array([0.0, 0.0, params.trunk_pivot_below_m])
    up = np.array([0.0, 0.0, params.trunk_pivot_below_m])  # pivot -> shoulder, trunk frame
    sternum = np.array([-0.18, 0.12, -0.12])  # trunk IMU on the sternum, trunk frame (right shoulder origin)
    device_rng = np.random.default_rng(seeds(0xA54))
    noise_rng = np.random.default_rng(seeds(0xA55))
    vicon_rng = np.random.default_rng(seeds(0xA56))
    stem = f"arm_s{subject:02d}_t{trial:02d}"
    inc = math.radians(params.inclination_deg)
    field_world = params.field_uT * np.array([math.cos(inc), 0.0, -math.sin(inc)])

    def world_state(ts: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per segment: sensor-to-world quaternion (N, 4) and IMU position (N, 3) m at times ``ts`` (s)."""
        fk = forward_kinematics(q_of_t(ts), model)
        q_wt = trunk_of_t(ts)
        shoulder = pivot + quat.rotate(q_wt, np.broadcast_to(up, (len(ts), 3)))
        out = {TRUNK: (q_wt, shoulder + quat.rotate(q_wt, np.broadcast_to(sternum, (len(ts), 3))))}
        for seg, r_seg, origin in (
            ("upper_arm", fk.r_upper_arm, fk.elbow_m),
            ("forearm", fk.r_forearm, fk.wrist_m),
        ):
            q_ts = quat.from_rotation_matrix(np.asarray(r_seg))
            q_ws = quat.normalize(quat.multiply(quat.multiply(q_wt, q_ts), mount[seg]))
            p_trunk = origin + np.einsum("nij,j->ni", r_seg, offsets[seg])
            out[seg] = (q_ws, shoulder + quat.rotate(q_wt, p_trunk))
        return out

    h = 1e-3
    now, plus, minus = world_state(t_s), world_state(t_s + h), world_state(t_s - h)
    fk_true = forward_kinematics(q_of_t(t_s), model)
    imus, marker_pos, labels, channels = [], [], [], {}
    vparams = vicon_model.ViconParams(noise_mm=params.vicon_noise_mm)
    wearing = (*SEGMENTS, TRUNK) if params.trunk_imu else SEGMENTS
    for seg in wearing:
        q_ws, p = now[seg]
        qp, pp = plus[seg]
        qm, pm = minus[seg]
        acc_world = (pp - 2 * p + pm) / h**2
        qp = np.where(np.sum(qp * q_ws, axis=1, keepdims=True) < 0, -qp, qp)
        qm = np.where(np.sum(qm * q_ws, axis=1, keepdims=True) < 0, -qm, qm)
        dq = (qp - qm) / (2 * h)
        omega = 2.0 * quat.multiply(quat.conjugate(q_ws), dq)[:, 1:]
        f_sensor = quat.rotate_inverse(q_ws, acc_world + np.array([0.0, 0.0, imu_model.EARTH_G]))
        m_sensor = quat.rotate_inverse(q_ws, np.broadcast_to(field_world, p.shape))
        device = imu_model.draw_device(imu, device_rng)
        ch = imu_model.measure(f_sensor, omega, m_sensor, t_s, imu, device, noise_rng)
        channels[seg] = ch
        meta = {
            "model": "LSM9DS1 (simulated)",
            "rate_hz": params.rate_hz,
            "units": {q: c.unit for q, c in ch.items()},
            "source": f"{stem}_imu.csv",
            "segment": seg,
        }
        imus.append(ImuStream(seg, t_ns, acc=ch["acc"].si, gyr=ch["gyr"].si, mag=ch["mag"].si, meta=meta))
        true_markers = vicon_model.marker_positions(p, q_ws, q_ic[seg], vparams)
        marker_pos.append(
            vicon_model.add_noise_and_gaps(true_markers, params.rate_hz, vparams, vicon_rng, params.noise_free)
        )
        labels += [f"{seg}_{lab}" for lab in vicon_model.LABELS]
    markers = MarkerStream(
        VICON_NAME, t_ns, labels, np.concatenate(marker_pos, axis=1), meta={"rate_hz": params.rate_hz, "units": "mm"}
    )
    m = params.workspace_margin_m
    boxes = {
        "workspace_elbow_m": [(fk_true.elbow_m.min(0) - m).tolist(), (fk_true.elbow_m.max(0) + m).tolist()],
        "workspace_wrist_m": [(fk_true.wrist_m.min(0) - m).tolist(), (fk_true.wrist_m.max(0) + m).tolist()],
    }
    kin_meta = {
        "upper_arm_imu": "upper_arm",
        "forearm_imu": "forearm",
        "markers": VICON_NAME,
        "clusters": {s: [f"{s}_{lab}" for lab in ("O", "X", "Y")] for s in wearing},
        **({"trunk_imu": TRUNK} if params.trunk_imu else {}),
        "neutral_pose_deg": list(params.neutral_pose_deg),
        "neutral_window_s": [0.5, params.neutral_s - 0.5],
        "side": "right",
        "frame": "trunk: origin shoulder centre, x lateral, y anterior, z up (Caruso 2024)",
        **boxes,
    }
    anthropometrics = {
        "upper_arm_length_m": params.upper_arm_length_m,
        "forearm_length_m": params.forearm_length_m,
        "styloid_distance_m": params.styloid_distance_m,
        "carrying_angle_deg": params.carrying_angle_deg,
    }
    recording = Recording(
        imus=imus,
        markers=[markers],
        metadata={
            "imulog.trial": {
                "subject": f"S{subject:02d}",
                "trial": int(trial),
                "task": "arm",
                "simulated": True,
                "seed": int(seed),
            },
            "imulog.anthropometrics": anthropometrics,
            "imulog.kinematics": kin_meta,
            **{f"imulog.device.{s.name}": dict(s.meta) for s in imus},
        },
    )
    truth = ArmTruth(
        t_ns=t_ns,
        q_rad=q_of_t(t_s),
        r_upper_arm=fk_true.r_upper_arm,
        r_forearm=fk_true.r_forearm,
        elbow_m=fk_true.elbow_m,
        wrist_m=fk_true.wrist_m,
        q_world_trunk=now[TRUNK][0],
        q_segment_to_sensor=mount,
        info={
            "joint_names": list(JOINT_NAMES),
            **law_info,
            "params": dataclasses.asdict(params),
            "imu_params": dataclasses.asdict(imu),
            "seed": int(seed),
            "subject": int(subject),
            "trial": int(trial),
            "rate_hz": params.rate_hz,
            "clock": "IMUs and Vicon share one clock (offset 0, no drift)",
            "rotation_imu_to_cluster": {s: [float(v) for v in q_ic[s]] for s in wearing},
        },
        q_world_sensor={s: now[s][0] for s in wearing},
        imu_position_m={s: now[s][1] for s in wearing},
    )
    raw = {"t_ns": t_ns, "channels": channels, "vicon_decimals": vparams.decimals}
    return ArmTrial(recording, truth, params, int(seed), int(subject), int(trial), raw)


def simulate_arm_to_folder(
    out_dir: Path | str,
    subjects: int = 1,
    trials: int = 1,
    seed: int = 0,
    progress: Callable[[int, int, str], Any] | None = None,
    **overrides: Any,
) -> list[dict[str, Path]]:
    """``subjects`` x ``trials`` arm trials written with :func:`write_arm_files`; ``progress(done,
    total, stem)`` after each. Returns one dict of paths per trial, in (subject, trial) order."""
    written = []
    total = subjects * trials
    for s in range(subjects):
        for t in range(trials):
            sim = simulate_arm(seed=seed, subject=s, trial=t, **overrides)
            written.append(write_arm_files(sim, out_dir))
            if progress is not None:
                progress(len(written), total, sim.stem)
    return written


def main(argv: list[str] | None = None) -> None:
    """``python -m imulog.simulate.arm OUT.mcap [--seconds S] [--seed N] [--noise-free] [--trunk-imu] [--trunk-sway DEG]``."""
    parser = argparse.ArgumentParser(description="Simulate a two-IMU arm trial and write it as an MCAP trial.")
    parser.add_argument("out", type=Path)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--noise-free", action="store_true")
    parser.add_argument("--trunk-imu", action="store_true", help="add a trunk IMU and cluster")
    parser.add_argument("--trunk-sway", type=float, default=0.0, help="trunk sway amplitude, deg (0: still trunk)")
    parser.add_argument("--overwrite", action="store_true")
    args = parser.parse_args(argv)
    from imulog.archive import write_trial

    sim = simulate_arm(
        seed=args.seed,
        duration_s=args.seconds,
        noise_free=args.noise_free,
        trunk_imu=args.trunk_imu,
        trunk_sway_deg=args.trunk_sway,
    )
    path = write_trial(args.out, sim.recording, attach_sources=False, overwrite=args.overwrite)
    print(f"wrote {path}")


if __name__ == "__main__":  # pragma: no cover
    main()
