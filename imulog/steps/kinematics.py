"""Reprocessing step ``kinematics``: shoulder and elbow angles from an upper-arm and a forearm IMU.

Reads ``/derived/orientation/{imu}`` of both IMUs, and of a trunk IMU when one is named (computed
in memory with the orientation step's default backend when absent; without a trunk IMU the trunk is
assumed still, as in the paper), the model geometry from ``imulog.anthropometrics`` and the task set-up
(IMU names, neutral posture and window, workspace boxes, joint limits, marker clusters) from
``imulog.kinematics``; writes on the upper-arm IMU's clock:

* ``/derived/kinematics/joint_angles_unconstrained`` and ``.../joint_angles_constrained``:
  SignalStream, columns :data:`~imulog.process.kinematics.dh.JOINT_NAMES`, unit **deg**;
* ``/derived/kinematics/elbow`` and ``/derived/kinematics/wrist``: PoseStream (frame ``trunk``,
  origin the shoulder centre, m) of the constrained solution; orientation = upper arm / forearm;
* ``/derived/kinematics/constraint_active``: columns ``active`` (any constraint), ``joint_limit``,
  ``elbow_box``, ``wrist_box`` (constrained solution on a bound) and ``outside_unconstrained`` (the
  paper's t_out), 0/1;
* with marker clusters: ``/derived/kinematics/joint_angles_reference`` (deg, the same solver fed with
  the cluster orientations, unconstrained) and the metadata record ``imulog.kinematics_errors``
  (e_tot / e_out, unconstrained and constrained, deg); always ``imulog.kinematics_calibration``.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.param_rules import check_rules
from imulog.process.kinematics.calibration import NeutralCalibration
from imulog.process.kinematics.dh import JOINT_NAMES, ArmModel, JointLimits
from imulog.process.kinematics.errors import kinematics_errors
from imulog.process.kinematics.pipeline import KinematicsConfig, estimate_kinematics
from imulog.process.kinematics.solver import SolverParams, Workspace
from imulog.process.orientation import OrientationParams
from imulog.steps.common import names_trial
from imulog.steps.kinematics_windows import PREFIX, calibration_record, kinematics_streams, resample_onto
from imulog.steps.windows import WindowParams, channel_rate_hz

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "kinematics"
ALGORITHM = "imulog.kinematics.caruso2024_dh"
META = "imulog.kinematics"
KINEMATICS_CORE_S = 1800.0  # per-sample solutions: half-hour windows (about 1 KB per sample while solved)


@dataclass(frozen=True)
class KinematicsOptions:
    """User overrides (``None``: take the value from the trial metadata, else the default)."""

    upper_arm: str | None = None
    forearm: str | None = None
    trunk: str | None = None  # "" disables a trunk IMU named in the metadata
    neutral_pose_deg: tuple[float, ...] | None = None
    neutral_window_s: tuple[float, float] | None = None
    calibration_mode: str = "heading"
    use_markers: bool = True
    solver: SolverParams = SolverParams()
    orientation: OrientationParams = OrientationParams()
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


def resolve_config(metadata: dict[str, dict[str, Any]], options: KinematicsOptions) -> tuple[KinematicsConfig, dict]:
    """Model, limits, boxes and calibration from metadata + options; also the JSON-able params record."""
    kin = metadata.get(META, {}) or {}
    model = ArmModel.from_metadata(metadata.get("imulog.anthropometrics", {}) or {})
    limits = JointLimits.from_metadata(kin)
    workspace = Workspace.from_metadata(kin)
    default = NeutralCalibration()
    pose = options.neutral_pose_deg or tuple(kin.get("neutral_pose_deg", default.pose_deg))
    window = options.neutral_window_s or tuple(kin.get("neutral_window_s", default.window_s))
    calib = NeutralCalibration(tuple(float(v) for v in pose), tuple(float(v) for v in window), options.calibration_mode)
    config = KinematicsConfig(model, limits, workspace, calib, options.solver)
    record = {
        "model": dataclasses.asdict(model),
        "joint_limits_deg": {n: list(getattr(limits, f"{n}_deg")) for n in JOINT_NAMES},
        "workspace_elbow_m": workspace.elbow.as_list() if workspace.elbow else None,
        "workspace_wrist_m": workspace.wrist.as_list() if workspace.wrist else None,
        "calibration": dataclasses.asdict(calib),
        "solver": dataclasses.asdict(options.solver),
    }
    return config, record


def imu_names(topics: list[str], metadata: dict, options: KinematicsOptions) -> tuple[str, str]:
    """(upper-arm IMU, forearm IMU): the options, else ``imulog.kinematics``, else the trial's sensor names and
    placements (:mod:`imulog.steps.placements`)."""
    from imulog.steps.placements import arm_imus, partner

    kin = metadata.get(META, {}) or {}
    ua = options.upper_arm or kin.get("upper_arm_imu")
    fa = options.forearm or kin.get("forearm_imu")
    have = [t.split("/", 2)[2] for t in topics if t.startswith("/imu/")]
    hint = f"; choose with --upper-arm/--forearm or set {META}.upper_arm_imu/forearm_imu"
    try:
        if ua is None and fa is None:
            ua, fa = arm_imus(have, metadata)
        elif ua is None:
            ua = partner("upper_arm", fa, have, metadata) if fa in have else "upper_arm"
        elif fa is None:
            fa = partner("forearm", ua, have, metadata) if ua in have else "forearm"
    except ValueError as exc:
        raise ValueError(f"{exc}{hint}") from None
    for role, name in (("upper-arm", ua), ("forearm", fa)):
        if name not in have:
            raise ValueError(
                f"no channel /imu/{name} for the {role} IMU (IMU channels: {', '.join(have) or 'none'}); "
                f"choose with --upper-arm/--forearm or set {META}.{role.replace('-', '_')}_imu"
            )
    if ua == fa:
        raise ValueError(f"the upper-arm and forearm IMUs must differ (both {ua!r})")
    return ua, fa


def trunk_name(topics: list[str], metadata: dict, options: KinematicsOptions) -> str | None:
    """The trunk IMU (``--trunk`` or ``imulog.kinematics.trunk_imu``), None for a still trunk."""
    name = options.trunk if options.trunk is not None else (metadata.get(META, {}) or {}).get("trunk_imu")
    if not name:
        return None
    if f"/imu/{name}" not in topics:
        have = [t.split("/", 2)[2] for t in topics if t.startswith("/imu/")]
        raise ValueError(f"no channel /imu/{name} for the trunk IMU (IMU channels: {', '.join(have) or 'none'})")
    return name


def _orientation(trial: Any, imu: str, params: OrientationParams) -> tuple[np.ndarray, np.ndarray, str]:
    """(t_ns, q_s2g, topic read): the orientation step's output when present, else computed here."""
    from imulog.process.orientation import estimate_orientation
    from imulog.steps.common import mean_rate_hz
    from imulog.steps.orientation import read_imu_arrays

    topic = f"/derived/orientation/{imu}"
    if topic in trial.topics():
        s = trial.read(topic)
        cols = [s.columns.index(c) for c in ("qw", "qx", "qy", "qz")]
        return s.t_ns, s.values[:, cols], topic
    t, acc, gyr, mag = read_imu_arrays(trial, f"/imu/{imu}")
    res = estimate_orientation(gyr, acc, mean_rate_hz(t), mag, params, t_ns=t)
    return t, res.quat, f"/imu/{imu}"


def _cluster_orientations(trial: Any, kin: dict) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """Cluster-to-world quaternions per segment from the markers named in ``imulog.kinematics``."""
    from imulog.process.alignment import cluster_kinematics

    clusters = kin.get("clusters")
    name = kin.get("markers", "vicon")
    topic = f"/markers/{name}"
    if not clusters or topic not in trial.topics():
        return None
    ms = trial.read(topic)
    rate = float((len(ms.t_ns) - 1) / ((ms.t_ns[-1] - ms.t_ns[0]) * 1e-9))
    out = {}
    for seg in ("upper_arm", "forearm", "trunk"):
        if seg == "trunk" and not clusters.get(seg):
            continue
        labels = clusters.get(seg)
        if not labels or any(lab not in ms.labels for lab in labels):
            raise ValueError(
                f"{META}.clusters.{seg} names markers {labels} not all in {topic} ({', '.join(ms.labels)})"
            )
        pos = ms.pos[:, [ms.labels.index(lab) for lab in labels]]
        ck = cluster_kinematics(ms.t_ns, ["O", "X", "Y"], pos, rate)
        out[seg] = ck.quat_c2w
    return ms.t_ns, out


def _reference_times(trial: Any, imu_topic: str, t_dev: np.ndarray) -> np.ndarray:
    """IMU sample times on the marker clock: via the IMU's alignment record (``imulog.alignment``, or
    ``imulog.alignment.{imu}`` in a setup aligned as a whole: :func:`imulog.steps.common.alignment_for`) when
    there is one for this IMU, else equal."""
    from imulog.steps.common import alignment_for

    al = alignment_for(trial.metadata, imu_topic)
    if al and al.get("imu") == imu_topic:
        from imulog.process.alignment import device_to_reference

        return np.asarray(device_to_reference(t_dev, al), dtype=np.int64)
    return t_dev


def _interp_angles(t_src: np.ndarray, q: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    out = np.full((len(t_dst), q.shape[1]), np.nan)
    ok = np.all(np.isfinite(q), axis=1)
    if ok.sum() < 2:
        return out
    ts, td = t_src[ok].astype(np.float64), np.asarray(t_dst, dtype=np.float64)
    for k in range(q.shape[1]):
        out[:, k] = np.interp(td, ts, np.unwrap(q[ok, k]), left=np.nan, right=np.nan)
    # NaN where the nearest source sample is far (a long marker gap)
    idx = np.clip(np.searchsorted(ts, td), 1, len(ts) - 1)
    gap = np.minimum(np.abs(td - ts[idx - 1]), np.abs(ts[idx] - td))
    period = np.median(np.diff(ts))
    out[gap > 1.5 * period] = np.nan
    return out


def compute_kinematics(
    trial: Any, ua: str, fa: str, options: KinematicsOptions, trunk: str | None = None
) -> tuple[list, dict]:
    """Core of the step on an open trial: (streams, metadata records)."""
    metadata = trial.metadata
    config, record = resolve_config(metadata, options)
    t_ua, q_ua, _ = _orientation(trial, ua, options.orientation)
    t_fa, q_fa, _ = _orientation(trial, fa, options.orientation)
    q_fa = resample_onto(t_fa, q_fa, t_ua)
    q_tr = None
    if trunk is not None:
        t_tr, q_tr, _ = _orientation(trial, trunk, options.orientation)
        q_tr = resample_onto(t_tr, q_tr, t_ua)
    est = estimate_kinematics(q_ua, q_fa, t_ua, config, q_trunk_s2g=q_tr)
    meta: dict[str, dict[str, Any]] = {
        "imulog.kinematics_calibration": calibration_record(ua, fa, trunk, config, est.q_global_to_trunk)
    }
    q_ref = None
    kin = metadata.get(META, {}) or {}
    clusters = _cluster_orientations(trial, kin) if options.use_markers else None
    if clusters is not None:
        t_m, qc = clusters
        ref = estimate_kinematics(
            qc["upper_arm"], qc["forearm"], t_m, config, constrained=False, q_trunk_s2g=qc.get("trunk")
        )
        q_ref = _interp_angles(t_m, ref.unconstrained.q_rad, _reference_times(trial, f"/imu/{ua}", t_ua))
        errors = kinematics_errors(est.unconstrained.q_rad, est.constrained.q_rad, q_ref, est.t_out)
        errors["reference"] = f"/markers/{kin.get('markers', 'vicon')} clusters, same solver (unconstrained)"
        meta["imulog.kinematics_errors"] = errors
    active = est.constrained.any_active
    meta["imulog.kinematics_calibration"].update(
        {
            "ms_per_sample": {k: float(v) for k, v in est.timing_ms_per_sample.items()},
            "constraint_active_fraction": float(np.mean(active)),
            "infeasible_samples": est.constrained.extra.get("n_infeasible", 0),
            "t_out_fraction": float(np.mean(est.t_out)),
            "config": record,
        }
    )
    return kinematics_streams(est, q_ref), meta


@names_trial
def run_kinematics(
    path: str | os.PathLike[str],
    *,
    options: KinematicsOptions = KinematicsOptions(),
    force: bool = False,
    windows: WindowParams | None = None,
) -> StepOutcome:
    """Run the step on a trial file; returns the :func:`imulog.steps.base.run_step` outcome.

    A recording longer than one window (``windows``, default half-hour cores) is solved window by window while
    the result is written (:func:`~imulog.steps.kinematics_windows.kinematics_pieces`: the same angles per sample, bounded memory); it reads the
    orientation step's channels of its IMUs, or computes them core by core as that step would when absent."""
    from imulog.archive import TrialReader
    from imulog.steps.base import StepResult, run_step
    from imulog.steps.common import alignment_record

    with TrialReader(path) as trial:
        topics = trial.topics()
        metadata = trial.metadata
        ua, fa = imu_names(topics, metadata, options)
        alignment_name = alignment_record(metadata, f"/imu/{ua}")  # what the reference angles' clock reads
        trunk = trunk_name(topics, metadata, options)
        config, config_record = resolve_config(metadata, options)
        inputs = []
        for imu in (ua, fa) if trunk is None else (ua, fa, trunk):
            o = f"/derived/orientation/{imu}"
            inputs.append(o if o in topics else f"/imu/{imu}")
        kin = metadata.get(META, {}) or {}
        marker_topic = f"/markers/{kin.get('markers', 'vicon')}"
        if options.use_markers and kin.get("clusters") and marker_topic in topics:
            inputs.append(marker_topic)

    windows = windows or WindowParams(core_s=KINEMATICS_CORE_S, margin_s=0.0)
    ua_topic = f"/derived/orientation/{ua}" if f"/derived/orientation/{ua}" in topics else f"/imu/{ua}"
    with TrialReader(path) as trial:
        ch = trial.channel(ua_topic)
        total = int(ch.sample_count or 0)
        plan = windows.plan(total, channel_rate_hz(total, ch.start_ns, ch.end_ns, ch.rate_hz))

    def compute(trial) -> StepResult:
        if len(plan) > 1:
            from imulog.archive.streaming import StreamPieces
            from imulog.steps.kinematics_windows import kinematics_pieces

            record: dict[str, Any] = {}
            pieces = StreamPieces(
                topics=[
                    f"{PREFIX}/{k}"
                    for k in (
                        "joint_angles_unconstrained",
                        "joint_angles_constrained",
                        "elbow",
                        "wrist",
                        "constraint_active",
                    )
                ],
                pieces=lambda: kinematics_pieces(
                    path, ua, fa, trunk, options.orientation, plan, record, config, config_record
                ),
                expected_duration_s=((ch.end_ns or 0) - (ch.start_ns or 0)) * 1e-9,
            )
            return StepResult(streams=[pieces], metadata={"imulog.kinematics_calibration": record})
        streams, meta = compute_kinematics(trial, ua, fa, options, trunk)
        return StepResult(streams=streams, metadata=meta)

    params = {
        "upper_arm": ua,
        "forearm": fa,
        "trunk": trunk,
        "use_markers": options.use_markers,
        "orientation": dataclasses.asdict(options.orientation),
        **config_record,
    }
    if len(plan) > 1:  # a trial within one core does not depend on the window sizes
        params["windows"] = windows.to_dict()
    return run_step(
        path,
        step=STEP,
        algorithm=ALGORITHM,
        params=params,
        inputs=inputs,
        metadata_inputs=(alignment_name, "imulog.anthropometrics", META),
        compute=compute,
        force=force,
    )
