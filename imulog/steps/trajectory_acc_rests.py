"""The trajectory step's accelerometer corrected from the trial's own rests (``TrajectoryParams.acc_rests``, issue 31
point 2): pure functions, no I/O.

Where it belongs under the window contract (docs/trajectory.md, "The accelerometer corrected from the rests"): the
orientation step owns the filter, the phases step owns the rests, and the trajectory step reads both. The
calibration needs the rests, which the phases step finds after the orientation step has run, so the trajectory step
estimates it from its own window's rests (:func:`imulog.process.acc_rest_calibration.estimate`) and re-runs the
orientation step's own function (:func:`imulog.steps.orientation.orientation_with_gaps`, with the parameters that
step recorded) on the corrected accelerometer over the same window. Raw channels and the orientation step's channels
are left as they are; the trajectory record says which accelerometer, which filter and what the calibration found.
The re-run's global frame is turned about the vertical onto the orientation channel's (one constant heading, least
squares over the window), so the alignment's global-to-world rotation, fitted on that channel, still applies.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any

import numpy as np

from imulog.process import quaternion as quat
from imulog.process.acc_rest_calibration import AccRestCalibration, AccRestParams, estimate
from imulog.process.orientation import OrientationParams, StaticParams
from imulog.steps.orientation import orientation_with_gaps

ORIENTATION_ALGORITHM = "imulog.orientation."  # the orientation step's algorithm names start so


@dataclass(frozen=True)
class OrientationSource:
    """What the orientation step read and how it ran: the accelerometer ``acc_mps2`` (N, 3) m/s^2 and gyroscope
    ``gyr_rad_s`` (N, 3) rad/s at ``t_ns`` (int64 ns, device clock) from ``topic`` (``/imu/{imu}`` or
    ``/derived/calibrated/{imu}``) and the filter's ``params``."""

    t_ns: np.ndarray
    acc_mps2: np.ndarray
    gyr_rad_s: np.ndarray
    topic: str
    params: OrientationParams


@dataclass
class RestCalibrated:
    """The inputs on the corrected accelerometer: ``acc_global`` (N, 3) m/s^2 gravity-free and ``quat`` (N, 4)
    sensor-to-global, both in the orientation channel's global frame; ``acc_sensor`` (N, 3) m/s^2 the corrected
    accelerometer (sensor frame); ``calibration`` the estimate; ``record`` the trajectory record's entry."""

    acc_global: np.ndarray
    quat: np.ndarray
    acc_sensor: np.ndarray
    calibration: AccRestCalibration
    record: dict[str, Any]


def orientation_params_of(topic: str, metadata: dict[str, Any]) -> tuple[str, OrientationParams]:
    """``(input topic, OrientationParams)`` the orientation step recorded in the metadata of the channel ``topic``
    (``/derived/orientation/{imu}``); a one-line ValueError when another program wrote it."""
    algorithm = str(metadata.get("algorithm", ""))
    if not algorithm.startswith(ORIENTATION_ALGORITHM) or "params" not in metadata:
        raise ValueError(
            f"{topic} was not written by `imulog process orientation` (algorithm {algorithm or 'unknown'!r}): "
            "TrajectoryParams.acc_rests re-runs that step's filter with its recorded parameters"
        )
    params = json.loads(metadata["params"]) if isinstance(metadata["params"], str) else dict(metadata["params"])
    inputs = json.loads(metadata.get("inputs") or "{}") if isinstance(metadata.get("inputs"), str) else {}
    fields = {f.name for f in dataclasses.fields(OrientationParams)}
    kw = {k: v for k, v in params.items() if k in fields}
    if isinstance(kw.get("static"), dict):
        kw["static"] = StaticParams(**kw["static"])
    source = next(iter(inputs), "")
    return source, OrientationParams(**kw)


def rest_calibrated(
    t_ns: np.ndarray,
    t_s: np.ndarray,
    given_rest: np.ndarray | None,
    q_global: np.ndarray | None,
    source: OrientationSource | None,
    *,
    imu: str,
    params: AccRestParams,
) -> RestCalibrated:
    """The accelerometer corrected from the rests of ``given_rest`` (N,) bool (the phases step's zero-velocity
    mask) and the orientation filter re-run on it, on the samples ``t_ns`` (int64 ns, device clock; ``t_s`` (N,) s
    the times the gyroscope is integrated over, the reference clock when aligned). ``q_global`` (N, 4): the
    orientation step's orientation; ``source``: its accelerometer, gyroscope and parameters, on the same samples;
    missing samples as that step treats them (:mod:`imulog.process.gaps`' defaults). A one-line ValueError when an
    input is missing or the calibration is not identifiable (too few or too similar rests:
    :attr:`AccRestCalibration.reason`)."""
    option = "TrajectoryParams.acc_rests (--accelerometer rests)"
    if q_global is None:
        raise ValueError(f"{option} needs /derived/orientation/{imu}: run `imulog process orientation` first")
    if given_rest is None:
        raise ValueError(f"{option} needs /derived/static/{imu}: run `imulog process phases` first")
    if source is None:
        raise ValueError(f"{option} needs the accelerometer and gyroscope of /imu/{imu} (the orientation's input)")
    if source.params.use_mag:
        raise ValueError(f"{option}: the orientation of {imu} fused the magnetometer, which the re-run does not")
    if len(source.t_ns) != len(t_ns) or not np.array_equal(source.t_ns, t_ns):
        raise ValueError(f"{option}: {source.topic} and /derived/acc_global/{imu} have different samples")
    acc, gyr = np.asarray(source.acc_mps2, dtype=np.float64), np.asarray(source.gyr_rad_s, dtype=np.float64)
    calibration = estimate(acc, gyr, t_s, np.asarray(given_rest, bool), params)
    if not calibration.applied:
        raise ValueError(f"{source.topic}: the accelerometer cannot be corrected from its rests: {calibration.reason}")
    corrected = calibration.apply(acc)
    streams, _ = orientation_with_gaps(t_ns, corrected, gyr, None, imu, source.params)
    q_new, lin = streams[0].values, streams[1].values
    both = np.all(np.isfinite(q_new), axis=1) & np.all(np.isfinite(q_global), axis=1)
    heading = quat.heading_offset(q_new[both], np.asarray(q_global, float)[both])  # re-run's frame -> channel's
    record = {
        "accelerometer": source.topic,
        "corrected_from": f"the rests of /derived/static/{imu}",
        "calibration": calibration.as_dict(),
        "orientation_filter": {
            "algorithm": f"{ORIENTATION_ALGORITHM}{source.params.backend}",
            "params": dataclasses.asdict(source.params),
            "input": "the corrected accelerometer",
            "heading_to_channel_deg": round(float(np.degrees(2 * np.arctan2(heading[3], heading[0]))), 4),
        },
    }
    return RestCalibrated(
        acc_global=quat.rotate(heading, lin),
        quat=quat.multiply(heading, q_new),
        acc_sensor=corrected,
        calibration=calibration,
        record=record,
    )


def acc_source(
    params: AccRestParams,
    topic: str,
    metadata: dict[str, Any] | None,
    one_window: bool,
    core_s: float,
) -> tuple[str | None, OrientationParams | None]:
    """``(accelerometer topic, OrientationParams)`` the option re-runs the filter with, from the orientation channel
    ``topic``'s ``metadata`` (None when the option is off or the channel is missing: the step's own error then says
    what to run); a one-line ValueError on a recording longer than one trajectory window (``core_s`` s), where the
    calibration and the re-run are not built window by window."""
    if not params.enabled or metadata is None:
        return None, None
    if not one_window:
        raise ValueError(
            f"TrajectoryParams.acc_rests (--accelerometer rests) runs on recordings of one trajectory window (at "
            f"most {core_s / 60:g} min): the calibration from the rests is not reduced over windows yet"
        )
    return orientation_params_of(topic, metadata)
