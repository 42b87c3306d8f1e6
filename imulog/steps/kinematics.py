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
from dataclasses import dataclass
from typing import Any

import numpy as np

from imulog.model import PoseStream, SignalStream
from imulog.process import quaternion as quat
from imulog.process.kinematics.calibration import NeutralCalibration
from imulog.process.kinematics.dh import JOINT_NAMES, ArmModel, JointLimits
from imulog.process.kinematics.errors import kinematics_errors
from imulog.process.kinematics.pipeline import KinematicsConfig, KinematicsEstimate, estimate_kinematics
from imulog.process.kinematics.solver import SolverParams, Workspace
from imulog.process.orientation import OrientationParams
from imulog.steps.windows import WindowParams, channel_rate_hz

STEP = "kinematics"
ALGORITHM = "imulog.kinematics.caruso2024_dh"
PREFIX = "/derived/kinematics"
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


def _resample(t_src: np.ndarray, q: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    if len(t_src) == len(t_dst) and np.array_equal(t_src, t_dst):
        return q
    from imulog.process.resample import ResampleParams, resample_quaternions

    return resample_quaternions(t_src, q, t_dst, ResampleParams(cutoff_ratio=0.0))


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


def _streams(est: KinematicsEstimate, q_ref: np.ndarray | None) -> list:
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


def compute_kinematics(
    trial: Any, ua: str, fa: str, options: KinematicsOptions, trunk: str | None = None
) -> tuple[list, dict]:
    """Core of the step on an open trial: (streams, metadata records)."""
    metadata = trial.metadata
    config, record = resolve_config(metadata, options)
    t_ua, q_ua, _ = _orientation(trial, ua, options.orientation)
    t_fa, q_fa, _ = _orientation(trial, fa, options.orientation)
    q_fa = _resample(t_fa, q_fa, t_ua)
    q_tr = None
    if trunk is not None:
        t_tr, q_tr, _ = _orientation(trial, trunk, options.orientation)
        q_tr = _resample(t_tr, q_tr, t_ua)
    est = estimate_kinematics(q_ua, q_fa, t_ua, config, q_trunk_s2g=q_tr)
    meta: dict[str, dict[str, Any]] = {
        "imulog.kinematics_calibration": {
            "upper_arm_imu": ua,
            "forearm_imu": fa,
            "trunk_imu": trunk,
            "mode": config.calibration.mode,
            "neutral_pose_deg": list(config.calibration.pose_deg),
            "neutral_window_s": list(config.calibration.window_s),
            "q_global_to_trunk": {k: [float(x) for x in v] for k, v in est.q_global_to_trunk.items()},
        }
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
    return _streams(est, q_ref), meta


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


def _last_finite(q: np.ndarray) -> np.ndarray | None:
    ok = np.flatnonzero(np.all(np.isfinite(q), axis=1))
    return None if len(ok) == 0 else q[ok[-1]].copy()


def kinematics_pieces(path, ua: str, fa: str, trunk: str | None, options: KinematicsOptions, plan, record: dict):
    """The step window by window (``plan``: :class:`~imulog.steps.windows.Window` s over the upper-arm IMU's
    orientation samples): the neutral-posture calibration from the first window, every later window warm-started
    from the previous one's last solution, so each sample's angles are the whole computation's. Yields the
    streams of each window; fills ``record`` (``imulog.kinematics_calibration``) at the end."""
    from imulog.archive import TrialReader
    from imulog.heap import bound_heap
    from imulog.process.kinematics.pipeline import calibrate_kinematics
    from imulog.steps.sample_window import SampleWindow

    bound_heap()  # the same temporaries window after window: keep them out of the heap (imulog.heap)
    margin_ns = 1_000_000_000  # forearm/trunk samples this far beyond the window, for the resampling
    sums = {"n": 0, "active": 0.0, "t_out": 0.0, "infeasible": 0, "ms": {}}
    with TrialReader(path) as trial:
        config, cfg_record = resolve_config(trial.metadata, options)
        total = plan[-1].hi
        ua_buf = SampleWindow(_quaternion_blocks(trial, f"/derived/orientation/{ua}"), total)
        others = {
            k: _TimeCursor(_quaternion_blocks(trial, f"/derived/orientation/{n}"))
            for k, n in (("fa", fa), ("tr", trunk))
            if n
        }
        calibrated, warm = None, {}
        for w in plan:
            t, q_ua = ua_buf.take(w.lo, w.hi)
            t_fa, q_fa = others["fa"].get(int(t[0]) - margin_ns, int(t[-1]) + margin_ns)
            q_fa = _resample(t_fa, q_fa, t)
            q_tr = None
            if "tr" in others:
                t_tr, q_tr = others["tr"].get(int(t[0]) - margin_ns, int(t[-1]) + margin_ns)
                q_tr = _resample(t_tr, q_tr, t)
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
            yield from _streams(est, None)
    n = max(sums["n"], 1)
    record.update(
        {
            "upper_arm_imu": ua,
            "forearm_imu": fa,
            "trunk_imu": trunk,
            "mode": config.calibration.mode,
            "neutral_pose_deg": list(config.calibration.pose_deg),
            "neutral_window_s": list(config.calibration.window_s),
            "q_global_to_trunk": {k: [float(x) for x in v] for k, v in calibrated[0].items()},
            "ms_per_sample": {k: v / n for k, v in sums["ms"].items()},
            "constraint_active_fraction": sums["active"] / n,
            "infeasible_samples": sums["infeasible"],
            "t_out_fraction": sums["t_out"] / n,
            "config": cfg_record,
            "windows": len(plan),
            "reference": "marker reference angles are computed for recordings of one window (lab trials)",
        }
    )


def run_kinematics(
    path, *, options: KinematicsOptions = KinematicsOptions(), force: bool = False, windows: WindowParams | None = None
):
    """Run the step on a trial file; returns the :func:`imulog.steps.base.run_step` outcome.

    A recording longer than one window (``windows``, default half-hour cores) is solved window by window while
    the result is written (:func:`kinematics_pieces`: the same angles per sample, bounded memory); it needs the
    orientation step's channels of its IMUs."""
    from imulog.archive import TrialReader
    from imulog.steps.base import StepResult, run_step
    from imulog.steps.common import alignment_record

    with TrialReader(path) as trial:
        topics = trial.topics()
        metadata = trial.metadata
        ua, fa = imu_names(topics, metadata, options)
        alignment_name = alignment_record(metadata, f"/imu/{ua}")  # what the reference angles' clock reads
        trunk = trunk_name(topics, metadata, options)
        _, record = resolve_config(metadata, options)
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
    if len(plan) > 1:
        missing = [i for i in (ua, fa, trunk) if i and f"/derived/orientation/{i}" not in topics]
        if missing:
            raise ValueError(
                f"/imu/{ua} spans {len(plan)} windows: kinematics reads the orientation step's channels window by "
                f"window; run `imulog process orientation --imu {missing[0]}` first"
            )

    def compute(trial) -> StepResult:
        if len(plan) > 1:
            from imulog.archive.streaming import StreamPieces

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
                pieces=lambda: kinematics_pieces(path, ua, fa, trunk, options, plan, record),
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
        **record,
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
