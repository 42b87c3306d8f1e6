"""Reprocessing step ``phases``: movements, R2G phases, zero-velocity mask and timing table of one IMU.

Reads ``/imu/{imu}`` (gyroscope, device clock) and writes

* ``/derived/movements/{imu}``: Intervals labelled ``movement`` (raw segmentation, before event correction);
* ``/derived/phases/{imu}``: Intervals labelled ``reach``, ``lift``, ``return_bottle``, ``return_hand`` with
  ``task_index`` = repetition (1-based), onsets/offsets refined against the static gyroscope noise
  (:mod:`imulog.process.segmentation.boundaries`);
* ``/derived/static/{imu}``: SignalStream column ``static`` (1 = zero velocity), one row per IMU sample on the
  IMU device clock (the same ``t_ns`` as the raw channel, ready for ZUPT);
* metadata ``imulog.timing``: per phase repetition, label, start/end, duration (s), peak angular velocity
  (rad/s), ``forced`` and the repetition's ``confidence``; per repetition what event correction did
  (``repetition_quality``: movements, merged, dropped, split, missing, forced, cost, confidence), with
  ``n_forced_phases``, ``mean_confidence`` and ``low_confidence_repetitions`` (confidence < 0.5).

Interval times (movements, phases, timing table) are on the reference clock when the trial has an
``imulog.alignment`` record for this IMU (so they line up with Vicon), otherwise on the IMU device clock;
``imulog.timing["clock"]`` says which.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from imulog.model import Intervals, SignalStream
from imulog.process.gaps import GapParams, prepare
from imulog.process.segmentation.pipeline import PhaseParams, segment_phases, timing_table
from imulog.process.segmentation.repetitions import RepetitionParams
from imulog.steps.common import alignment_for, mean_rate_hz, pick_imu, record_for
from imulog.steps.long_phases import LONG_SAMPLES, PhaseCores, long_phase_pieces, long_unsupported

STEP = "phases"
LOW_CONFIDENCE = 0.5  # repetitions below this confidence are listed in imulog.timing["low_confidence_repetitions"]


def protocol_of(trial_record: dict[str, Any], default_repetitions: int = 25) -> tuple[str, int]:
    """(protocol, repetitions) of a trial from its ``imulog.trial`` record.

    ``task`` ``r2g`` gives the drinking task's phases with the recorded ``repetitions`` (default 25);
    any other or unknown task gives plain movements (labelling R2G phases there would be nonsense).
    Raises ValueError when ``repetitions`` is not a whole number.
    """
    protocol = "r2g" if str(trial_record.get("task", "")).lower() == "r2g" else "movements"
    value = trial_record.get("repetitions", default_repetitions)
    try:
        return protocol, int(value)
    except (TypeError, ValueError):
        raise ValueError(f"imulog.trial repetitions={value!r} is not a whole number") from None


def params_for_trial(trial_record: dict[str, Any]) -> PhaseParams:
    """Default parameters for a trial: its protocol and repetition count (see :func:`protocol_of`)."""
    protocol, repetitions = protocol_of(trial_record)
    return PhaseParams(protocol=protocol, repetitions=RepetitionParams(n_repetitions=repetitions))


def algorithm_name(params: PhaseParams) -> str:
    return f"imulog.segmentation.{params.method}"


def compute_phases(
    t_ns: np.ndarray,
    gyr: np.ndarray,
    imu: str,
    params: PhaseParams,
    alignment: dict | None = None,
    acc: np.ndarray | None = None,
    gaps: GapParams | None = None,
) -> tuple[list, dict]:
    """Pure part of the step: streams and the ``imulog.timing`` record from IMU samples (no I/O).

    ``acc`` (m/s^2, optional): phase boundaries then also follow the hand's translation.

    Missing samples (NaN) follow :mod:`imulog.process.gaps`: short gaps are bridged; inside longer ones the
    gyroscope reads as zero (no movement is detected there, so a movement interrupted by a gap ends at it and a new
    one starts after it; repetition grouping still sees the whole trial) and ``/derived/static`` is NaN (unknown,
    never zero velocity). ``imulog.timing["gaps"]`` records what was done."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if len(t_ns) < 10:
        raise ValueError(f"/imu/{imu} has only {len(t_ns)} samples")
    if gyr is None:
        raise ValueError(f"/imu/{imu} has no gyroscope columns")
    rate_hz = mean_rate_hz(t_ns)
    (gyr, acc), gap_report = prepare([gyr, acc], gaps)
    unknown = np.ones(len(t_ns), dtype=bool)
    for a, b in gap_report.runs:
        unknown[a:b] = False
    if unknown.all():
        raise ValueError(f"/imu/{imu}: no valid run of samples ({gap_report.missing} of {len(t_ns)} missing)")
    if unknown.any():
        gyr = np.where(unknown[:, None], 0.0, gyr)
        if acc is not None:  # only for boundary refinement near the gap edges: bridged, the gap itself is not used
            ok = ~unknown
            idx = np.arange(len(acc))
            acc = np.column_stack([np.interp(idx, idx[ok], acc[ok, j]) for j in range(3)])
    result = segment_phases(gyr, rate_hz, params, acc)
    t_iv, clock = t_ns, "device"
    if alignment is not None:
        from imulog.process.alignment import device_to_reference

        t_iv, clock = np.asarray(device_to_reference(t_ns, alignment), dtype=np.int64), "reference"
    last = len(t_ns) - 1
    ph = result.phases
    movements = Intervals(
        topic=f"/derived/movements/{imu}",
        start_ns=t_iv[result.movement_start],
        end_ns=t_iv[np.minimum(np.maximum(result.movement_end - 1, result.movement_start), last)],
        labels=["movement"] * len(result.movement_start),
    )
    phases = Intervals(
        topic=f"/derived/phases/{imu}",
        start_ns=t_iv[ph.start],
        end_ns=t_iv[np.minimum(np.maximum(ph.end - 1, ph.start), last)],
        labels=list(ph.labels),
        task_index=ph.repetition,
    )
    static = SignalStream(
        topic=f"/derived/static/{imu}",
        t_ns=t_ns,
        columns=["static"],
        units=["1"],
        values=np.where(unknown, np.nan, result.static.astype(np.float64))[:, None],
        frame_id=imu,
    )
    rows = timing_table(ph, t_iv, gyr)
    n_rep = int(ph.repetition.max()) if len(ph) else 0
    timing = {
        "imu": f"/imu/{imu}",
        "method": params.method,
        "protocol": params.protocol,
        "clock": clock,
        "rate_hz": round(rate_hz, 4),
        "n_movements": int(len(result.movement_start)),
        "n_repetitions": n_rep,
        "n_phases": int(len(ph)),
        "n_corrected_repetitions": int(ph.n_corrected),
        "n_forced_phases": int(np.sum(ph.forced)) if ph.forced is not None else 0,
        "mean_confidence": round(float(np.mean([q["confidence"] for q in ph.quality])), 3) if ph.quality else None,
        "low_confidence_repetitions": [q["repetition"] for q in ph.quality if q["confidence"] < LOW_CONFIDENCE],
        "repetition_quality": list(ph.quality),
        "static_fraction": round(float(result.static[~unknown].mean()), 4),
        "phases": rows,
    }
    if gap_report.missing:
        timing["gaps"] = gap_report.as_dict()
    return [movements, phases, static], timing


def run_phases(
    path,
    *,
    imu: str | None = None,
    params: PhaseParams | None = None,
    force: bool = False,
    gaps: GapParams | None = None,
    cores: PhaseCores | None = None,
):
    """Run the step on a trial file; returns the :func:`imulog.steps.base.run_step` outcome.

    Without ``params`` the trial's own protocol and repetition count are used (:func:`params_for_trial`);
    ``gaps``: how missing IMU samples are treated (:mod:`imulog.process.gaps`). Recordings longer than
    :data:`~imulog.steps.long_phases.LONG_SAMPLES` samples, or any with ``cores``, are segmented core by core in
    bounded memory (:mod:`imulog.steps.long_phases`; ``imulog.timing`` then holds summaries, not a row per phase).
    """
    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step

    with TrialReader(path) as trial:
        name = pick_imu(trial.topics(), imu)
        record_name = record_for("imulog.timing", name, trial.topics(), trial.metadata)
        params = params or params_for_trial(trial.metadata.get("imulog.trial", {}))
        channel = trial.channel(f"/imu/{name}")
        total = int(channel.sample_count or 0)
        span_ns = (channel.end_ns or 0) - (channel.start_ns or 0)
    topic = f"/imu/{name}"
    long = cores is not None or total > LONG_SAMPLES
    step_params = {"imu": name, **params.to_dict()}
    if long:
        reason = long_unsupported(params)
        if reason is not None:
            raise ValueError(
                f"{topic} has {total:,} samples (more than {LONG_SAMPLES:,}: processed core by core): {reason}"
            )
        cores = cores or PhaseCores()
        step_params["cores"] = cores.to_dict()

    def compute(trial) -> StepResult:
        alignment = alignment_for(trial.metadata, topic)
        if long:  # days of daily life: core by core while the result is written; the record fills at the end
            if total < 10 or span_ns <= 0:
                raise ValueError(f"{topic} has only {total} samples")
            rate = (total - 1) / (span_ns * 1e-9)  # mean_rate_hz of the whole channel
            start_time = (trial.metadata.get("imulog.trial") or {}).get("start_time")
            record: dict[str, Any] = {}
            pieces = StreamPieces(
                topics=[f"/derived/static/{name}", f"/derived/movements/{name}", f"/derived/phases/{name}"],
                pieces=lambda: long_phase_pieces(
                    path,
                    topic,
                    name,
                    params,
                    gaps,
                    total,
                    rate,
                    record,
                    alignment=alignment,
                    start_time=str(start_time) if start_time else None,
                    cores=cores,
                ),
                expected_duration_s=span_ns * 1e-9,
            )
            return StepResult(streams=[pieces], metadata={record_name: record})
        stream = trial.read(topic)
        streams, timing = compute_phases(stream.t_ns, stream.gyr, name, params, alignment, stream.acc, gaps)
        provenance = {"gaps": timing["gaps"]} if "gaps" in timing else {}
        return StepResult(streams=streams, metadata={record_name: timing}, provenance=provenance)

    return run_step(
        path,
        step=f"{STEP}:{name}",
        algorithm=algorithm_name(params),
        params=step_params,
        inputs=[topic],
        metadata_inputs=("imulog.trial", "imulog.alignment"),
        compute=compute,
        force=force,
    )
