"""Reprocessing step ``metrics``: clinical metrics of one IMU appended to the trial.

Reads ``/imu/{imu}`` (accelerometer, device clock) and, when present, ``/derived/phases/{imu}`` (R2G / NHPT
intervals) and ``/derived/trajectory/{method}`` (positions on the reference clock). Writes

* ``/derived/metrics/activity/{imu}``: Intervals labelled ``activity``, ``task_index`` = activity number (1-based),
  the activities of Doshi's method 2 on the IMU device clock;
* ``/derived/metrics/distance/{imu}``: SignalStream ``distance_cm``, the distance traversed since the start of each
  window (Doshi ch. 5), one row per IMU sample, for plots;
* metadata ``imulog.metrics``: flat keys with JSON scalar (or list) values, see :func:`compute_metrics` and
  ``docs/metrics.md``.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.model import ImuStream, Intervals, PoseStream, SignalStream
from imulog.params import check_params
from imulog.process.gaps import GapParams
from imulog.process.metrics import (
    ActivityCountParams,
    DistanceHistogramParams,
    NhptParams,
    nhpt_timings,
    phase_summary,
    repetition_durations,
    smoothness,
)
from imulog.steps.common import alignment_for, alignment_record, names_trial, nominal_rate_hz, pick_imu, record_for
from imulog.steps.metrics_windows import metric_pieces, metric_plan
from imulog.steps.windows import WindowParams, channel_rate_hz

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "metrics"
ALGORITHM = "imulog.metrics.doshi2011"
RECORD = "imulog.metrics"


@dataclass(frozen=True)
class MetricsParams:
    """All parameters of the step, with the published defaults (units in the names).

    noise_level_g: arm-usage threshold on sample-to-sample change (Doshi 2011: 0.022 g).
    noise_floor_g: activity method 2 noise floor on the high-passed signal (Doshi 2011 App. A.2: 0.09 g).
    m_s: moving-average half width in s (Doshi: m = 5 samples at 10 Hz = 0.5 s).
    dead_s: dead period in s that separates activities (Doshi: 10 samples at 10 Hz = 1.0 s).
    min_activity_s: drop shorter activities (imulog addition; 0 = keep all, as published).
    window_s: distance-histogram window (Doshi: 5 s); max_distance_cm, weight_start_cm: 120 cm and 60 cm.
    acc_unit: "g" reproduces Doshi App. A.3 distances, "m/s^2" integrates in SI units.
    trajectory: method name under /derived/trajectory/ for smoothness ("" = the most accurate one present:
        optimized, zupt_bias, zupt, kalman, ...; else the Vicon cluster pose; "vicon" = the Vicon cluster pose).
    nhpt_pickup_movement, nhpt_place_movement: labels of the NHPT movements ending at a peg pick-up and at its
        insertion (simulator protocol ``nhpt``).
    arm_usage_rate_hz: the rate at which ``noise_level_g`` applies (Doshi: 10 Hz); faster recordings are averaged
        to it first, so arm usage does not depend on the sampling rate (docs/metrics.md).
    """

    noise_level_g: float = 0.022
    noise_floor_g: float = 0.09
    m_s: float = 0.5
    dead_s: float = 1.0
    min_activity_s: float = 0.0
    window_s: float = 5.0
    max_distance_cm: float = 120.0
    weight_start_cm: float = 60.0
    acc_unit: str = "g"
    trajectory: str = ""
    nhpt_pickup_movement: str = "to_container"
    nhpt_place_movement: str = "place"
    arm_usage_rate_hz: float = 10.0

    def __post_init__(self) -> None:  # ParamError names the field and its unit; the CLI prints the same line
        check_params(
            self,
            positive=("window_s", "max_distance_cm", "arm_usage_rate_hz"),
            non_negative=("noise_level_g", "noise_floor_g", "m_s", "dead_s", "min_activity_s", "weight_start_cm"),
            choices={"acc_unit": ("g", "m/s^2")},
        )

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def activity(self, rate_hz: float) -> ActivityCountParams:
        return ActivityCountParams.for_rate(
            rate_hz,
            m_s=self.m_s,
            dead_s=self.dead_s,
            noise_floor_g=self.noise_floor_g,
            min_activity_s=self.min_activity_s,
        )

    def distance(self) -> DistanceHistogramParams:
        return DistanceHistogramParams(
            window_s=self.window_s,
            m_s=self.m_s,
            max_distance_cm=self.max_distance_cm,
            weight_start_cm=self.weight_start_cm,
            acc_unit=self.acc_unit,  # type: ignore[arg-type]
        )


VICON_POSE = "/derived/vicon/cluster_pose"


# default smoothness source: IMU trajectory methods from the most to the least accurate on simulated R2G
# (docs/trajectory.md); ddi, highpass and wavelet drift by decimetres and would make jerk meaningless
TRAJECTORY_PREFERENCE = ("optimized", "zupt_bias", "zupt", "kalman", "wavelet", "highpass", "ddi")


def pick_trajectory(
    topics: list[str], method: str, imu: str | None = None, metadata: Mapping[str, Any] | None = None
) -> str | None:
    """Positions for smoothness: ``/derived/trajectory/{method}`` (``method`` "" = the most accurate present,
    in :data:`TRAJECTORY_PREFERENCE` order; "vicon" = the optical ``/derived/vicon/cluster_pose``), else the
    Vicon cluster pose if present, else None. With ``imu`` (and ``metadata``), that IMU's trajectories in a
    trial with one set per IMU (``/derived/trajectory/{method}/{imu}``, :mod:`imulog.steps.trajectory_topics`)
    and its own cluster pose (``/derived/vicon/cluster_pose/{imu}``) when the setup was aligned as a whole."""
    from imulog.steps.trajectory_topics import trajectories_by_imu

    vicon = VICON_POSE
    if imu is not None and f"{VICON_POSE}/{imu}" in topics:
        vicon = f"{VICON_POSE}/{imu}"
    by_imu = trajectories_by_imu(topics, metadata or {})
    if imu is not None and imu in by_imu:
        mine = by_imu[imu]
    elif imu is not None and any(k for k in by_imu):  # per-IMU or attributed trajectories, none of this IMU
        mine = {}
    else:
        mine = {t.removeprefix("/derived/trajectory/"): t for t in topics if t.startswith("/derived/trajectory/")}
    found = sorted(mine.values())
    if method == "vicon":
        if vicon not in topics:
            raise ValueError(f"no channel {vicon} in the trial")
        return vicon
    if method:
        if method not in mine:
            per_imu = any(t.count("/") > 3 for t in topics if t.startswith("/derived/trajectory/"))
            topic = f"/derived/trajectory/{method}" + (f"/{imu}" if imu and per_imu else "")
            raise ValueError(f"no channel {topic} in the trial (trajectories: {', '.join(found) or 'none'})")
        return mine[method]
    if mine:  # the most accurate method present (docs/trajectory.md), never plain double integration first
        rank = {m: i for i, m in enumerate(TRAJECTORY_PREFERENCE)}
        return mine[min(mine, key=lambda m: (rank.get(m, len(rank)), m))]
    return vicon if vicon in topics else None


def _r(x: float, digits: int = 6) -> float:
    return float(round(float(x), digits))


def _positions(trajectory: SignalStream | PoseStream) -> np.ndarray:
    if isinstance(trajectory, PoseStream):
        return trajectory.position
    return trajectory.values[:, :3]


def _smoothness_per_phase(trajectory: SignalStream | PoseStream, phases: Intervals) -> dict[str, Any]:
    """Mean smoothness indicators per phase label over the phases that lie inside the trajectory."""
    t = trajectory.t_ns
    pos = _positions(trajectory)
    rate = nominal_rate_hz(t)
    vel = np.gradient(pos, 1.0 / rate, axis=0, edge_order=2)
    per_label: dict[str, list] = {}
    for start, end, label in zip(phases.start_ns, phases.end_ns, phases.labels, strict=True):
        i0, i1 = np.searchsorted(t, [start, end])
        if i1 - i0 < 8 or not np.isfinite(vel[i0:i1]).all():
            continue
        try:
            per_label.setdefault(label, []).append(smoothness(vel[i0:i1], rate))
        except ValueError:
            continue
    out: dict[str, Any] = {}
    for label, items in per_label.items():
        out[f"smoothness.{label}.n"] = len(items)
        for name in ("velocity_peaks", "normalized_jerk", "ldlj", "sparc", "peak_speed_m_s", "path_length_m"):
            out[f"smoothness.{label}.{name}_mean"] = _r(np.mean([getattr(s, name) for s in items]))
    return out


def compute_metrics(
    imu: ImuStream,
    params: MetricsParams | None = None,
    *,
    phases: Intervals | None = None,
    trajectory: SignalStream | PoseStream | None = None,
    start_time: str | None = None,
    gaps: GapParams | None = None,
) -> tuple[list, dict[str, Any]]:
    """Pure part of the step: derived streams and the ``imulog.metrics`` record from in-memory streams.

    Recordings longer than an hour also get ``by_hour`` (and longer than a day ``by_day``) summaries, aligned to
    the wall clock when ``start_time`` (the trial's ``imulog.trial.start_time``) is known.

    Missing samples (NaN) follow :mod:`imulog.process.gaps`: short gaps are bridged; in longer ones there is no
    arm use or activity, the distance is NaN and left out of the histogram, and percentages are of the recorded
    samples; ``gaps.*`` keys in the record say what was done.
    """
    p = params or MetricsParams()
    if imu.acc is None:
        raise ValueError(f"/imu/{imu.name} has no accelerometer columns")
    if len(imu) < 3:
        raise ValueError(f"/imu/{imu.name} has only {len(imu)} samples")
    record: dict[str, Any] = {}
    pieces = metric_pieces(
        lambda: iter([(imu.t_ns, imu.acc)]), len(imu), imu.topic, imu.name, p, record, start_time=start_time, gaps=gaps
    )
    activity, distance = whole_streams(pieces)
    return [activity, distance], phase_records(record, p, phases, trajectory)


def whole_streams(pieces) -> tuple[Intervals, SignalStream]:
    """The activity intervals and the distance channel from :func:`metric_pieces` (distance pieces joined)."""
    parts = list(pieces)
    activity = parts[-1]
    d = parts[:-1]
    distance = SignalStream(
        d[0].topic,
        np.concatenate([s.t_ns for s in d]),
        d[0].columns,
        d[0].units,
        np.concatenate([s.values for s in d]),
        frame_id=d[0].frame_id,
        attrs=dict(d[0].attrs),
    )
    return activity, distance


def phase_records(
    record: dict[str, Any],
    p: MetricsParams,
    phases: Intervals | None,
    trajectory: SignalStream | PoseStream | None,
) -> dict[str, Any]:
    """``record`` with the per-phase keys (timings, NHPT, smoothness) added, when there are phases."""
    if phases is not None and len(phases):
        for label, stats in phase_summary(phases).items():
            for key, value in stats.items():
                record[f"timings.{label}.{key}"] = value if key == "n" else _r(value)
        reps = repetition_durations(phases)
        if reps:
            values = np.array(list(reps.values()))
            record["timings.repetition.n"] = len(values)
            record["timings.repetition.mean_s"] = _r(values.mean())
            record["timings.repetition.std_s"] = _r(values.std())
        labels = set(phases.labels)
        if p.nhpt_pickup_movement in labels and p.nhpt_place_movement in labels:
            nhpt_params = NhptParams(pickup_movement=p.nhpt_pickup_movement, place_movement=p.nhpt_place_movement)
            nhpt = nhpt_timings(phases, nhpt_params).as_dict()
            for key, value in nhpt.items():
                record[f"nhpt.{key}"] = [_r(v) for v in value] if isinstance(value, list) else value
        if trajectory is not None:
            record["smoothness.source"] = trajectory.topic
            record.update(_smoothness_per_phase(trajectory, phases))
    return record


@names_trial
def run_metrics(
    path: str | os.PathLike[str],
    *,
    imu: str | None = None,
    params: MetricsParams | None = None,
    force: bool = False,
    windows: WindowParams | None = None,
) -> StepOutcome:
    """Clinical metrics of one IMU (``imulog process metrics``): appends ``/derived/metrics/activity/IMU`` (active
    intervals), ``/derived/metrics/distance/IMU`` (cm) and the ``imulog.metrics`` record (arm use %, activity
    counts, smoothness). Returns the :class:`~imulog.steps.base.StepOutcome`; :class:`~imulog.steps.common.StepError`
    names ``path``.

    One implementation at any length (:mod:`imulog.steps.metrics_windows`): ``windows`` (default an hour with
    10 s margins) cuts the accelerometer into cores. A recording within one core is computed at once with its
    per-phase metrics; a longer one (daily life) is written core by core and leaves the per-phase metrics out
    (its phases are daily-life movements, summarised by ``imulog.timing``).
    """
    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step

    p = params or MetricsParams()
    windows = windows or WindowParams(core_s=3600.0, margin_s=10.0)
    imu_topic_of = "/imu/{}".format
    with TrialReader(path) as trial:
        topics = trial.topics()
        name = pick_imu(topics, imu)
        record_name = record_for(RECORD, name, topics, trial.metadata)
        alignment_name = alignment_record(trial.metadata, imu_topic_of(name))  # this IMU's, in a setup
        traj_topic = pick_trajectory(topics, p.trajectory, name, trial.metadata)
        info = trial.channel(imu_topic_of(name))
        total = info.sample_count
        rate = channel_rate_hz(total, info.start_ns, info.end_ns, info.rate_hz)
    imu_topic = imu_topic_of(name)
    phase_topic = f"/derived/phases/{name}"
    inputs = [imu_topic] + [t for t in (phase_topic, traj_topic) if t is not None and t in topics]
    long = len(metric_plan(total, rate, p, windows)) > 1
    step_params = {"imu": name, **p.to_dict()}
    if long:  # the result depends on the windows only then; a week's phases must not make it whole
        step_params["windows"] = windows.to_dict()
        inputs = [imu_topic]

    def compute(trial) -> StepResult:
        start_time = (trial.metadata.get("imulog.trial") or {}).get("start_time")
        start = str(start_time) if start_time else None
        record: dict[str, Any] = {}

        def pieces():
            with TrialReader(path) as source:

                def blocks():
                    return ((b.t_ns, _acc_of(b, imu_topic)) for b in source.iter_blocks(imu_topic))

                yield from metric_pieces(blocks, total, imu_topic, name, p, record, start_time=start, windows=windows)

        if long:  # daily life over days: core by core while the result is written; the record fills at the end
            topics_out = [f"/derived/metrics/distance/{name}", f"/derived/metrics/activity/{name}"]
            return StepResult(streams=[StreamPieces(topics=topics_out, pieces=pieces)], metadata={record_name: record})
        activity, distance = whole_streams(pieces())
        phases = trial.read(phase_topic) if phase_topic in topics else None
        trajectory = trial.read(traj_topic) if traj_topic is not None else None
        if trajectory is not None and phases is not None and alignment_for(trial.metadata, imu_topic) is None:
            trajectory = None  # phases on the device clock cannot be matched to a reference-clock trajectory
        record = phase_records(record, p, phases, trajectory)
        gaps_done = {k[5:]: v for k, v in record.items() if k.startswith("gaps.")}
        provenance = {"gaps": gaps_done} if gaps_done else {}
        return StepResult(streams=[activity, distance], metadata={record_name: record}, provenance=provenance)

    return run_step(
        path,
        step=f"{STEP}:{name}",
        algorithm=ALGORITHM,
        params=step_params,
        inputs=inputs,
        metadata_inputs=(alignment_name, "imulog.trial"),
        compute=compute,
        force=force,
    )


def _acc_of(block: ImuStream, topic: str) -> np.ndarray:
    if block.acc is None:
        raise ValueError(f"{topic} has no accelerometer columns")
    return block.acc
