"""Reprocessing step ``trajectory``: the wrist's path from one IMU, one derived channel per method.

Reads (``{imu}`` e.g. ``wrist``):

* ``/derived/acc_global/{imu}`` (orientation step): gravity-free acceleration in the IMU global frame,
  IMU device clock (required);
* ``/derived/static/{imu}`` (phases step): zero-velocity mask (required by every method but ``ddi``,
  ``highpass`` and ``wavelet``);
* ``/derived/phases/{imu}`` (phases step): R2G phases with ``task_index`` = repetition; without it the whole
  recording is one window and ``optimized`` is skipped;
* ``/derived/orientation/{imu}`` (orientation step, optional): enables ``zupt_bias`` and the rotating-bias
  compensation of the optimisation's initial estimate;
* metadata ``imulog.alignment`` (optional) for the reference clock and the global-to-world rotation, and
  ``imulog.anthropometrics`` (h1/h2/h3, for the optimisation's reference).

Writes ``/derived/trajectory/{method}`` (``x,y,z`` m; reference clock and ``world`` frame when the trial is
aligned, else IMU device clock and ``{imu}_global`` frame); in a trial with several IMUs one set per IMU,
``/derived/trajectory/{method}/{imu}``, with the IMU's own record (:mod:`imulog.steps.trajectory_topics`). Each repetition's samples are its displacement
from the repetition's first sample (a single IMU reconstructs displacement, not absolute position); only
samples inside repetition windows are written. Metadata ``imulog.trajectory`` records the windows, clock,
frame, estimated rotating bias and the waypoints used.
"""

from __future__ import annotations

import dataclasses
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.model import Intervals, SignalStream
from imulog.process.gaps import GapParams, prepare, runs_of
from imulog.process.minjerk import R2GReferenceParams, r2g_waypoints_from_anthropometrics
from imulog.process.repetition_flags import flagged_repetitions, repetition_features
from imulog.process.rests import rest_report, true_rests
from imulog.process.trajectory_checks import check_attrs
from imulog.process.trajectory_opt import (
    BASELINE,
    DEFAULT_PARAMS,
    DEFAULT_REFERENCE,
    METHODS,
    Repetition,
    TrajectoryParams,
    merge_overlapping,
    reconstruct_repetitions,
    repetition_windows,
)
from imulog.steps.common import alignment_for, alignment_record, names_trial, pick_imu, record_for, record_of
from imulog.steps.orientation import imu_arrays
from imulog.steps.placements import placement_side
from imulog.steps.trajectory_acc_rests import OrientationSource, acc_source, rest_calibrated
from imulog.steps.trajectory_inputs import phase_bounds_by_repetition, sample_onto, to_reference, world_acceleration
from imulog.steps.trajectory_topics import RECORD, baseline_topic, per_imu_layout, split_topic, trajectory_topic
from imulog.steps.trajectory_windows import F32, TrajectoryWindows, has_r2g, trajectory_pieces
from imulog.steps.trajectory_windows import plan as window_plan

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "trajectory"
TRAJECTORY_TOPIC = "/derived/trajectory/{method}"
BASELINE_TOPIC = "/derived/trajectory_baseline/{method}"  # what every method must beat (imulog evaluate)
NEEDS_STATIC = {"zupt", "kalman", "zupt_bias", "optimized"}


def compute_trajectories(
    acc_t_ns: np.ndarray,
    acc_global: np.ndarray,
    *,
    imu: str,
    methods: list[str] | tuple[str, ...] = METHODS,
    static: tuple[np.ndarray, np.ndarray] | None = None,
    phases: Intervals | None = None,
    phases_clock: str = "reference",
    orientation: tuple[np.ndarray, np.ndarray] | None = None,
    alignment: dict[str, Any] | None = None,
    anthropometrics: dict[str, Any] | None = None,
    params: TrajectoryParams = DEFAULT_PARAMS,
    reference_params: R2GReferenceParams = DEFAULT_REFERENCE,
    gaps: GapParams | None = None,
    gyr: tuple[np.ndarray, np.ndarray] | None = None,
    repetition_quality: list[dict[str, Any]] | None = None,
    per_imu: bool = False,
    chain_rest_s: float = TrajectoryWindows.chain_rest_s,
    side: tuple[str, str] | None = None,
    source: OrientationSource | None = None,
) -> tuple[list[SignalStream], dict[str, Any]]:
    """Pure part of the step: trajectory streams and the ``imulog.trajectory`` record (no I/O).

    ``repetition_quality``: the phases step's per-repetition records (``imulog.timing``); with them,
    ``imulog.trajectory["flagged_repetitions"]`` combines event correction's reasons with the trajectory's own
    (:mod:`imulog.process.repetition_flags`: drift, weak rest, poor alignment). ``per_imu``: the channels are
    ``/derived/trajectory/{method}/{imu}`` and carry their ``clock`` (a trial with several IMUs).

    Missing samples (NaN in ``acc_global``) follow :mod:`imulog.process.gaps`: short gaps are bridged linearly; a
    repetition that contains a longer gap is not reconstructed (its motion inside the gap is unknown, and
    integrating across it would be a guess), and without phases the recording is integrated per valid run.
    ``imulog.trajectory["gaps"]`` lists what was bridged and which repetitions were left out.

    ``static`` and ``orientation`` are ``(t_ns, values)`` on the IMU device clock; ``phases`` on the reference
    clock (``phases_clock="reference"``) or on the device clock (``"device"``). With the gyroscope ``gyr``
    (``(t_ns, (N, 3) rad/s)``, device clock) and the orientation, the orientation is re-integrated through every
    movement and anchored at its rests (:func:`imulog.process.integration.rest_anchored_orientation`,
    ``params.anchor``) and the gravity-free acceleration rotated accordingly (``imulog.trajectory["orientation"]``
    says which was used). ``chain_rest_s``: the heading chain of ``AnchorParams.heading="gyroscope"`` restarts at
    rests at least this long outside the repetitions, where the step's windows are cut
    (:class:`imulog.steps.trajectory_windows.TrajectoryWindows`), so windows equal the whole. ``side``: which
    wrist the placement metadata says (``(left|right, source)``, :func:`imulog.steps.placements.placement_side`), checked against the
    IMU's lateral direction of the drink with the anthropometrics (issue 31). ``source``: the orientation step's
    accelerometer and parameters, which ``params.acc_rests`` corrects from the rests and re-runs the filter on
    (:mod:`imulog.steps.trajectory_acc_rests`; ``imulog.trajectory["accelerometer"]`` says what it found).
    """
    t_dev = np.asarray(acc_t_ns, dtype=np.int64)
    acc = np.asarray(acc_global, dtype=np.float64)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ValueError(f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(METHODS)}")
    if static is None and any(m in NEEDS_STATIC for m in methods):
        need = ", ".join(m for m in methods if m in NEEDS_STATIC)
        raise ValueError(f"methods {need} need /derived/static/{imu}: run `imulog process phases` first")
    t_ref = to_reference(t_dev, alignment)
    q_world = None if orientation is None else sample_onto(orientation[0], np.asarray(orientation[1], float), t_dev)
    orientation_used = "filter" if q_world is not None else None
    rest_info: dict[str, Any] = {}
    given = None  # the phases step's static mask, before the accelerometer's check
    if static is not None:
        given = sample_onto(np.asarray(static[0], np.int64), np.asarray(static[1]).reshape(-1) > 0.5, t_dev)
    corrected = None  # the accelerometer from the trial's own rests, the filter re-run on it (issue 31 point 2)
    if params.acc_rests.enabled:
        t_cal = (t_ref - t_ref[0]) / 1e9  # s: the gyroscope integrated between rests on the reference clock
        corrected = rest_calibrated(t_dev, t_cal, given, q_world, source, imu=imu, params=params.acc_rests)
        acc, q_world = corrected.acc_global, corrected.quat
    if static is not None:  # velocity resets only at true rests: the accelerometer must agree (issue 32)
        rate = (len(t_dev) - 1) / max((t_dev[-1] - t_dev[0]) / 1e9, 1e-9)
        rest_mask = true_rests(given, acc, rate, params.rests, orientation=q_world)
        rest_info = rest_report(given, rest_mask, rate)
        static = (t_dev, rest_mask)
    t_ph = phases
    if phases is not None and len(phases) and phases_clock == "device" and alignment is not None:
        t_ph = Intervals(
            phases.topic,
            to_reference(phases.start_ns, alignment),
            to_reference(phases.end_ns, alignment),
            phases.labels,
            phases.task_index,
        )
    acc, q_world, anchored, frame, clock = world_acceleration(
        acc,
        q_world,
        imu=imu,
        t_dev=t_dev,
        t_ref=t_ref,
        rest=None if static is None else static[1],
        given_rest=given,
        gyr=gyr,
        phases=t_ph,
        alignment=alignment,
        params=params,
        chain_rest_s=chain_rest_s,
        acc_sensor=None if corrected is None else corrected.acc_sensor,
    )
    orientation_used = "rest_anchored" if anchored else orientation_used
    (acc,), gap_report = prepare([acc], gaps)
    unknown = ~np.all(np.isfinite(acc), axis=1)  # long gaps, after bridging the short ones
    if unknown.all():
        raise ValueError(f"/derived/acc_global/{imu}: no valid samples ({gap_report.missing} missing)")
    acc = np.where(unknown[:, None], 0.0, acc)  # never integrated: repetitions across long gaps are left out
    t_s = (t_ref - t_ref[0]) / 1e9
    mask = (
        np.zeros(len(t_dev), bool)
        if static is None
        else sample_onto(np.asarray(static[0], np.int64), np.asarray(static[1]).reshape(-1) > 0.5, t_dev)
    )
    reps: list[Repetition] = []
    if phases is not None and len(phases):
        reps = repetition_windows(t_s, phase_bounds_by_repetition(t_ph, int(t_ref[0])), mask)
    info: dict[str, Any] = {"rests": rest_info} if rest_info else {}
    reps, merged = merge_overlapping(reps)
    if merged:  # movements without a true rest between them are one window (one velocity reset each side)
        info["merged_repetitions"] = merged
    if not reps:  # no phases: the whole recording, or each valid run when long gaps split it
        runs = runs_of(~unknown) if unknown.any() else [(0, len(t_s))]
        reps = [Repetition(index=-1, start=a, stop=b, phase_bounds_s=np.zeros((0, 2))) for a, b in runs]
    if gap_report.missing:
        left_out = [r.index for r in reps if unknown[r.start : r.stop].any()]
        reps = [r for r in reps if not unknown[r.start : r.stop].any()]
        info["gaps"] = {**gap_report.as_dict(), "repetitions_left_out": left_out}
        if not reps:
            raise ValueError(
                f"/derived/acc_global/{imu}: every repetition contains a gap longer than "
                f"{gap_report.params.max_bridge_samples} samples"
            )
    if "optimized" in methods and not any(len(r.phase_bounds_s) == 4 for r in reps):
        # the optimisation models the four R2G phases: other tasks (slide, NHPT, ADL) get every other method
        why = f"no repetition with the 4 R2G phases in /derived/phases/{imu}"
        methods = [m for m in methods if m != "optimized"]
        if not methods:
            raise ValueError(f"method optimized needs R2G repetitions (reach, lift, return_bottle, return_hand): {why}")
        info["skipped"] = {"optimized": why}
    if "optimized" in methods:
        info["waypoints_from"] = "anthropometrics"
        try:
            r2g_waypoints_from_anthropometrics(anthropometrics or {}, reference_params)
        except KeyError as exc:  # the optimisation then measures every waypoint from the ZUPT estimate
            info["waypoints_from"] = "zupt"
            info["notes"] = [
                f"optimized: {exc.args[0] if anthropometrics else 'no imulog.anthropometrics record'}; "
                "waypoints measured from ZUPT (give h1_m, h2_m, h3_m with convert --meta anthropometrics.h1_m=...)"
            ]
    recon = reconstruct_repetitions(
        t_s,
        acc,
        mask,
        reps,
        list(methods),
        anthropometrics=anthropometrics,
        orientation=q_world,
        params=params,
        reference_params=reference_params,
        info=info,
        baseline=True,
        side=side,
        acc_calibration=None if corrected is None else corrected.calibration,
    )
    if any(len(r.phase_bounds_s) for r in reps):  # repetitions to judge (issue 31): what to distrust, and why
        features = repetition_features(t_s, acc, mask, reps, recon, repetition_quality or (), trajectory_info=info)
        quality = (alignment or {}).get("quality")
        info["flagged_repetitions"] = flagged_repetitions(features, alignment_quality=quality)
    streams, written = [], []
    checks = info.get("checks", {})
    owner = imu if per_imu else None
    for m, pos in recon.items():
        rows = np.all(np.isfinite(pos), axis=1)
        if not np.any(rows):
            continue
        check = checks.get(m, {})
        streams.append(
            SignalStream(
                topic=(baseline_topic if m == BASELINE else trajectory_topic)(m, owner),
                t_ns=t_ref[rows],
                columns=["x", "y", "z"],
                units=["m", "m", "m"],
                values=pos[rows],
                frame_id=frame,
                attrs={**check_attrs(check), **clock_attrs(imu, clock, per_imu), **F32},  # float32: docs/schemas.md
            )
        )
        written += [] if m == BASELINE else [m]
    record = {
        "imu": f"/imu/{imu}",
        "methods": written,
        "baseline": BASELINE,
        "clock": clock,
        "frame": frame,
        "origin": "repetition_start",
        **({"orientation": orientation_used} if orientation_used else {}),
        **({"accelerometer": corrected.record} if corrected is not None else {}),
        "repetitions": [
            {"index": r.index, "start_ns": int(t_ref[r.start]), "end_ns": int(t_ref[r.stop - 1])} for r in reps
        ],
        **info,
    }
    return streams, record


def clock_attrs(imu: str, clock: str, per_imu: bool) -> dict[str, str]:
    """Channel metadata ``clock`` of a per-IMU trajectory (``reference``, or the IMU topic when unaligned), so
    that the viewer and exports put it on the right clock without the trial-level record."""
    return {"clock": "reference" if clock == "reference" else f"/imu/{imu}"} if per_imu else {}


def params_dict(methods: list[str] | tuple[str, ...], params: TrajectoryParams, reference: R2GReferenceParams) -> dict:
    ref = dataclasses.asdict(reference)
    ref["keys"] = {k: list(v) for k, v in reference.keys.items()}
    return {"methods": list(methods), **dataclasses.asdict(params), "reference": ref}


@names_trial
def run_trajectory(
    path: str | os.PathLike[str],
    *,
    imu: str | None = None,
    methods: list[str] | tuple[str, ...] = METHODS,
    params: TrajectoryParams = DEFAULT_PARAMS,
    reference_params: R2GReferenceParams = DEFAULT_REFERENCE,
    force: bool = False,
    windows: TrajectoryWindows | None = None,
) -> StepOutcome:
    """Wrist trajectories by each of ``methods`` (``imulog process trajectory``): appends ``/derived/trajectory/
    METHOD`` (x, y, z in m, the reference's world frame, per repetition) and the ``imulog.trajectory`` record; needs
    the orientation and the phases. Returns the :class:`~imulog.steps.base.StepOutcome`;
    :class:`~imulog.steps.common.StepError` names ``path``.

    A recording longer than one window (``windows``, default one-hour cores) is reconstructed window by window,
    each window the movements between two rests (:mod:`imulog.steps.trajectory_windows`), in bounded memory."""
    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step
    from imulog.steps.windows import channel_rate_hz

    windows = windows or TrajectoryWindows()
    with TrialReader(path) as trial:
        topics = trial.topics()
        name = pick_imu(
            topics, imu, prefix="/derived/acc_global/", missing_hint="run `imulog process orientation` first"
        )
        acc_topic = f"/derived/acc_global/{name}"
        timing_record = record_of("imulog.timing", name, trial.metadata) or "imulog.timing"  # this IMU's phases
        per_imu = per_imu_layout(topics)  # several IMUs: one set of channels and one record each
        record_name = record_for(RECORD, name, topics, trial.metadata) if per_imu else RECORD
        alignment_name = alignment_record(trial.metadata, f"/imu/{name}")
        ch = trial.channel(acc_topic)
        orient = f"/derived/orientation/{name}"
        orient_meta = trial.channel(orient).metadata if params.acc_rests.enabled and orient in topics else None
        total = int(ch.sample_count or 0)
        rate = channel_rate_hz(total, ch.start_ns, ch.end_ns, ch.rate_hz)
    one_window = total <= max(1, int(round(windows.core_s * rate)))
    static_topic, phases_topic = f"/derived/static/{name}", f"/derived/phases/{name}"
    orient_topic = f"/derived/orientation/{name}"
    imu_topic = f"/imu/{name}"  # the gyroscope, to re-integrate the orientation through movements
    use_gyr = params.anchor.enabled and orient_topic in topics and imu_topic in topics
    inputs = [acc_topic] + [t for t in (static_topic, phases_topic, orient_topic) if t in topics]
    inputs += [imu_topic] if use_gyr else []
    src_topic, src_params = acc_source(params.acc_rests, orient_topic, orient_meta, one_window, windows.core_s)
    inputs += [src_topic] if src_topic and src_topic not in inputs else []

    def window_compute(trial, phases):
        timing = trial.metadata.get(timing_record, {})
        alignment = alignment_for(trial.metadata, f"/imu/{name}")
        phases_clock = str(timing.get("clock", "reference"))

        def one(acc, static, orient, raw, source=None):
            mine = phases
            if phases is not None and not one_window:  # the repetitions inside this window only
                t = np.asarray(acc[0][[0, -1]], dtype=np.int64)
                lo, hi = to_reference(t, alignment) if phases_clock == "reference" else t
                inside = (phases.start_ns >= lo) & (phases.end_ns <= hi)
                mine = Intervals(
                    phases.topic,
                    phases.start_ns[inside],
                    phases.end_ns[inside],
                    [label for label, k in zip(phases.labels, inside, strict=True) if k],
                    phases.task_index[inside],
                )
            return compute_trajectories(
                acc[0],
                acc[1],
                imu=name,
                methods=methods,
                static=None if static is None else (static[0], static[1][:, 0]),
                phases=mine,
                phases_clock=str(timing.get("clock", "reference")),
                orientation=orient,
                alignment=alignment,
                anthropometrics=trial.metadata.get("imulog.anthropometrics"),
                params=params,
                reference_params=reference_params,
                gyr=None if raw is None or raw[1] is None else raw,
                repetition_quality=timing.get("repetition_quality"),
                per_imu=per_imu,
                chain_rest_s=windows.chain_rest_s,
                side=placement_side(name, trial.metadata),
                source=source,
            )

        return one, alignment, str(timing.get("clock", "reference"))

    def compute(trial) -> StepResult:
        phases = trial.read(phases_topic) if phases_topic in topics else None
        one, alignment, phases_clock = window_compute(trial, phases)
        if one_window:  # a lab trial: the whole recording at once
            acc = trial.read(acc_topic)
            static = trial.read(static_topic) if static_topic in topics else None
            orient = trial.read(orient_topic) if orient_topic in topics else None
            raw = trial.read(imu_topic) if use_gyr else None
            source = None
            if src_topic and src_topic in topics:  # the orientation's own input, for TrajectoryParams.acc_rests
                t_src, acc_src, gyr_src, _ = imu_arrays(trial.read(src_topic), src_topic)
                source = OrientationSource(t_src, acc_src, gyr_src, src_topic, src_params)
            streams, record = one(
                (acc.t_ns, acc.values),
                None if static is None else (static.t_ns, static.values),
                None if orient is None else (orient.t_ns, orient.values),
                None if raw is None else (raw.t_ns, raw.gyr),
                source,
            )
            provenance = {"gaps": record["gaps"]} if "gaps" in record else {}
            return StepResult(streams=streams, metadata={record_name: record}, provenance=provenance)
        return _windowed(trial, phases, one, alignment, phases_clock)

    def _windowed(trial, phases, one, alignment, phases_clock) -> StepResult:
        from imulog.process.alignment_clock import reference_to_device

        if static_topic not in topics and any(m in NEEDS_STATIC for m in methods):
            need = ", ".join(m for m in methods if m in NEEDS_STATIC)
            raise ValueError(f"methods {need} need /derived/static/{name}: run `imulog process phases` first")
        t_first = int(trial.channel(acc_topic).start_ns or 0)
        if alignment is not None and phases_clock == "reference":
            to_device = lambda t: np.asarray(reference_to_device(t, alignment), dtype=np.int64)  # noqa: E731
        else:
            to_device = lambda t: np.asarray(t, dtype=np.int64)  # noqa: E731
        plan_ = window_plan(
            trial, static_topic if static_topic in topics else None, phases, t_first, total, rate, windows, to_device
        )
        used = [m for m in methods if m != "optimized" or has_r2g(phases)]
        owner = name if per_imu else None
        out_topics = [trajectory_topic(m, owner) for m in used] + [baseline_topic(BASELINE, owner)]
        record: dict[str, Any] = {}
        pieces = StreamPieces(
            topics=out_topics,
            pieces=lambda: trajectory_pieces(
                path,
                name,
                {
                    "acc": acc_topic,
                    "static": static_topic if static_topic in topics else None,
                    "orientation": orient_topic if orient_topic in topics else None,
                    "imu": imu_topic if use_gyr else None,
                },
                plan_,
                one,
                record,
                out_topics,
                windows,
                lambda t: to_reference(t, alignment),
                total,
                "world"
                if alignment is not None and alignment.get("rotation_global_to_world", 0) is not None
                else f"{name}_global",
                clock_attrs(name, "reference" if alignment is not None else "device", per_imu),
                skip_rest_only=phases is not None and len(phases) > 0,
            ),
            expected_duration_s=total / rate,
        )
        return StepResult(streams=[pieces], metadata={record_name: record})

    step_params = {"imu": name, **params_dict(methods, params, reference_params)}
    if not one_window:
        step_params["windows"] = windows.to_dict()
    outcome = run_step(
        path,
        step=f"{STEP}:{name}" if per_imu else STEP,
        algorithm="imulog.trajectory",
        params=step_params,
        inputs=inputs,
        metadata_inputs=(
            alignment_name,
            "imulog.anthropometrics",
            timing_record,
            "imulog.trial",
            f"imulog.device.{name}",
        ),
        compute=compute,
        force=force,
    )
    if not outcome.skipped:
        _remove_stale(path, outcome.topics, name)
    return outcome


def _remove_stale(path, written: list[str], imu: str) -> None:
    """Drop the trajectory channels of ``imu`` from earlier trajectory runs that this run did not rewrite (a
    method left out of --method; the one-set channels of an older run once the trial has several IMUs), so
    evaluate, metrics and the viewer never mix them with the new inputs."""
    from imulog.archive import TrialReader, remove_derived

    with TrialReader(path) as trial:
        metadata = trial.metadata
        stale = [
            c.topic
            for c in trial.channels
            if c.topic.startswith(TRAJECTORY_TOPIC.format(method=""))
            and str(c.metadata.get("step", "")).split(":")[0] == STEP
            and (split_topic(c.topic, metadata) or ("", ""))[0] in (imu, "")
            and c.topic not in written
        ]
    if stale:
        remove_derived(
            path,
            stale,
            run={"step": "remove", "algorithm": f"stale outputs of step {STEP}", "params": {}, "inputs": []},
        )


def check_lines(record: dict[str, Any]) -> list[str]:
    """Lines for ``process trajectory``: what the accelerometer removed from the rests, then one line per
    method whose assumptions fail (``imulog.trajectory["checks"]``), with what would work instead."""
    from imulog.process.trajectory_checks import format_check

    lines = []
    rests = record.get("rests") or {}
    if rests.get("static_runs_not_rests"):
        lines.append(
            f"rests: {rests['static_runs_not_rests']} of {rests['static_runs']} still-gyroscope intervals are not "
            f"rests (the accelerometer moves): {rests['rest_s']:g} of {rests['static_s']:g} s kept for velocity resets"
        )
    for method, check in (record.get("checks") or {}).items():
        line = format_check(method, check)
        if line:
            lines.append(f"assumption failed: {line}")
    return lines
