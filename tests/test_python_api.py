"""imulog as a library (docs/python.md): every command has a documented, typed Python entry point; parameter objects
refuse bad values naming the field and its unit, and the CLI prints the same line; a recorded run gives its
parameter object back; a step's error names the trial, as the command's line does."""

from __future__ import annotations

import importlib
import inspect
import re
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from imulog.archive import ArchiveError, TrialReader, write_trial
from imulog.batch import run_params
from imulog.batch.registry import STEPS, _load
from imulog.cli import PROCESS_COMMANDS, TOP_LEVEL_COMMANDS, cli
from imulog.params import ParamError, params_from_dict, params_to_dict
from imulog.process.alignment_params import AlignmentParams
from imulog.process.orientation import OrientationParams, StaticParams
from imulog.steps.common import StepError
from imulog.steps.epochs import EpochParams
from imulog.steps.metrics import MetricsParams
from imulog.steps.orientation import run_orientation

PAGE = Path(__file__).resolve().parents[1] / "docs" / "python.md"
_ROW = re.compile(r"^\| `([a-z ]+)` \| (.+?) \|")


def _table() -> dict[str, str]:
    return {m.group(1): m.group(2) for line in PAGE.read_text().splitlines() if (m := _ROW.match(line))}


def _resolve(dotted: str):
    """``imulog.a.b.name`` -> the object (the longest importable module prefix, then attributes)."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for name in parts[i:]:
            obj = getattr(obj, name)
        return obj
    raise ImportError(dotted)


def test_every_command_has_a_typed_python_entry_point():
    table = _table()
    commands = [*TOP_LEVEL_COMMANDS, *(f"process {name}" for name in PROCESS_COMMANDS)]
    assert sorted(set(commands) - set(table)) == []  # the page names every command
    for command in commands:
        names = re.findall(r"`(imulog\.[\w.]+)`", table[command])
        if command == "demo":
            assert table[command].startswith("none:")
            continue
        assert names, command
        for dotted in names:
            obj = _resolve(dotted)
            if inspect.isclass(obj) or not callable(obj):
                continue
            sig = inspect.signature(obj)  # follows functools.wraps to the function itself
            untyped = [n for n, p in sig.parameters.items() if p.annotation is inspect.Parameter.empty]
            assert untyped == [], f"{command}: {dotted} has untyped parameters {untyped}"
            assert sig.return_annotation is not inspect.Parameter.empty, f"{command}: {dotted} has no return type"


def test_the_export_targets_are_the_commands():
    import imulog.export
    from imulog.commands.archive import export

    choices = next(p.type.choices for p in export.params if p.name == "target")
    assert set(imulog.export.TARGETS) == set(choices)
    for target in set(choices) - {"parquet", "csv"}:  # one function each (parquet and csv: export_table)
        assert callable(getattr(imulog.export, f"export_{target}"))


@pytest.mark.parametrize(
    ("make", "line"),
    [
        (lambda: OrientationParams(beta=-1.0), "OrientationParams.beta: must be finite and > 0 (rad/s), got -1.0"),
        (lambda: OrientationParams(beta="0.1"), "OrientationParams.beta: must be float (rad/s), got '0.1'"),
        (lambda: OrientationParams(backend="vqf-offline"), "OrientationParams.backend: must be one of"),
        (lambda: OrientationParams(imufusion_gain=float("nan")), "OrientationParams.imufusion_gain: must be finite"),
        (lambda: StaticParams(threshold_rad_s=0.0), "StaticParams.threshold_rad_s: must be finite and > 0 (rad/s)"),
        (lambda: StaticParams(min_duration_s=-0.5), "StaticParams.min_duration_s: must be finite and >= 0 (s)"),
        (lambda: OrientationParams(static={"threshold_rad_s": 0.2}), "OrientationParams.static: must be StaticParams"),
        (
            lambda: EpochParams(epochs_s=(60.0, 0.0)),
            "EpochParams.epochs_s: must be finite and > 0 (s), got (60.0, 0.0)",
        ),
        (lambda: EpochParams(valid_day_hours=-1.0), "EpochParams.valid_day_hours: must be finite and >= 0 (h)"),
        (lambda: AlignmentParams(window_s=0.0), "AlignmentParams.window_s: must be finite and > 0 (s), got 0.0"),
        (lambda: AlignmentParams(max_lag_s=-1.0), "AlignmentParams.max_lag_s: must be finite and >= 0 (s)"),
        (lambda: AlignmentParams(cluster="OXY"), "AlignmentParams.cluster: must be one of auto, oxy, svd, got 'OXY'"),
        (lambda: MetricsParams(acc_unit="m/s2"), "MetricsParams.acc_unit: must be one of g, m/s^2, got 'm/s2'"),
        (lambda: MetricsParams(noise_level_g=-0.02), "MetricsParams.noise_level_g: must be finite and >= 0 (g)"),
    ],
)
def test_parameter_objects_refuse_bad_values_naming_field_and_unit(make, line):
    with pytest.raises(ParamError) as err:
        make()
    assert str(err.value).startswith(line)
    assert isinstance(err.value, ValueError)


def test_every_steps_parameter_object_goes_to_a_dict_and_back():
    for spec in STEPS.values():
        if spec.params_class is None:
            continue
        cls = _load(spec.params_class)
        assert params_from_dict(cls, params_to_dict(cls())) == cls(), spec.name
    assert EpochParams(epochs_s=[10, 60]).epochs_s == (10, 60)  # a list is taken as the tuple it stands for
    changed = params_from_dict(OrientationParams, {"backend": "madgwick", "static": {"threshold_rad_s": 0.2}})
    assert changed == OrientationParams(backend="madgwick", static=StaticParams(threshold_rad_s=0.2))
    with pytest.raises(ValueError, match="unknown option 'betta'.*fields: backend, beta"):
        params_from_dict(OrientationParams, {"betta": 0.1})


def test_a_parameter_object_goes_into_the_batch_options_as_its_dict():
    """``imulog.batch.run(options={step: params_to_dict(params)})`` runs with ``params``; before, phases' alias
    ``repetitions`` (the count) took the nested RepetitionParams dict as the count itself, silently."""
    from imulog.batch.registry import resolve_options
    from imulog.process.segmentation.pipeline import PhaseParams

    for spec in STEPS.values():
        if spec.params_class is not None:
            cls = _load(spec.params_class)
            assert resolve_options(spec.name, params_to_dict(cls()))[1] == cls(), spec.name
    phases = PhaseParams(static_margin_s=0.2)
    assert resolve_options("phases", params_to_dict(phases))[1] == phases
    assert resolve_options("phases", {"repetitions": {"n_repetitions": 5}})[1].repetitions.n_repetitions == 5
    assert resolve_options("phases", {"repetitions": "7"})[1].repetitions.n_repetitions == 7  # the alias still


@pytest.fixture(scope="module")
def trial(tmp_path_factory) -> Path:
    from imulog.simulate import simulate

    path = tmp_path_factory.mktemp("api") / "trial.mcap"
    write_trial(path, simulate("r2g", subject=0, trial=0, seed=3, repetitions=2).recording)
    return path


def test_the_cli_prints_the_parameter_objects_line_naming_the_option(trial):
    """The command line names the option typed (declared where its name is not the field's, else click's
    parameter name); the Python API names the field (test above)."""
    with TrialReader(trial) as t:
        runs_before = len(t.runs())
    for step, option, value, line in (
        ("orientation", "--static-threshold", "-1", "--static-threshold: must be finite and > 0 (rad/s), got -1.0"),
        ("orientation", "--static-min-s", "-0.5", "--static-min-s: must be finite and >= 0 (s), got -0.5"),
        ("orientation", "--beta", "0", "--beta: must be finite and > 0 (rad/s), got 0.0"),
        ("epochs", "--epoch-s", "0", "--epoch-s: must be finite and > 0 (s), got (0.0,)"),
        ("align", "--window", "0", "--window: must be finite and > 0 (s), got 0.0"),
        ("phases", "--static-threshold", "0", "--static-threshold: must be finite and > 0 (rad/s), got 0.0"),
        ("phases", "--repetitions", "-2", "--repetitions: must be finite and >= 0, got -2"),
        ("trajectory", "--kalman-q", "0", "--kalman-q: must be finite and > 0 (m^2/s^4), got 0.0"),
    ):
        result = CliRunner().invoke(cli, ["process", step, str(trial), option, value])
        assert result.exit_code == 1, result.output
        assert result.output.strip() == f"Error: {line}"
        assert result.exception is None or isinstance(result.exception, SystemExit)  # no traceback
    with TrialReader(trial) as t:
        assert len(t.runs()) == runs_before  # nothing computed, nothing written


def test_a_recorded_run_gives_its_parameter_object_back(trial):
    from imulog.process.segmentation.pipeline import PhaseParams
    from imulog.steps.phases import run_phases

    params = OrientationParams(backend="madgwick", beta=0.07, static=StaticParams(threshold_rad_s=0.15))
    outcome = run_orientation(trial, params=params)
    phases = run_phases(trial, params=PhaseParams(static_margin_s=0.2))
    with TrialReader(trial) as t:
        runs = t.runs()
    rebuilt, rest = run_params(runs[outcome.run])
    assert rebuilt == params and rest["imu"] == "wrist" and "global_frame" in rest
    assert run_orientation(trial, imu=rest["imu"], params=rebuilt).skipped
    assert run_orientation(trial, imu="/imu/wrist", params=rebuilt).skipped  # the topic names the IMU too
    rebuilt_phases, rest = run_params(runs[phases.run])
    assert isinstance(rebuilt_phases, PhaseParams) and rebuilt_phases.static_margin_s == 0.2
    assert run_phases(trial, imu=rest["imu"], params=rebuilt_phases).skipped  # the run, repeated exactly
    with pytest.raises(ValueError, match="not a registered step"):
        run_params({"step": "manual", "params": {}})


def test_a_steps_error_names_the_trial_as_the_command_does(trial, tmp_path):
    with pytest.raises(StepError) as err:
        run_orientation(trial, imu="ankle")
    assert str(err.value) == f"{trial}: no channel /imu/ankle in the trial (/imu/* channels: wrist)"
    assert isinstance(err.value, ValueError) and err.value.path == trial
    result = CliRunner().invoke(cli, ["process", "orientation", str(trial), "--imu", "ankle"])
    assert result.exit_code == 1 and result.output.strip() == f"Error: {err.value}"
    with pytest.raises(
        TypeError, match=r"run_orientation: params must be OrientationParams \(a parameter object\), got a dict; imulog"
    ):
        run_orientation(trial, params={"beta": 0.1})  # was: asdict() should be called on dataclass instances
    with pytest.raises(ArchiveError, match=re.escape(str(tmp_path / "none.mcap"))):  # archive errors: unchanged
        run_orientation(tmp_path / "none.mcap")


def test_a_field_no_option_sets_keeps_its_name_on_the_command_line():
    from imulog.commands.option_fields import option_fields, option_line

    command = option_fields(threshold="StaticParams.threshold_rad_s")(
        click.Command("x", params=[click.Option(["--threshold"]), click.Option(["--beta", "-b"])])
    )
    static = ParamError("StaticParams", "threshold_rad_s", "must be finite and > 0", -1.0, "rad/s")
    assert option_line(static, command) == "--threshold: must be finite and > 0 (rad/s), got -1.0"
    beta = ParamError("OrientationParams", "beta", "must be finite and > 0", 0.0, "rad/s")
    assert option_line(beta, command) == "--beta: must be finite and > 0 (rad/s), got 0.0"
    other = ParamError("StaticParams", "min_duration_s", "must be finite and >= 0", -1.0, "s")
    assert (
        option_line(other, command)
        == str(other)
        == "StaticParams.min_duration_s: must be finite and >= 0 (s), got -1.0"
    )
    assert option_line(other, None) == str(other)
