"""Clinical metrics (pure numpy): arm usage, activity counts, distance histograms, smoothness, timings.

See ``docs/metrics.md`` for formulas, parameters with their published defaults, and references.
"""

from imulog.process.metrics.activity import (
    ActivityCount,
    ActivityCountParams,
    activity_count_dead_period,
    activity_count_sign,
    dead_period_intervals,
    estimate_noise_floor,
)
from imulog.process.metrics.arm_usage import (
    ArmUsage,
    ArmUsageParams,
    NoiseLevel,
    acc_to_g,
    adc_to_g,
    arm_usage,
    estimate_noise_level,
    to_reference_rate,
)
from imulog.process.metrics.distance import (
    DistanceHistogram,
    DistanceHistogramParams,
    average_consecutive,
    distance_histogram,
    progress_areas,
    weighted_area,
)
from imulog.process.metrics.smoothness import (
    Smoothness,
    SparcParams,
    VelocityPeakParams,
    log_dimensionless_jerk,
    normalized_jerk,
    smoothness,
    sparc,
    velocity_peaks,
)
from imulog.process.metrics.timings import (
    NhptParams,
    NhptTimings,
    compare_durations,
    nhpt_timings,
    phase_summary,
    phase_table,
    repetition_durations,
)

__all__ = [
    "ActivityCount",
    "ActivityCountParams",
    "ArmUsage",
    "ArmUsageParams",
    "DistanceHistogram",
    "DistanceHistogramParams",
    "NhptParams",
    "NhptTimings",
    "NoiseLevel",
    "Smoothness",
    "SparcParams",
    "VelocityPeakParams",
    "acc_to_g",
    "activity_count_dead_period",
    "activity_count_sign",
    "adc_to_g",
    "arm_usage",
    "average_consecutive",
    "compare_durations",
    "dead_period_intervals",
    "distance_histogram",
    "estimate_noise_floor",
    "estimate_noise_level",
    "log_dimensionless_jerk",
    "nhpt_timings",
    "normalized_jerk",
    "phase_summary",
    "phase_table",
    "progress_areas",
    "repetition_durations",
    "smoothness",
    "sparc",
    "to_reference_rate",
    "velocity_peaks",
    "weighted_area",
]
