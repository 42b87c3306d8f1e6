"""The segmentation's, the trajectory's, the kinematics' and the alignment's parts' parameter objects check their
values when made (imulog.param_rules, docs/python.md "Errors"), and no option the benchmarks use is refused."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import pytest

from imulog.param_rules import RULES, check_rules
from imulog.params import ParamError
from imulog.process.acc_rest_calibration import MODELS, AccRestParams
from imulog.process.alignment_frames import FilterParams
from imulog.process.alignment_search import SearchParams
from imulog.process.drift import HighpassParams, WaveletParams
from imulog.process.integration import AnchorParams, DdiParams, RotatingBiasParams, ZuptParams
from imulog.process.kalman import KalmanParams
from imulog.process.kinematics.solver import SolverParams
from imulog.process.rests import RestParams
from imulog.process.segmentation.boundaries import BoundaryParams
from imulog.process.segmentation.double_threshold import DoubleThresholdParams
from imulog.process.segmentation.dynamos import DynamosParams
from imulog.process.segmentation.hand_params import HandParams
from imulog.process.segmentation.pipeline import METHODS, PROTOCOLS, PhaseParams
from imulog.process.segmentation.repetitions import RepetitionParams
from imulog.process.segmentation.template import TemplateParams
from imulog.process.segmentation.zero_velocity import GyroNormStaticParams
from imulog.process.trajectory_checks import CheckParams
from imulog.process.trajectory_methods import TrajectoryParams
from imulog.process.trajectory_optimize import OptimizationParams
from imulog.steps.kinematics import KinematicsOptions

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

#: one bad value per object: (the object, its field, the bad value, the line's start)
BAD = [
    (PhaseParams, "method", "dynamo", "PhaseParams.method: must be one of dynamos, double-threshold, template"),
    (PhaseParams, "static_margin_s", -0.1, "PhaseParams.static_margin_s: must be finite and >= 0 (s), got -0.1"),
    (DynamosParams, "cutoff_hz", 0.0, "DynamosParams.cutoff_hz: must be finite and > 0 (Hz), got 0.0"),
    (DynamosParams, "threshold", None, "DynamosParams.threshold: must be float | str"),
    (DoubleThresholdParams, "t1", -1.0, "DoubleThresholdParams.t1: must be finite and >= 0 (rad/s), got -1.0"),
    (TemplateParams, "n_matches", -1, "TemplateParams.n_matches: must be finite and >= 0, got -1"),
    (RepetitionParams, "n_repetitions", 2.5, "RepetitionParams.n_repetitions: must be int, got 2.5"),
    (RepetitionParams, "split", "gaps", "RepetitionParams.split: must be one of activity, movements, got 'gaps'"),
    (BoundaryParams, "max_shift_s", -0.3, "BoundaryParams.max_shift_s: must be finite and >= 0 (s), got -0.3"),
    (HandParams, "velocity_level_mps", -0.03, "HandParams.velocity_level_mps: must be finite and >= 0 (m/s)"),
    (HandParams, "profile_durations_s", (0.5, -8.0), "HandParams.profile_durations_s: must be finite and >= 0 (s)"),
    (GyroNormStaticParams, "metric", "median", "GyroNormStaticParams.metric: must be one of mean, max"),
    (DdiParams, "remove_mean", "yes", "DdiParams.remove_mean: must be bool, got 'yes'"),
    (ZuptParams, "min_static_samples", -1, "ZuptParams.min_static_samples: must be finite and >= 0, got -1"),
    (HighpassParams, "cutoff_hz", float("nan"), "HighpassParams.cutoff_hz: must be finite and > 0 (Hz), got nan"),
    (WaveletParams, "level", 0, "WaveletParams.level: must be finite and > 0, got 0"),
    (KalmanParams, "process_var_m2ps4", 0.0, "KalmanParams.process_var_m2ps4: must be finite and > 0 (m^2/s^4)"),
    (RotatingBiasParams, "outlier_factor", -3.0, "RotatingBiasParams.outlier_factor: must be finite and > 0"),
    (OptimizationParams, "sigma_data_mps", (0.02, 0.0, 0.02), "OptimizationParams.sigma_data_mps: must be finite"),
    (AnchorParams, "rest_tilt", "gravity", "AnchorParams.rest_tilt: must be one of filter, accelerometer"),
    (RestParams, "window_s", 0.0, "RestParams.window_s: must be finite and > 0 (s), got 0.0"),
    (CheckParams, "max_bias_mps2", -1.0, "CheckParams.max_bias_mps2: must be finite and >= 0 (m/s^2), got -1.0"),
    (AccRestParams, "model", "affine", "AccRestParams.model: must be one of bias, scale, matrix, got 'affine'"),
    (TrajectoryParams, "zupt", "zupt", "TrajectoryParams.zupt: must be ZuptParams, got 'zupt'"),
    (KinematicsOptions, "calibration_mode", "none", "KinematicsOptions.calibration_mode: must be one of heading"),
    (KinematicsOptions, "neutral_window_s", (-1.0, 2.0), "KinematicsOptions.neutral_window_s: must be finite and"),
    (SolverParams, "max_iterations", 0, "SolverParams.max_iterations: must be finite and > 0, got 0"),
    (FilterParams, "order", 0, "FilterParams.order: must be finite and > 0, got 0"),
    (SearchParams, "min_distance_m", -0.01, "SearchParams.min_distance_m: must be finite and >= 0 (m), got -0.01"),
]


@pytest.mark.parametrize(("cls", "name", "value", "line"), BAD, ids=[f"{c.__name__}.{n}" for c, n, _, _ in BAD])
def test_a_bad_value_is_refused_when_the_object_is_made(cls, name, value, line):
    with pytest.raises(ParamError) as err:
        cls(**{name: value})
    assert str(err.value).startswith(line)
    with pytest.raises(ParamError):  # dataclasses.replace makes the object anew: the same check
        dataclasses.replace(cls(), **{name: value})


def _objects(obj) -> list:
    """``obj`` and every parameter object it holds, depth first."""
    out = [obj]
    for f in dataclasses.fields(obj):
        if dataclasses.is_dataclass(value := getattr(obj, f.name)):
            out.extend(_objects(value))
    return out


def test_every_object_of_the_table_checks_itself_and_every_rule_names_real_fields():
    classes = {type(o) for top in (PhaseParams(), TrajectoryParams(), KinematicsOptions()) for o in _objects(top)}
    classes |= {FilterParams, SearchParams}
    checked = {c.__name__ for c in classes if c.__dict__.get("__post_init__") is check_rules}
    assert set(RULES) <= checked, f"in RULES but not checking: {set(RULES) - checked}"
    unchecked = {c.__name__ for c in classes if "__post_init__" not in c.__dict__}
    assert not unchecked, f"parameter objects that do not check themselves: {unchecked}"
    by_name = {c.__name__: c for c in classes}
    for name, rule in RULES.items():
        fields = {f.name for f in dataclasses.fields(by_name[name])}
        named = {*rule.get("positive", ()), *rule.get("non_negative", ()), *rule.get("choices", {})}
        assert named <= fields, f"{name}: no fields {named - fields}"


def test_the_tables_choices_are_the_modules_own():
    assert tuple(RULES["PhaseParams"]["choices"]["method"]) == METHODS
    assert tuple(RULES["PhaseParams"]["choices"]["protocol"]) == PROTOCOLS
    assert tuple(RULES["AccRestParams"]["choices"]["model"]) == tuple(MODELS)


def test_defaults_and_every_benchmark_option_still_construct():
    """The defaults, every ``--change`` of benchmarks/trajectory_paired.py and every grid method of
    benchmarks/segmentation_accuracy.py pass their own checks (made again field by field, nested objects too)."""
    sys.path.insert(0, str(BENCHMARKS))
    from segmentation_accuracy import GRID_METHODS
    from trajectory_paired import CHANGES

    made = [PhaseParams(), TrajectoryParams(), KinematicsOptions(), FilterParams(), SearchParams()]
    made += list(GRID_METHODS.values()) + [p for pair in CHANGES.values() for p in pair]
    assert len(made) == 5 + len(GRID_METHODS) + 2 * len(CHANGES) and len(CHANGES) > 40
    for top in made:
        for obj in _objects(top):
            check_rules(obj)
            assert dataclasses.replace(obj) == obj
