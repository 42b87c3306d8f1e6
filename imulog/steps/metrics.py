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
from dataclasses import dataclass
from typing import Any

import numpy as np

from imulog.model import ImuStream, Intervals, PoseStream, SignalStream
from imulog.process.gaps import GapParams, prepare
from imulog.process.metrics import (
    ActivityCountParams,
    ArmUsageParams,
    DistanceHistogramParams,
    NhptParams,
    acc_to_g,
    activity_count_dead_period,
    activity_count_sign,
    arm_usage,
    distance_histogram,
    nhpt_timings,
    phase_summary,
    repetition_durations,
    smoothness,
    weighted_area,
)
from imulog.process.metrics.distance import histogram_percent
from imulog.process.metrics.periods import DAY_S, HOUR_S, period_summaries, wall_clock_origin_ns
from imulog.steps.common import alignment_for, nominal_rate_hz, pick_imu
from imulog.steps.long_metrics import LONG_SAMPLES, MetricCores, long_metrics_pieces

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


def pick_trajectory(topics: list[str], method: str) -> str | None:
    """Positions for smoothness: ``/derived/trajectory/{method}`` (``method`` "" = the most accurate present,
    in :data:`TRAJECTORY_PREFERENCE` order; "vicon" = the optical ``/derived/vicon/cluster_pose``), else the
    Vicon cluster pose if present, else None."""
    found = sorted(t for t in topics if t.startswith("/derived/trajectory/"))
    if method == "vicon":
        if VICON_POSE not in topics:
            raise ValueError(f"no channel {VICON_POSE} in the trial")
        return VICON_POSE
    if method:
        topic = f"/derived/trajectory/{method}"
        if topic not in found:
            raise ValueError(f"no channel {topic} in the trial (trajectories: {', '.join(found) or 'none'})")
        return topic
    if found:  # the most accurate method present (docs/trajectory.md), never plain double integration first
        rank = {f"/derived/trajectory/{m}": i for i, m in enumerate(TRAJECTORY_PREFERENCE)}
        return min(found, key=lambda t: (rank.get(t, len(rank)), t))
    return VICON_POSE if VICON_POSE in topics else None


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


def _period_records(t_ns, acc_g, usage, m2, dist, p: MetricsParams, start_time: str | None) -> dict[str, Any]:
    """``by_hour`` / ``by_day`` lists (see :mod:`imulog.process.metrics.periods`) for recordings long enough."""
    span_s = (int(t_ns[-1]) - int(t_ns[0])) / 1e9
    out: dict[str, Any] = {}
    for key, period_s in (("by_hour", HOUR_S), ("by_day", DAY_S)):
        if span_s <= period_s:
            continue
        origin_ns, origin_time = wall_clock_origin_ns(int(t_ns[0]), start_time, period_s)
        rows = period_summaries(
            t_ns,
            np.isfinite(acc_g).all(axis=1),
            usage.active_any,
            m2.intervals[:, 0] if len(m2.intervals) else np.zeros(0, np.int64),
            dist.distance_cm,
            dist.bin_centres_cm,
            period_s=period_s,
            origin_ns=origin_ns,
            origin_time=origin_time,
            weight_start_cm=p.weight_start_cm,
        )
        out[key] = [r.to_dict() for r in rows]
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
    rate = nominal_rate_hz(imu.t_ns)
    (acc_g,), gap_report = prepare([acc_to_g(imu.acc)], gaps)
    unknown = ~np.isfinite(acc_g).all(axis=1)
    usage = arm_usage(acc_g, ArmUsageParams(p.noise_level_g, p.arm_usage_rate_hz), t_ns=imu.t_ns)
    m1 = activity_count_sign(acc_g)
    m2 = activity_count_dead_period(acc_g, p.activity(rate))
    dist = distance_histogram(acc_g, rate, p.distance())
    if unknown.any():  # the distance is unknown inside long gaps: NaN there and not in the histogram
        d_cm = np.where(unknown, np.nan, dist.distance_cm)
        hist = histogram_percent(d_cm, p.distance())
        dist = dataclasses.replace(
            dist,
            distance_cm=d_cm,
            histogram_percent=hist,
            weighted_area=weighted_area(hist, dist.bin_centres_cm, p.weight_start_cm),
        )
    last = len(imu) - 1
    iv = m2.intervals
    activity = Intervals(
        topic=f"/derived/metrics/activity/{imu.name}",
        start_ns=imu.t_ns[iv[:, 0]] if len(iv) else np.zeros(0, np.int64),
        end_ns=imu.t_ns[np.minimum(iv[:, 1], last)] if len(iv) else np.zeros(0, np.int64),
        labels=["activity"] * len(iv),
        task_index=np.arange(1, len(iv) + 1),
    )
    distance = SignalStream(
        topic=f"/derived/metrics/distance/{imu.name}",
        t_ns=imu.t_ns,
        columns=["distance_cm"],
        units=["cm" if p.acc_unit == "m/s^2" else "cm (Doshi A.3, integrated in g)"],
        values=dist.distance_cm[:, None],
        frame_id=imu.name,
    )
    durations = m2.durations_s(rate)
    record: dict[str, Any] = {
        "imu": imu.topic,
        "rate_hz": _r(rate, 4),
        "duration_s": _r((imu.t_ns[-1] - imu.t_ns[0]) / 1e9, 4),
        "arm_usage.noise_level_g": p.noise_level_g,
        "arm_usage.rate_hz": usage.rate_hz,
        "arm_usage.x_percent": _r(usage.per_axis_percent[0], 4),
        "arm_usage.y_percent": _r(usage.per_axis_percent[1], 4),
        "arm_usage.z_percent": _r(usage.per_axis_percent[2], 4),
        "arm_usage.overall_percent": _r(usage.overall_percent, 4),
        "activity.method1.count": m1.count,
        "activity.method1.per_axis": m1.per_axis.tolist(),
        "activity.method2.count": m2.count,
        "activity.method2.per_axis": m2.per_axis.tolist(),
        "activity.method2.m_samples": p.activity(rate).m_samples,
        "activity.method2.dead_samples": p.activity(rate).dead_samples,
        "activity.method2.noise_floor_g": p.noise_floor_g,
        "activity.method2.min_activity_samples": p.activity(rate).min_activity_samples,
        "activity.method2.total_s": _r(durations.sum(), 4),
        "activity.method2.mean_s": _r(durations.mean(), 4) if len(durations) else None,
        "distance.window_s": p.window_s,
        "distance.acc_unit": p.acc_unit,
        "distance.weighted_area": _r(dist.weighted_area, 4),
        "distance.weight_start_cm": p.weight_start_cm,
        "distance.bin_width_cm": p.distance().bin_width_cm,
        "distance.histogram_percent": [_r(v, 4) for v in dist.histogram_percent],
        "distance.window_median_cm": _r(np.median(dist.window_distance_cm), 4),
        "distance.window_max_cm": _r(np.max(dist.window_distance_cm), 4),
    }
    if gap_report.missing:  # flat keys, as every key of the record
        record.update({f"gaps.{k}": v for k, v in gap_report.as_dict().items()})
    record.update(_period_records(imu.t_ns, acc_g, usage, m2, dist, p, start_time))
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
    return [activity, distance], record


def run_metrics(
    path,
    *,
    imu: str | None = None,
    params: MetricsParams | None = None,
    force: bool = False,
    cores: MetricCores | None = None,
):
    """Run the step on a trial file; returns the :func:`imulog.steps.base.run_step` outcome.

    Recordings longer than :data:`~imulog.steps.long_metrics.LONG_SAMPLES` samples (daily life; per-phase metrics
    are left out, phases found core by core included), or any with ``cores``, are processed core by core in bounded
    memory (:mod:`imulog.steps.long_metrics`).
    """
    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step

    p = params or MetricsParams()
    with TrialReader(path) as trial:
        topics = trial.topics()
        name = pick_imu(topics, imu)
        traj_topic = pick_trajectory(topics, p.trajectory)
        total = trial.channel(f"/imu/{name}").sample_count
    imu_topic = f"/imu/{name}"
    phase_topic = f"/derived/phases/{name}"
    inputs = [imu_topic] + [t for t in (phase_topic, traj_topic) if t is not None and t in topics]
    long = cores is not None or total > LONG_SAMPLES  # with phases too: a week's phases must not make it whole
    step_params = {"imu": name, **p.to_dict()}
    if long:
        cores = cores or MetricCores()
        step_params["cores"] = cores.to_dict()
        inputs = [imu_topic]

    def compute(trial) -> StepResult:
        start_time = (trial.metadata.get("imulog.trial") or {}).get("start_time")
        if long:  # daily life over days: core by core while the result is written; the record fills at the end
            record: dict[str, Any] = {}
            pieces = StreamPieces(
                topics=[f"/derived/metrics/distance/{name}", f"/derived/metrics/activity/{name}"],
                pieces=lambda: long_metrics_pieces(
                    path, imu_topic, name, p, total, record, start_time=str(start_time) if start_time else None,
                    cores=cores,
                ),
            )
            return StepResult(streams=[pieces], metadata={RECORD: record})
        stream = trial.read(imu_topic)
        phases = trial.read(phase_topic) if phase_topic in topics else None
        trajectory = trial.read(traj_topic) if traj_topic is not None else None
        if trajectory is not None and phases is not None and alignment_for(trial.metadata, imu_topic) is None:
            trajectory = None  # phases on the device clock cannot be matched to a reference-clock trajectory
        streams, record = compute_metrics(
            stream, p, phases=phases, trajectory=trajectory, start_time=str(start_time) if start_time else None
        )
        gaps_done = {k[5:]: v for k, v in record.items() if k.startswith("gaps.")}
        provenance = {"gaps": gaps_done} if gaps_done else {}
        return StepResult(streams=streams, metadata={RECORD: record}, provenance=provenance)

    return run_step(
        path,
        step=STEP,
        algorithm=ALGORITHM,
        params=step_params,
        inputs=inputs,
        metadata_inputs=("imulog.alignment", "imulog.trial"),
        compute=compute,
        force=force,
    )
