"""Run one reprocessing step on a trial: read inputs, compute, append derived channels with provenance.

    outcome = run_step("trial.mcap", step="orientation", algorithm="vqf", params=VqfParams(),
                       inputs=["/imu/wrist"], compute=lambda trial: StepResult(streams=[...]))

The step is skipped (nothing written) when the latest run of the same ``step`` recorded the same
algorithm, params and input content hashes and its output channels are still the ones it wrote.

Races: a run holds the trial's lock for its step (a second run of the same step waits, then finds the
result up to date), and the append refuses to write when an input channel or a metadata record the step
read changed while it computed (another process re-aligned, say).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imulog.archive import TrialReader, append_derived
from imulog.archive.append import METADATA_INPUT
from imulog.archive.files import step_lock, target_path
from imulog.archive.metadata import record_hash, to_json
from imulog.model import Stream


@dataclass
class StepResult:
    """What a step's ``compute`` returns: derived streams and metadata records (e.g. ``imulog.alignment``).

    ``provenance``: extra keys of the run's ``imulog.run.<n>`` record, e.g. ``{"gaps": {...}}`` (how many
    missing input samples were bridged, how many runs the input was split into; see ``imulog.process.gaps``).
    """

    streams: list[Stream] = field(default_factory=list)
    metadata: dict[str, dict[str, Any]] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)


@dataclass
class StepOutcome:
    """What :func:`run_step` did: ``skipped`` (already up to date) or wrote ``topics`` as run ``run``."""

    path: Path
    step: str
    skipped: bool
    run: int | None
    topics: list[str]
    input_hashes: dict[str, str]
    reason: str = ""


WRITER_WAIT_S = 60.0  # how long a step waits for another step's append to finish before giving up
metadata_hash = record_hash  # content hash of a metadata record (canonical JSON; a missing one is ``null``)


def params_json(params: Any) -> str:
    """Canonical JSON of a params object (frozen dataclass, dict, or None)."""
    if dataclasses.is_dataclass(params) and not isinstance(params, type):
        params = dataclasses.asdict(params)
    return to_json({} if params is None else params)


def _up_to_date(
    trial: TrialReader, step: str, algorithm: str, pjson: str, hashes: dict[str, str]
) -> tuple[int, dict] | None:
    runs = [(n, r) for n, r in trial.runs().items() if r.get("step") == step]
    if not runs:
        return None
    n, rec = runs[-1]
    if rec.get("algorithm") != algorithm or to_json(rec.get("params", {})) != pjson or rec.get("inputs") != hashes:
        return None
    channels = {c.topic: c for c in trial.channels}
    for topic in rec.get("outputs", {}):
        c = channels.get(topic)
        if c is None or c.metadata.get("run") != str(n):
            return None
    return n, rec


def run_step(
    path: str | os.PathLike[str],
    *,
    step: str,
    algorithm: str,
    params: Any,
    inputs: Sequence[str],
    compute: Callable[[TrialReader], StepResult],
    force: bool = False,
    metadata_inputs: Sequence[str] = (),
) -> StepOutcome:
    """Run ``compute`` on the trial and append its result, unless the same run is already recorded.

    ``inputs`` are the topics the step reads (their content hashes go into the provenance);
    ``metadata_inputs`` the metadata records it reads (e.g. ``imulog.alignment``: recorded as
    ``metadata:imulog.alignment``, so that re-aligning makes the step out of date); ``params`` a frozen
    dataclass or dict. ``force`` recomputes and rewrites even when up to date.
    """
    path = Path(path)
    with step_lock(target_path(path), step):
        return _run_locked(path, step, algorithm, params, inputs, compute, force, metadata_inputs)


def _run_locked(
    path: Path,
    step: str,
    algorithm: str,
    params: Any,
    inputs: Sequence[str],
    compute: Callable[[TrialReader], StepResult],
    force: bool,
    metadata_inputs: Sequence[str],
) -> StepOutcome:
    pjson = params_json(params)
    with TrialReader(path) as trial:
        hashes = {topic: trial.channel_hash(topic) for topic in inputs}
        hashes |= {METADATA_INPUT + name: metadata_hash(trial.metadata.get(name)) for name in metadata_inputs}
        if not force:
            done = _up_to_date(trial, step, algorithm, pjson, hashes)
            if done is not None:
                n, rec = done
                return StepOutcome(
                    path, step, True, n, sorted(rec.get("outputs", {})), hashes, "same algorithm, params and inputs"
                )
        result = compute(trial)
    if not isinstance(result, StepResult):
        raise TypeError(f"step {step!r}: compute() must return a StepResult, got {type(result).__name__}")
    append_derived(
        path,
        result.streams,
        run={
            **result.provenance,
            "step": step,
            "algorithm": algorithm,
            "params": json.loads(pjson),
            "inputs": hashes,
        },
        metadata=result.metadata,
        replace=True,
        wait_s=WRITER_WAIT_S,
    )
    with TrialReader(path) as trial:
        n = max(trial.runs(), default=None)
    outputs = [t for s in result.streams for t in (s.topics if hasattr(s, "topics") else [s.topic])]
    return StepOutcome(path, step, False, n, outputs, hashes, "computed")


def run_record_step(
    path: str | os.PathLike[str],
    *,
    record_name: str,
    compute_record: Callable[[TrialReader], dict[str, Any]],
    **run_step_args: Any,
) -> tuple[StepOutcome, dict[str, Any]]:
    """:func:`run_step` for a step whose one output is the metadata record ``record_name`` (an evaluation, the
    heading): ``compute_record`` returns the record; returns the outcome and the record, computed now or, when the
    same run is already recorded, read back from the trial."""
    holder: dict[str, dict[str, Any]] = {}

    def compute(trial: TrialReader) -> StepResult:
        holder["record"] = compute_record(trial)
        return StepResult(streams=[], metadata={record_name: holder["record"]})

    outcome = run_step(path, compute=compute, **run_step_args)
    if "record" not in holder:
        with TrialReader(path) as trial:
            holder["record"] = trial.metadata.get(record_name, {})
    return outcome, holder["record"]
