"""Which accelerometer the trajectory step integrates: a preset over :class:`TrajectoryParams` (issue 31 point 2).

* ``"recorded"`` (the default): the orientation step's gravity-free acceleration, from the accelerometer as
  recorded (or as a calibration file corrected it);
* ``"rests"``: the twelfth round's combination (docs/accuracy.md, ``benchmarks/trajectory_paired.py --change
  rest-tilt-acc-rests-scatter``): the accelerometer's bias and sensitivity matrix estimated from the trial's own
  rests (``TrajectoryParams.acc_rests``), the orientation filter re-run on the corrected accelerometer, each rest's
  tilt from the corrected accelerometer (``AnchorParams.rest_tilt = "accelerometer"``), the start's rotating-bias
  compensation under the calibration's posterior and held-out share (``RotatingBiasParams.calibration_prior``,
  ``held_out``), the start trusted as far as its closure says (``OptimizationParams.corrected_floor_m``, 2 mm) and
  the reference's ends in x and y no more than the hand's own scatter (``OptimizationParams.reference_scatter``).

Every part is an existing option; this module only names the combination, so the command line, the batch and the
benchmarks build it in one place.
"""

from __future__ import annotations

from dataclasses import replace

from imulog.process.trajectory_methods import TrajectoryParams

ACCELEROMETERS = ("recorded", "rests")
CORRECTED_FLOOR_M = 0.002  # the start's static trust floor on a corrected accelerometer (tenth round), m


def with_accelerometer(params: TrajectoryParams, accelerometer: str) -> TrajectoryParams:
    """``params`` with the preset ``accelerometer`` (one of :data:`ACCELEROMETERS`); ``"recorded"`` leaves them
    as they are."""
    if accelerometer not in ACCELEROMETERS:
        raise ValueError(f"accelerometer must be one of {', '.join(ACCELEROMETERS)}, got {accelerometer!r}")
    if accelerometer == "recorded":
        return params
    return replace(
        params,
        acc_rests=replace(params.acc_rests, enabled=True),
        anchor=replace(params.anchor, rest_tilt="accelerometer"),
        rotating_bias=replace(params.rotating_bias, calibration_prior=True, held_out=True),
        optimized=replace(params.optimized, corrected_floor_m=CORRECTED_FLOOR_M, reference_scatter=(True, True, False)),
    )


def accelerometer_of(params: TrajectoryParams) -> str:
    """The preset name ``params`` use: ``"rests"`` when the accelerometer is corrected from the rests, else
    ``"recorded"`` (what ``imulog process trajectory --accelerometer`` defaults to)."""
    return "rests" if params.acc_rests.enabled else "recorded"
