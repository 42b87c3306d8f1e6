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

import os
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.process.gaps import GapParams
from imulog.process.segmentation.pipeline import PhaseParams
from imulog.process.segmentation.repetitions import RepetitionParams
from imulog.steps.common import mean_rate_hz, missing_gyroscope, names_trial, pick_imu, record_for
from imulog.steps.phases_record import LOW_CONFIDENCE
from imulog.steps.phases_store import array_source, trial_source
from imulog.steps.phases_windows import PhaseWindows, phase_pieces, unsupported

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

__all__ = ["LOW_CONFIDENCE", "PhaseWindows", "compute_phases", "params_for_trial", "pick_imu", "run_phases"]

STEP = "phases"


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


def collect(pieces, topics: list[str]) -> list:
    """Whole streams of ``topics`` from their pieces, in the order of ``topics`` (a one-window recording)."""
    from imulog.model import Intervals, SignalStream

    parts: dict[str, list] = {t: [] for t in topics}
    for piece in pieces:
        parts[piece.topic].append(piece)
    out = []
    for topic in topics:
        got = parts[topic]
        if len(got) == 1:
            out.append(got[0])
        elif isinstance(got[0], Intervals):
            out.append(
                Intervals(
                    topic,
                    np.concatenate([x.start_ns for x in got]),
                    np.concatenate([x.end_ns for x in got]),
                    [label for x in got for label in x.labels],
                    task_index=np.concatenate([x.task_index for x in got]),
                )
            )
        else:
            first: SignalStream = got[0]
            out.append(
                SignalStream(
                    topic,
                    np.concatenate([x.t_ns for x in got]),
                    first.columns,
                    first.units,
                    np.concatenate([x.values for x in got]),
                    frame_id=first.frame_id,
                )
            )
    return out


def compute_phases(
    t_ns: np.ndarray,
    gyr: np.ndarray,
    imu: str,
    params: PhaseParams,
    alignment: dict | None = None,
    acc: np.ndarray | None = None,
    gaps: GapParams | None = None,
) -> tuple[list, dict]:
    """The step on samples in memory: ``[movements, phases, static]`` and the ``imulog.timing`` record.

    One window of :func:`imulog.steps.phases_windows.phase_pieces` (the step's one implementation, which reads
    longer recordings window by window). ``acc`` (m/s^2, optional): phase boundaries then also follow the hand's
    translation.

    Missing samples (NaN) follow :mod:`imulog.process.gaps`: short gaps are bridged; inside longer ones the
    gyroscope reads as zero (no movement is detected there, so a movement interrupted by a gap ends at it and a new
    one starts after it; repetition grouping still sees the whole trial) and ``/derived/static`` is NaN (unknown,
    never zero velocity). ``imulog.timing["gaps"]`` records what was done."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if len(t_ns) < 10:
        raise ValueError(f"/imu/{imu} has only {len(t_ns)} samples")
    if gyr is None:
        raise missing_gyroscope(f"/imu/{imu}", "phases are found on the angular velocity")
    rate_hz = mean_rate_hz(t_ns)
    record: dict[str, Any] = {}
    one = PhaseWindows(core_s=float("inf"))
    pieces = phase_pieces(
        array_source(t_ns, gyr, acc), len(t_ns), rate_hz, imu, params, gaps, record, windows=one, alignment=alignment
    )
    streams = collect(pieces, [f"/derived/movements/{imu}", f"/derived/phases/{imu}", f"/derived/static/{imu}"])
    return streams, record


@names_trial
def run_phases(
    path: str | os.PathLike[str],
    *,
    imu: str | None = None,
    params: PhaseParams | None = None,
    force: bool = False,
    gaps: GapParams | None = None,
    windows: PhaseWindows | None = None,
) -> StepOutcome:
    """Movements, phases and repetitions of one IMU (``imulog process phases``): appends ``/derived/movements/IMU``
    and ``/derived/phases/IMU`` (intervals, ns on the clock the ``imulog.timing`` record names), ``/derived/static/IMU``
    (1 where still) and the ``imulog.timing`` record (per-phase durations in s). Returns the
    :class:`~imulog.steps.base.StepOutcome`; :class:`~imulog.steps.common.StepError` names ``path``.

    Without ``params`` the trial's own protocol and repetition count are used (:func:`params_for_trial`);
    ``gaps``: how missing IMU samples are treated (:mod:`imulog.process.gaps`). The recording is read in
    ``windows`` (default one-hour cores, :class:`~imulog.steps.phases_windows.PhaseWindows`): a lab trial is one
    window and computed at once; a longer one window by window while the result is written, in bounded memory.
    """
    from pathlib import Path

    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step
    from imulog.steps.common import alignment_for, alignment_record
    from imulog.steps.windows import channel_rate_hz

    windows = windows or PhaseWindows()
    with TrialReader(path) as trial:
        name = pick_imu(trial.topics(), imu)
        record_name = record_for("imulog.timing", name, trial.topics(), trial.metadata)
        alignment_name = alignment_record(trial.metadata, f"/imu/{name}")  # this IMU's, in a setup
        params = params or params_for_trial(trial.metadata.get("imulog.trial", {}))
        channel = trial.channel(f"/imu/{name}")
        total = int(channel.sample_count or 0)
        span_ns = (channel.end_ns or 0) - (channel.start_ns or 0)
        rate = channel_rate_hz(total, channel.start_ns, channel.end_ns, channel.rate_hz)
    topic = f"/imu/{name}"
    n_windows = len(windows.plan(total, rate))
    reason = unsupported(params, n_windows)
    if reason is not None:
        raise ValueError(f"{topic}: {reason}")
    step_params = {"imu": name, **params.to_dict()}
    if n_windows > 1:  # a trial within one core does not depend on the window sizes
        step_params["windows"] = windows.to_dict()

    def compute(trial) -> StepResult:
        alignment = alignment_for(trial.metadata, topic)
        if n_windows > 1:  # days of daily life: window by window while the result is written
            if total < 10 or span_ns <= 0:
                raise ValueError(f"{topic} has only {total} samples")
            start_time = (trial.metadata.get("imulog.trial") or {}).get("start_time")
            record: dict[str, Any] = {}
            pieces = StreamPieces(
                topics=[f"/derived/static/{name}", f"/derived/movements/{name}", f"/derived/phases/{name}"],
                pieces=lambda: phase_pieces(
                    trial_source(path, topic, total),
                    total,
                    rate,
                    name,
                    params,
                    gaps,
                    record,
                    windows=windows,
                    alignment=alignment,
                    start_time=str(start_time) if start_time else None,
                    temp_dir=Path(path).resolve().parent,
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
        metadata_inputs=("imulog.trial", alignment_name),
        compute=compute,
        force=force,
    )
