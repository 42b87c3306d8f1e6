"""Named conditions of the accuracy grid: simulator overrides that make drinking trials as varied as real ones.

Each condition is a dict of :func:`imulog.simulate.simulate` overrides; sources and reasoning are in
docs/simulate.md ("Conditions of the accuracy grid"). The tests run a small slice, the benchmarks
(``benchmarks/segmentation_accuracy.py``, ``benchmarks/trajectory_accuracy.py``) the whole grid.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

ROTATION_EARLY = {"rotation_onset_frac": (0.0, 0.15), "rotation_end_frac": (0.6, 0.85)}
CURVED = {"curve_m": (0.02, 0.08), "curve_peak": (0.3, 0.7)}
PLACEMENTS = {"placement_jitter_m": 0.05, "mouth_jitter_m": 0.03}
PAUSES = {"pause_probability": 0.4, "submovements": (1, 2)}
STROKE = {
    "slowness": 1.5,
    "submovements": (2, 4),
    "submovement_overlap": (0.3, 0.7),
    "pause_probability": 0.2,
    "duration_jitter": 0.25,
    "position_jitter_m": 0.02,
    "rotation_end_frac": (0.7, 1.0),
}
UNCALIBRATED = {
    "acc_bias_sd_mps2": 0.3,
    "gyr_bias_sd_dps": 3.0,
    "scale_sd": 0.02,
    "misalignment_sd_deg": 1.0,
    "acc_bias_drift_mps2": 0.05,
    "gyr_bias_drift_dps": 0.5,
}
CLOCK = {"imu_rate_hz": 115.0, "drift_ppm": 100.0}
OCCLUSION = {"gap_rate_per_min": 6.0, "gap_duration_s": (0.1, 1.5)}

CONDITIONS: dict[str, dict[str, Any]] = {
    "default": {},
    "rotation-early": ROTATION_EARLY,
    "curved": CURVED,
    "placements": PLACEMENTS,
    "pauses": PAUSES,
    "stroke": STROKE,
    "residual-velocity": {"residual_velocity_mps": 0.01, "extra_submovement_probability": 0.2},
    "uncalibrated": UNCALIBRATED,
    "clock-occlusion": {**CLOCK, **OCCLUSION},
    "rate-50hz": {"imu_rate_hz": 50.0},
    "rate-200hz": {"imu_rate_hz": 200.0},
    # like the independent simulation of issue 19: curved, skewed, rotation ending early, uncalibrated, 115 Hz
    # with clock drift, occluded markers, other placements
    "combined": {**ROTATION_EARLY, **CURVED, **PLACEMENTS, **UNCALIBRATED, **CLOCK, **OCCLUSION},
    "combined-stroke": {**ROTATION_EARLY, **CURVED, **PLACEMENTS, **UNCALIBRATED, **CLOCK, **OCCLUSION, **STROKE},
}

# The median real wrist IMU's white noise per sample at the simulator's 114.9 Hz (benchmarks/device_noise.py over
# the shared real recordings; docs/simulate.md "The noise level against real devices"): the accelerometer 1.6x the
# simulator's default (0.02 m/s^2), the gyroscope 0.6x (0.1 deg/s).
DEVICE_NOISE = {"acc_noise_mps2": 0.033, "gyr_noise_dps": 0.062}

# Conditions at a real device's noise, by name but outside CONDITIONS (``all``), so the grid's earlier figures keep
# their rows: the benchmarks ask for them by name (``segmentation_accuracy.py --grid devices`` adds ``stroke-slow``).
DEVICE_CONDITIONS: dict[str, dict[str, Any]] = {
    "device-noise": dict(DEVICE_NOISE),
    "stroke-device-noise": {**STROKE, **DEVICE_NOISE},
}


def condition(name: str) -> dict[str, Any]:
    """Overrides of condition ``name`` (of :data:`CONDITIONS` or :data:`DEVICE_CONDITIONS`); ValueError naming the
    valid ones otherwise."""
    known = {**CONDITIONS, **DEVICE_CONDITIONS}
    if name not in known:
        raise ValueError(f"unknown condition {name!r}; choose one of {', '.join(known)}")
    return dict(known[name])


def grid(
    conditions: list[str] | None = None, seeds: range = range(2), subjects: range = range(2)
) -> Iterator[tuple[str, int, int, dict[str, Any]]]:
    """(condition, seed, subject, overrides) over the grid, condition-major."""
    for name in conditions or list(CONDITIONS):
        options = condition(name)
        for seed in seeds:
            for subject in subjects:
                yield name, seed, subject, options
