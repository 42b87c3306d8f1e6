"""The bounds and choices of the parameter objects that check themselves through a table (docs/python.md).

A class opts in with ``__post_init__ = check_rules``: :func:`check_rules` calls :func:`imulog.params.check_params`
with the rule of the class's name in :data:`RULES` (the types of its annotations are checked for every class;
units come from the field names). The table keeps the bounds out of modules near the 500-line limit. Choices are
written out here (this module sits below the process layer); ``tests/test_param_rules.py`` compares them with the
modules' own lists (``METHODS``, ``PROTOCOLS``, ``MODELS``). Bounds refuse only what no step can use: a
cut-off, an order, a rate or a standard deviation of 0 or less, a negative duration, count or fraction. A field
that may be None (off) is checked only when it is a number.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any, TypedDict

from imulog.params import check_params


class Rule(TypedDict, total=False):
    """The keyword arguments of :func:`imulog.params.check_params` for one class."""

    positive: Collection[str]
    non_negative: Collection[str]
    choices: Mapping[str, Collection[Any]]
    units: Mapping[str, str]


#: {class name: its rule}; a class not listed is checked for its fields' types only
RULES: dict[str, Rule] = {
    # segmentation (imulog.process.segmentation)
    "PhaseParams": {
        "non_negative": ("static_margin_s", "template_pad_s"),
        "choices": {
            "method": ("dynamos", "double-threshold", "template"),
            "protocol": ("r2g", "movements"),
            "static": ("movements", "gyro-norm"),
        },
    },
    "DynamosParams": {
        "positive": ("cutoff_hz", "filter_order", "alpha", "beta", "max_iterations"),
        "non_negative": (
            "min_movement_s",
            "refine_level",
            "continuation_s",
            "continuation_level",
            "continuation_peak_fraction",
        ),
    },
    "DoubleThresholdParams": {
        "positive": ("frame_s", "hop_s"),
        "non_negative": ("t1", "t2", "t3", "zcr_extension_s", "min_movement_s", "min_rest_s"),
        "units": {"t1": "rad/s", "t2": "rad/s", "t3": "rad/s"},
    },
    "TemplateParams": {"non_negative": ("min_distance_fraction", "n_matches")},
    "RepetitionParams": {
        "positive": ("n_phases", "max_candidates"),
        "non_negative": (
            "n_repetitions",
            "activity_fraction",
            "major_fraction",
            "extra_cut_fraction",
            "continuation_gap_s",
            "extra_groups",
            "burst_gap_s",
            "burst_min_movements",
            "min_height_fraction",
            "rescue_fraction",
        ),
        "choices": {"split": ("activity", "movements")},
    },
    "BoundaryParams": {
        "positive": ("cutoff_hz", "min_cutoff_hz", "n_sigma"),
        "non_negative": (
            "target_level_rad_s",
            "static_window_s",
            "min_static_s",
            "guard_s",
            "min_level_rad_s",
            "strong_fraction",
            "max_shift_s",
            "continuation_s",
            "continuation_peak_fraction",
        ),
    },
    "HandParams": {
        "positive": ("cutoff_hz", "min_cutoff_hz", "n_sigma", "profile_grid_hz", "flank_noise_band_hz"),
        "non_negative": (
            "target_level_mps2",
            "rest_window_s",
            "rest_distance_s",
            "guard_s",
            "min_level_mps2",
            "velocity_level_mps",
            "quiet_s",
            "min_run_s",
            "max_shift_s",
            "continuation_s",
            "continuation_n_level",
            "cruise_velocity_mps",
            "bridge_n_level",
            "flank_top_n_level",
            "flank_search_s",
            "max_extrapolation_s",
            "speed_fit_s",
            "rest_check_s",
            "speed_reach_s",
            "profile_rest_s",
            "profile_durations_s",
            "profile_min_s",
        ),  # not profile_residual_ratio: inf turns step 9's residual check off (a finite bound would refuse it)
    },
    "GyroNormStaticParams": {
        "positive": ("threshold_rad_s", "window_s"),
        "non_negative": ("min_static_s",),
        "choices": {"metric": ("mean", "max")},
    },
    # trajectory (imulog.process.trajectory_methods.TrajectoryParams and its parts)
    "ZuptParams": {"non_negative": ("min_static_samples",)},
    "HighpassParams": {"positive": ("cutoff_hz", "order")},
    "WaveletParams": {"positive": ("level",), "non_negative": ("trend_details",)},
    "KalmanParams": {
        "positive": ("process_var_m2ps4", "meas_var_m2ps4", "zero_velocity_var_m2ps2"),
        "non_negative": ("alpha", "init_var"),
        "units": {"init_var": "m^2, (m/s)^2, (m/s^2)^2"},
    },
    "RotatingBiasParams": {
        "positive": ("gravity_mps2", "outlier_factor"),
        "non_negative": ("rest_s", "min_movements", "outlier_refits"),
    },
    "OptimizationParams": {
        "positive": (
            "sigma_data_mps",
            "sigma_ref_static_m",
            "sigma_ref_moving_m",
            "sigma_symmetry_m",
            "sigma_static_vel_mps",
        ),
        "non_negative": ("max_heading_deg", "closure_factor", "corrected_floor_m"),
    },
    "AnchorParams": {
        "positive": ("max_movement_s",),
        "non_negative": ("bias_window_s",),
        "choices": {
            "spread": ("time", "angle", "mixed", "none"),
            "heading": ("filter", "gyroscope"),
            "rest_tilt": ("filter", "accelerometer"),
        },
    },
    "RestParams": {
        "positive": ("window_s", "long_window_s", "k_noise"),
        "non_negative": (
            "min_std_mps2",
            "max_mean_mps2",
            "short_max_mean_mps2",
            "short_s",
            "mean_relative",
            "min_rest_s",
            "run_mean_max_s",
        ),
    },
    "CheckParams": {
        "non_negative": (
            "max_without_rest_s",
            "max_bias_mps2",
            "max_matrix",
            "limit_z",
            "max_offset_mps2",
            "max_removed_share",
            "min_motion_m",
        ),
    },
    "AccRestParams": {
        "non_negative": (
            "min_rest_s",
            "trim_s",
            "max_rest_sd_mps2",
            "min_rests",
            "min_spread_deg",
            "max_gap_s",
            "bias_prior_mps2",
            "scale_prior",
            "misalignment_prior_deg",
            "reading_sd_mps2",
            "gyro_angle_sd_rad",
            "gyro_scale_sd",
            "gyro_bias_window_s",
            "max_bias_sd_mps2",
        ),
        "choices": {"model": ("bias", "scale", "matrix")},
    },
    # kinematics (imulog.steps.kinematics)
    "KinematicsOptions": {
        "non_negative": ("neutral_window_s",),
        "choices": {"calibration_mode": ("heading", "full")},
    },
    "SolverParams": {
        "positive": ("max_iterations", "qp_sweeps"),
        "non_negative": ("step_tol_rad", "feasibility_tol_m", "initial_damping", "penalty", "restarts"),
    },
    # alignment (imulog.process.alignment_params.AlignmentParams's parts)
    "FilterParams": {"positive": ("cutoff_hz", "order"), "non_negative": ("max_gap_s",)},
    "SearchParams": {
        "positive": ("coarse_hz", "rigidity_frames", "max_triads", "refine"),
        "non_negative": (
            "max_distance_sd_m",
            "max_relative_sd",
            "min_distance_m",
            "min_height_m",
            "min_visible",
            "min_vector_match",
            "extend_sd_factor",
            "extend_floor_m",
        ),
    },
}


def check_rules(obj: Any) -> None:
    """Check dataclass ``obj`` by its class's rule in :data:`RULES` (its types alone when it has none): raises
    :class:`imulog.params.ParamError` naming the class, the field and the unit."""
    check_params(obj, **RULES.get(type(obj).__name__, {}))
