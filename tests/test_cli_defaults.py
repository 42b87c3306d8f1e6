"""One source of defaults (issue 15 item 5): every command-line default equals the Python and batch default.

The test walks every option of every ``imulog process ...`` command, ``imulog evaluate`` and ``imulog
calibrate``, and compares its default with the step's parameter object as the batch registry builds it
(``imulog.batch.registry.resolve_options(step, {})``) or the ``run_*`` keyword default. An option must either map
to a Python default below or be listed as command-line only; a new option without either fails the test.
(Before this test, ``process trajectory --sigma-ref`` was 0.03 while ``OptimizationParams.sigma_ref_static_m`` is
0.015, so `imulog batch` recomputed every optimized trajectory made on the command line.)
"""

from __future__ import annotations

import inspect
from typing import Any

import click
import pytest

from imulog.batch.registry import STEPS, _load, resolve_options
from imulog.cli import cli
from imulog.process.trajectory_accelerometer import accelerometer_of

# options that only steer the command line (what to print, which channel) or whose default is read from the trial
CLI_ONLY = {"help", "force", "as_json", "quiet", "imu", "imus", "markers", "poses", "static_trial", "noise_statistic"}
FROM_TRIAL = {  # None on the command line = the trial's own value, as in the batch (StepSpec.trial_defaults)
    ("process", "phases"): {"repetitions", "protocol"},
    ("process", "kinematics"): {"upper_arm", "forearm", "trunk", "neutral_pose", "neutral_window"},
    ("evaluate",): {"strides"},  # per stride when the trial is walking (issue 27)
    ("process", "heading"): {"static_pose"},  # a pose only when the user declares one
}


def _trajectory_methods(kw: dict[str, Any], p: Any) -> str:
    return ",".join(kw["methods"])


# command -> (registry step, {option name: python default from (run_* keyword defaults, params)})
DEFAULTS: dict[tuple[str, ...], tuple[str, dict[str, Any]]] = {
    ("process", "orientation"): (
        "orientation",
        {
            "backend": lambda kw, p: p.backend,
            "beta": lambda kw, p: p.beta,
            "use_mag": lambda kw, p: p.use_mag,
            "static_threshold": lambda kw, p: p.static.threshold_rad_s,
            "static_min_s": lambda kw, p: p.static.min_duration_s,
            "source": lambda kw, p: kw["source"],
        },
    ),
    ("process", "align"): (
        "align",
        {
            "window_s": lambda kw, p: p.window_s,
            "window_start_s": lambda kw, p: p.window_start_s,
            "max_lag_s": lambda kw, p: p.max_lag_s,
            "drift": lambda kw, p: p.drift,
            "cluster": lambda kw, p: p.cluster,
            "cluster_markers": lambda kw, p: ",".join(p.markers) or None,
            "cutoff_hz": lambda kw, p: p.filter.cutoff_hz,
            "max_gap_s": lambda kw, p: p.filter.max_gap_s,
            "resample": lambda kw, p: kw["resample"],
        },
    ),
    ("process", "phases"): (
        "phases",
        {
            "method": lambda kw, p: p.method,
            "threshold": lambda kw, p: p.dynamos.threshold,
            "phases_per_repetition": lambda kw, p: p.repetitions.n_phases,
            "alpha": lambda kw, p: p.dynamos.alpha,
            "beta": lambda kw, p: p.dynamos.beta,
            "cutoff_hz": lambda kw, p: p.dynamos.cutoff_hz,
            "no_refine": lambda kw, p: not p.dynamos.refine_boundaries,
            "static_method": lambda kw, p: p.static,
            "static_threshold": lambda kw, p: p.gyro_norm.threshold_rad_s,
        },
    ),
    ("process", "trajectory"): (
        "trajectory",
        {
            "methods": _trajectory_methods,
            "highpass_hz": lambda kw, p: p.highpass.cutoff_hz,
            "wavelet": lambda kw, p: p.wavelet.wavelet,
            "wavelet_level": lambda kw, p: p.wavelet.level,
            "kalman_alpha": lambda kw, p: p.kalman.alpha,
            "kalman_q": lambda kw, p: p.kalman.process_var_m2ps4,
            "no_smoother": lambda kw, p: not p.kalman.smoother,
            "no_zero_velocity": lambda kw, p: not p.kalman.zero_velocity,
            "sigma_ref": lambda kw, p: p.optimized.sigma_ref_static_m,
            "sigma_data": lambda kw, p: p.optimized.sigma_data_mps,
            "no_return_to_start": lambda kw, p: not p.optimized.return_to_start,
            "accelerometer": lambda kw, p: accelerometer_of(p),
        },
    ),
    ("process", "metrics"): (
        "metrics",
        {
            "noise_level_g": lambda kw, p: p.noise_level_g,
            "noise_floor_g": lambda kw, p: p.noise_floor_g,
            "m_s": lambda kw, p: p.m_s,
            "dead_s": lambda kw, p: p.dead_s,
            "min_activity_s": lambda kw, p: p.min_activity_s,
            "window_s": lambda kw, p: p.window_s,
            "max_distance_cm": lambda kw, p: p.max_distance_cm,
            "weight_start_cm": lambda kw, p: p.weight_start_cm,
            "acc_unit": lambda kw, p: p.acc_unit,
            "trajectory": lambda kw, p: p.trajectory,
            "arm_usage_rate_hz": lambda kw, p: p.arm_usage_rate_hz,
        },
    ),
    ("process", "epochs"): (
        "epochs",
        {
            "epochs_s": lambda kw, p: p.epochs_s,
            "no_calibrate": lambda kw, p: not p.calibrate,
            "valid_day_hours": lambda kw, p: p.valid_day_hours,
        },
    ),
    ("process", "kinematics"): (
        "kinematics",
        {
            "calibration": lambda kw, p: p.calibration_mode,
            "markers": lambda kw, p: p.use_markers,
            "max_iterations": lambda kw, p: p.solver.max_iterations,
        },
    ),
    ("process", "calibrate"): ("calibrate", {"calibrations": "required"}),  # no default in either
    ("process", "heading"): ("heading", {}),
    ("evaluate",): (
        "evaluate",
        {
            "methods": lambda kw, p: kw["methods"],
            "max_gap": lambda kw, p: kw["max_gap_s"],
            "what": lambda kw, p: kw["what"],
        },
    ),
}


def _command(path: tuple[str, ...]) -> click.Command:
    ctx = click.Context(cli)
    cmd: click.Command = cli
    for name in path:
        cmd = cmd.get_command(ctx, name)  # type: ignore[union-attr]
        assert cmd is not None, f"no command imulog {' '.join(path)}"
    return cmd


def _python_defaults(step: str) -> tuple[dict[str, Any], Any]:
    """(run_* keyword defaults, params) exactly as ``imulog batch`` calls the step without options."""
    spec = STEPS[step]
    kwargs = {
        k: v.default
        for k, v in inspect.signature(_load(spec.function)).parameters.items()
        if v.default is not inspect.Parameter.empty
    }
    if step == "calibrate":
        return kwargs, None
    resolved, params = resolve_options(step, {})
    return {**kwargs, **resolved}, params


def _cli_default(cmd: click.Command, option: click.Option) -> Any:
    value = option.get_default(click.Context(cmd), call=True)  # what a run without the option gets (flags: False)
    if cmd.name == "phases" and option.name == "threshold":
        from imulog.commands.phases import _threshold

        return _threshold(value)
    return value


def test_every_process_command_is_covered():
    """A new `imulog process` command needs an entry here (and so a check of its defaults)."""
    group = _command(("process",))
    names = set(group.list_commands(click.Context(group)))  # type: ignore[attr-defined]
    assert names == {p[1] for p in DEFAULTS if p[0] == "process"}


@pytest.mark.parametrize("path", sorted(DEFAULTS), ids=" ".join)
def test_command_line_defaults_equal_the_python_and_batch_defaults(path):
    step, mapping = DEFAULTS[path]
    cmd = _command(path)
    kwargs, params = _python_defaults(step)
    undeclared, wrong = [], []
    for option in cmd.params:
        if not isinstance(option, click.Option) or option.name in CLI_ONLY:
            continue
        if option.name in FROM_TRIAL.get(path, set()):
            assert option.default is None, f"--{option.name} must default to the trial's own value (None)"
            continue
        if option.name not in mapping:
            undeclared.append(option.name)
            continue
        if mapping[option.name] == "required":
            assert option.required and STEPS[step].required, f"--{option.name} is required in both or in neither"
            continue
        expected = mapping[option.name](kwargs, params)
        got = _cli_default(cmd, option)
        if got != expected and not (isinstance(got, float) and got == pytest.approx(expected)):
            wrong.append(f"--{option.name.replace('_', '-')}: command line {got!r}, Python/batch {expected!r}")
    assert not undeclared, f"imulog {' '.join(path)}: options without a Python counterpart: {undeclared}"
    assert not wrong, f"imulog {' '.join(path)}: " + "; ".join(wrong)


def test_metrics_command_defaults_match_when_run():
    """`process metrics` builds the same MetricsParams as the batch when no option is given (noise options are
    None on the command line so that --static can fill them)."""
    from imulog.steps.metrics import MetricsParams

    _, params = _python_defaults("metrics")
    assert params == MetricsParams()
