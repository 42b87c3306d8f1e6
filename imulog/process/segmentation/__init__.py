"""Segmentation of IMU trials: movements, R2G phases and repetitions, zero-velocity intervals.

Modules: :mod:`.dynamos` (DynAMoS), :mod:`.repetitions` (repetition splitting + event correction),
:mod:`.boundaries` (phase onsets/offsets against the static noise), :mod:`.hand` (boundaries that follow the
hand's translation, from the accelerometer),
:mod:`.double_threshold` (Bai et al.), :mod:`.template` (template matching), :mod:`.zero_velocity`.
"""

from imulog.process.segmentation.boundaries import BoundaryParams, refine_phase_boundaries
from imulog.process.segmentation.double_threshold import DoubleThresholdParams, double_threshold
from imulog.process.segmentation.dynamos import DynamosParams, Segmentation, dynamos, lowpass_norm, runs
from imulog.process.segmentation.hand import HandParams, refine_with_accelerometer
from imulog.process.segmentation.repetitions import Phases, RepetitionParams, segment_repetitions
from imulog.process.segmentation.template import TemplateParams, build_template, match_template
from imulog.process.segmentation.zero_velocity import (
    GyroNormStaticParams,
    gyro_norm_static,
    mask_from_intervals,
    static_from_movements,
)

__all__ = [
    "BoundaryParams",
    "DoubleThresholdParams",
    "DynamosParams",
    "GyroNormStaticParams",
    "HandParams",
    "Phases",
    "RepetitionParams",
    "Segmentation",
    "TemplateParams",
    "build_template",
    "double_threshold",
    "dynamos",
    "gyro_norm_static",
    "lowpass_norm",
    "mask_from_intervals",
    "match_template",
    "refine_phase_boundaries",
    "refine_with_accelerometer",
    "runs",
    "segment_repetitions",
    "static_from_movements",
]
