"""The step registry: step names -> the steps' Python entry points and their options.

Options are plain JSON-able dicts (so they travel to worker processes and Dask workers unchanged)::

    {"phases": {"repetitions": 3, "threshold": 0.11}, "trajectory": {"methods": ["zupt", "kalman"]}}

Each key is either a keyword of the step's ``run_*`` function (``imu``, ``markers``, ``methods``...) or a field
of the step's parameter dataclass, dotted for nested ones (``dynamos.threshold``, ``static.threshold_rad_s``);
a few short aliases exist (``repetitions`` -> ``repetitions.n_repetitions`` for ``phases``), and a preset names a
combination of fields as the command's option does (``accelerometer=rests`` for ``trajectory``). Values given as
strings (from the command line) are converted to the type of the field's default.

:func:`run_file` runs a plan (steps in dependency order with their resolved options) on one trial and
returns a :class:`FileResult`; it never raises, so one bad file cannot stop a batch.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import json
import os
import time
import traceback
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imulog.params import coerce, params_from_dict, set_field

# Dependency order: a step may read what an earlier one wrote (align reads orientation, phases the alignment,
# trajectory orientation + phases, evaluate and metrics the trajectories, kinematics the orientations).
STEP_ORDER = (
    "calibrate",
    "orientation",
    "align",
    "heading",
    "phases",
    "trajectory",
    "metrics",
    "epochs",
    "evaluate",
    "kinematics",
)


@dataclass(frozen=True)
class StepSpec:
    """How to call one step: ``function`` (``module:attr``) with keyword ``kwargs`` and a params dataclass."""

    name: str
    function: str
    kwargs: tuple[str, ...] = ()
    params_class: str | None = None
    params_kwarg: str = "params"
    aliases: dict[str, str] = field(default_factory=dict)
    # option -> ``module:attr`` of a function ``(params, value) -> params`` that applies a named combination of
    # fields (trajectory's ``accelerometer=rests``, as the command's ``--accelerometer rests``); presets are
    # applied before the other options, so a field given with them refines the preset
    presets: dict[str, str] = field(default_factory=dict)
    required: tuple[str, ...] = ()
    help: str = ""
    # ``module:attr`` of a function ``imulog.trial record -> params``: the per-trial defaults that options
    # are applied onto (e.g. the phases step's protocol and repetition count come from the trial)
    trial_defaults: str | None = None
    # the steps whose output this one reads, required or when present (the raw channels need no step): after a
    # failure in a file, a step runs only when none of these failed or was left out for a failure (run_file)
    reads: tuple[str, ...] = ()


STEPS: dict[str, StepSpec] = {
    "calibrate": StepSpec(
        "calibrate",
        "imulog.steps.calibrate:run_calibrate",
        kwargs=("imu", "calibration"),
        required=("calibration",),
        help="apply a calibration file (option calibration=FILE.json from `imulog calibrate`)",
    ),
    "orientation": StepSpec(
        "orientation",
        "imulog.steps.orientation:run_orientation",
        reads=("calibrate",),
        kwargs=("imu", "source"),
        params_class="imulog.process.orientation:OrientationParams",
        help="orientation + gravity-free acceleration (OrientationParams: backend, beta, use_mag, ...)",
    ),
    "align": StepSpec(
        "align",
        "imulog.steps.align_setup:run_align_trial",
        reads=("orientation",),
        kwargs=("imu", "markers", "resample"),
        params_class="imulog.process.alignment:AlignmentParams",
        help="IMU-to-Vicon clock and frame alignment (AlignmentParams: window_s, max_lag_s, drift, ...)",
    ),
    "heading": StepSpec(
        "heading",
        "imulog.steps.heading:run_heading",
        reads=("orientation", "align"),
        kwargs=("imus",),
        help="one heading frame for the oriented IMUs (imulog.heading: magnetometer, optical, or none)",
    ),
    "phases": StepSpec(
        "phases",
        "imulog.steps.phases:run_phases",
        reads=("align",),
        kwargs=("imu",),
        params_class="imulog.process.segmentation.pipeline:PhaseParams",
        trial_defaults="imulog.steps.phases:params_for_trial",
        aliases={
            "repetitions": "repetitions.n_repetitions",
            "n_repetitions": "repetitions.n_repetitions",
            "phases_per_repetition": "repetitions.n_phases",
            "threshold": "dynamos.threshold",
            "alpha": "dynamos.alpha",
            "beta": "dynamos.beta",
            "cutoff_hz": "dynamos.cutoff_hz",
        },
        help="movements, R2G phases, zero-velocity mask (PhaseParams; alias repetitions=N)",
    ),
    "trajectory": StepSpec(
        "trajectory",
        "imulog.steps.trajectory:run_trajectory",
        reads=("orientation", "align", "phases"),
        kwargs=("imu", "methods"),
        params_class="imulog.process.trajectory_opt:TrajectoryParams",
        presets={"accelerometer": "imulog.process.trajectory_accelerometer:with_accelerometer"},
        help="wrist trajectories per method (methods=zupt,kalman,...; accelerometer=recorded|rests; "
        "TrajectoryParams fields)",
    ),
    "metrics": StepSpec(
        "metrics",
        "imulog.steps.metrics:run_metrics",
        reads=("align", "phases", "trajectory"),
        kwargs=("imu",),
        params_class="imulog.steps.metrics:MetricsParams",
        help="clinical metrics (MetricsParams fields)",
    ),
    "epochs": StepSpec(
        "epochs",
        "imulog.steps.epochs:run_epochs",
        kwargs=("imu",),
        params_class="imulog.steps.epochs:EpochParams",
        help="ENMO, MAD, ActiGraph counts, non-wear per epoch; hourly/daily totals (EpochParams: epochs_s=5,60, "
        "calibrate, valid_day_hours, ...)",
    ),
    "evaluate": StepSpec(
        "evaluate",
        "imulog.steps.evaluate:run_evaluate",
        reads=("orientation", "align", "trajectory"),
        kwargs=("methods", "max_gap_s", "what"),
        help="trajectory errors against the optical reference (methods=..., max_gap_s=0.05); what=orientation: the "
        "orientation against a rigid body's poses (what=auto|orientation|trajectory, as imulog evaluate --what)",
    ),
    "kinematics": StepSpec(
        "kinematics",
        "imulog.steps.kinematics:run_kinematics",
        reads=("orientation", "align"),
        params_class="imulog.steps.kinematics:KinematicsOptions",
        params_kwarg="options",
        help="shoulder and elbow angles from two IMUs (KinematicsOptions: upper_arm, forearm, ...)",
    ),
}

_LIST_KWARGS = {"methods"}


def _load(ref: str) -> Any:
    module, attr = ref.split(":")
    return getattr(importlib.import_module(module), attr)


def parse_steps(steps: str | list[str] | tuple[str, ...]) -> list[str]:
    """Step names (comma-separated string or list) validated and put in dependency order."""
    names = [s.strip() for s in steps.split(",")] if isinstance(steps, str) else [str(s).strip() for s in steps]
    names = [s for s in names if s]
    unknown = [s for s in names if s not in STEPS]
    if unknown or not names:
        raise ValueError(f"unknown step(s) {', '.join(unknown) or '(none)'}; choose from {', '.join(STEP_ORDER)}")
    return [s for s in STEP_ORDER if s in names]


def resolve_options(step: str, options: dict[str, Any] | None, base: Any = None) -> tuple[dict[str, Any], Any]:
    """``(kwargs, params)`` for calling step ``step`` with the plain ``options`` dict.

    ``base`` is the params object the options are applied onto (default: the params class's defaults).
    """
    spec = STEPS[step]
    options = dict(options or {})
    missing = [k for k in spec.required if k not in options]
    if missing:
        raise ValueError(f"step {step}: option(s) {', '.join(missing)} required ({spec.help})")
    kwargs: dict[str, Any] = {}
    params = base if base is not None else (_load(spec.params_class)() if spec.params_class else None)
    for key in [k for k in spec.presets if k in options]:  # a named combination first, then single fields
        try:
            params = _load(spec.presets[key])(params, str(options.pop(key)))
        except ValueError as exc:
            raise ValueError(f"step {step} {key}: {exc}") from None
    for key, value in options.items():
        key = str(key)
        if key in spec.kwargs:
            if key in _LIST_KWARGS and isinstance(value, str):
                value = [m.strip() for m in value.split(",") if m.strip()]
            elif key == "resample" and isinstance(value, str):
                value = coerce(value, True, f"step {step} {key}")
            elif key == "max_gap_s" and isinstance(value, str):
                value = float(value)
            kwargs[key] = value
            continue
        if params is None:
            raise ValueError(f"step {step}: unknown option {key!r} (options: {', '.join(spec.kwargs) or 'none'})")
        nested = isinstance(value, dict) and key in {f.name for f in dataclasses.fields(params)}
        # a dict for a nested parameter object sets its fields: a field's own name wins over a short alias
        # (phases' ``repetitions``: the count as a number, the RepetitionParams as a dict)
        params = set_field(params, key if nested else spec.aliases.get(key, key), value, f"step {step}")
    return kwargs, params


def normalize_options(steps: list[str], options: dict[str, dict[str, Any]] | None) -> dict[str, dict[str, Any]]:
    """Validate ``options`` for ``steps`` (raises ValueError early, before any file is touched)."""
    options = {str(k): dict(v or {}) for k, v in (options or {}).items()}
    extra = sorted(set(options) - set(STEPS))
    if extra:
        raise ValueError(f"options for unknown step(s) {', '.join(extra)}")
    out = {}
    for step in steps:
        resolve_options(step, options.get(step))  # raises on bad keys / values
        out[step] = options.get(step, {})
    return out


def plan_fingerprint(steps: list[str], options: dict[str, dict[str, Any]]) -> str:
    """Canonical text of a plan (steps, resolved options, imulog version): the batch ledger's key.

    Options are resolved first, so ``{"repetitions": "3"}`` and ``{"repetitions": 3}`` are the same plan.
    """
    from imulog import __version__
    from imulog.steps.base import params_json

    resolved = {}
    for step in steps:
        kwargs, params = resolve_options(step, options.get(step))
        resolved[step] = {"kwargs": kwargs, "params": json.loads(params_json(params))}
        if step == "calibrate":  # the calibration file's content, not just its name
            try:
                resolved[step]["calibration_sha256"] = hashlib.sha256(
                    Path(kwargs["calibration"]).read_bytes()
                ).hexdigest()
            except OSError as exc:
                raise ValueError(f"step calibrate: cannot read calibration file: {exc}") from None
    return json.dumps(
        {"steps": steps, "options": resolved, "imulog": __version__}, sort_keys=True, separators=(",", ":"), default=str
    )


# ---------------------------------------------------------------------------------------------- one file


@dataclass
class StepRecord:
    """What one step did on one file."""

    step: str
    skipped: bool
    run: int | None
    seconds: float
    reason: str = ""


@dataclass
class FileResult:
    """What the batch did to one file. ``status``: ``processed`` (some step computed), ``up_to_date`` (nothing
    to do: every step already recorded, or the batch ledger says so: ``prechecked``), ``failed``."""

    path: str
    status: str
    steps: list[StepRecord] = field(default_factory=list)
    error: str = ""
    failed_step: str = ""
    traceback: str = ""
    seconds: float = 0.0
    prechecked: bool = False
    worker: str = ""

    @property
    def computed(self) -> int:
        return sum(not s.skipped for s in self.steps)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def run_params(run: Mapping[str, Any]) -> tuple[Any, dict[str, Any]]:
    """``(params, rest)`` of a recorded run (``trial.runs()[n]``, an ``imulog.run.<n>`` record): the step's
    parameter object rebuilt from the ``params`` it recorded (``OrientationParams`` for ``orientation:wrist``;
    None for a step without one), and the recorded keys that are not its fields (the step's keywords such as
    ``imu`` or ``methods``, and what it derived, such as orientation's ``global_frame``). ValueError names a step
    this registry does not know."""
    name = str(run.get("step", "")).partition(":")[0]
    spec = STEPS.get(name)
    if spec is None:
        raise ValueError(f"run of step {run.get('step')!r}: not a registered step ({', '.join(STEP_ORDER)})")
    recorded = dict(run.get("params") or {})
    if spec.params_class is None:
        return None, recorded
    cls = _load(spec.params_class)
    fields = {f.name for f in dataclasses.fields(cls)}
    params = params_from_dict(cls, {k: v for k, v in recorded.items() if k in fields})
    return params, {k: v for k, v in recorded.items() if k not in fields}


def call_step(path: str | os.PathLike[str], step: str, options: dict[str, Any] | None = None, *, force: bool = False):
    """Run one registered step on one trial; returns the step's ``StepOutcome``."""
    spec = STEPS[step]
    base = None
    if spec.trial_defaults:
        from imulog.archive import TrialReader

        with TrialReader(path) as trial:
            base = _load(spec.trial_defaults)(trial.metadata.get("imulog.trial", {}))
    kwargs, params = resolve_options(step, options, base)
    fn = _load(spec.function)
    from imulog.batch.imus import PER_IMU_NEEDS, run_every_imu

    if step == "calibrate":
        from imulog.process.calibration import Calibration

        cal_file = Path(kwargs.pop("calibration"))
        calibration = Calibration.from_dict(json.loads(cal_file.read_text()))
        if "imu" not in kwargs:  # every IMU of the trial, like `imulog calibrate` with one file
            return run_every_imu(path, step, lambda **kw: fn(path, calibration, force=force, **kw), kwargs)
        return fn(path, calibration, force=force, **kwargs)
    if params is not None:
        kwargs[spec.params_kwarg] = params
    if step in PER_IMU_NEEDS and "imu" not in kwargs:  # every IMU of the trial, one step:IMU run each
        return run_every_imu(path, step, lambda **kw: fn(path, force=force, **kw), kwargs)
    out = fn(path, force=force, **kwargs)
    return out[0] if isinstance(out, tuple) else out  # run_evaluate returns (outcome, record)


def failed_inputs(step: str, lost: dict[str, tuple[str, ...]]) -> tuple[str, ...]:
    """The failed steps ``step`` depends on: ``lost`` maps each step that failed to ``(itself,)`` and each step
    left out for a failure to the failed steps behind it; a step reading none of them gives ``()`` (it runs)."""
    roots: list[str] = []
    for name in STEPS[step].reads:
        roots.extend(r for r in lost.get(name, ()) if r not in roots)
    return tuple(roots)


def run_file(path: str, plan: list[tuple[str, dict[str, Any]]], force: bool = False) -> FileResult:
    """Run ``plan`` (``[(step, options), ...]``) on one trial; never raises (errors go into the result).

    One rule after a failure: a step runs when no step it reads (:attr:`StepSpec.reads`) failed or was left out,
    else it is recorded skipped with the reason naming the failed step(s). ``error`` names every failure, then
    what still ran and what did not; ``failed_step`` is the first failure.

    Top-level and picklable: the entry point of worker processes and Dask tasks.
    """
    t0 = time.perf_counter()
    result = FileResult(path=str(path), status="up_to_date", worker=f"pid {os.getpid()}")
    lost: dict[str, tuple[str, ...]] = {}
    after: list[str] = []  # steps that ran after the first failure
    for step, options in plan:
        roots = failed_inputs(step, lost)
        if roots:
            lost[step] = roots
            reason = f"not run: needs {', '.join(roots)}, which failed"
            result.steps.append(StepRecord(step, True, None, 0.0, reason))
            continue
        t = time.perf_counter()
        try:
            outcome = call_step(path, step, options, force=force)
        except Exception as exc:  # isolate the file: report, do not propagate
            from imulog.steps.common import StepError

            result.failed_step = result.failed_step or step
            shown = exc.__cause__ if isinstance(exc, StepError) and exc.__cause__ is not None else exc  # the file
            line = f"{step}: {type(shown).__name__}: {shown}"  # is named once, by the batch's line
            result.error = f"{result.error}; {line}" if result.error else line
            result.traceback = result.traceback or traceback.format_exc(limit=8)
            lost[step] = (step,)
            continue
        result.steps.append(
            StepRecord(step, bool(outcome.skipped), outcome.run, time.perf_counter() - t, outcome.reason)
        )
        if lost:
            after.append(step)
        elif not outcome.skipped:
            result.status = "processed"
    if lost:
        result.status = "failed"
        notes = [f"still run: {', '.join(after)}"] if after else []
        notes += [f"{s.step} {s.reason}" for s in result.steps if s.step in lost]
        if notes:
            result.error += f" ({'; '.join(notes)})"
    result.seconds = time.perf_counter() - t0
    return result
