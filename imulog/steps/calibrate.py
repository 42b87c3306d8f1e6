"""Calibration: estimate a calibration from a calibration recording, apply one to a trial.

* :func:`calibration_from_arrays` segments a calibration recording (six static orientations, a
  static period and one known rotation about each axis, in any order) and estimates accelerometer
  and gyroscope bias and calibration matrices (R2G thesis eqs. 2.1-2.5).
* :func:`run_calibrate` (step ``calibrate``) writes ``/derived/calibrated/{imu}`` (``ax,ay,az``
  m/s^2, ``gx,gy,gz`` rad/s, and ``mx,my,mz`` uT passed through when present) on the IMU device
  clock; the calibration itself is recorded in the run's params.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

from imulog.model import SignalStream
from imulog.process import calibration as cal
from imulog.steps.common import mean_rate_hz, names_trial, pick_imu
from imulog.steps.windows import WindowParams, channel_rate_hz

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "calibrate"


def calibration_from_arrays(
    t_ns: np.ndarray,
    acc: np.ndarray | None,
    gyr: np.ndarray,
    *,
    angle_rad: float = 2 * np.pi,
    params: cal.SegmentParams | None = None,
    g_m_s2: float = cal.GRAVITY_M_S2,
) -> cal.Calibration:
    """Estimate a :class:`~imulog.process.calibration.Calibration` from one calibration recording.

    Accelerometer: needs the six static orientations (skipped with a note in ``info`` when absent).
    Gyroscope: needs rotations of ``angle_rad`` about each axis between static periods (skipped
    likewise). Raises when neither can be estimated.
    """
    params = params or cal.SegmentParams()
    fs = mean_rate_hz(t_ns)
    statics = cal.find_static_segments(gyr, fs, params)
    if not statics:
        raise ValueError("no static period found (gyro norm never stays below the threshold for long enough)")
    out = cal.Calibration(info={"static_periods": len(statics), "rate_hz": round(fs, 4)})
    problems = []
    if acc is not None:
        try:
            ap, am = cal.six_position_means(acc, statics)
            out.acc = cal.accelerometer_six_position(ap, am, g_m_s2)
        except ValueError as exc:
            problems.append(f"accelerometer: {exc}")
    rotations = cal.find_rotation_segments(gyr, fs, statics, angle_rad, params)
    out.info["rotations"] = len(rotations)
    try:
        longest = max(statics, key=lambda se: se[1] - se[0])
        out.gyr = cal.gyroscope_from_rotations(gyr[longest[0] : longest[1]], rotations, fs)
    except ValueError as exc:
        problems.append(f"gyroscope: {exc}")
    if out.acc is None and out.gyr is None:
        raise ValueError("; ".join(problems))
    if problems:
        out.info["not_estimated"] = problems
    return out


def compute_calibrated(
    t_ns: np.ndarray,
    acc: np.ndarray | None,
    gyr: np.ndarray | None,
    mag: np.ndarray | None,
    imu: str,
    calibration: cal.Calibration,
) -> SignalStream:
    """The calibrated channel of one IMU."""
    if acc is None or gyr is None:
        raise ValueError(f"/imu/{imu} needs accelerometer and gyroscope columns")
    a, g = cal.apply(calibration, acc, gyr)
    cols, units, vals = ["ax", "ay", "az", "gx", "gy", "gz"], ["m/s^2"] * 3 + ["rad/s"] * 3, [a, g]
    if mag is not None:
        cols += ["mx", "my", "mz"]
        units += ["uT"] * 3
        vals.append(mag)
    return SignalStream(f"/derived/calibrated/{imu}", t_ns, cols, units, np.hstack(vals), frame_id=imu)


def calibrated_pieces(path, topic: str, imu: str, calibration: cal.Calibration) -> Iterator[SignalStream]:
    """The calibrated channel of ``topic`` block by block (a per-sample map: no margins, no carry)."""
    from imulog.archive import TrialReader
    from imulog.heap import reuse_heap

    reuse_heap()  # the same temporaries block after block: reuse their pages (imulog.heap; 1.31x from 1 to 7 days without)
    with TrialReader(path) as trial:
        for s in trial.iter_blocks(topic):
            yield compute_calibrated(s.t_ns, s.acc, s.gyr, s.mag, imu, calibration)


@names_trial
def run_calibrate(
    path: str | os.PathLike[str],
    calibration: cal.Calibration,
    *,
    imu: str | None = None,
    force: bool = False,
    windows: WindowParams | None = None,
) -> StepOutcome:
    """Apply ``calibration`` to a trial (step ``calibrate``); returns the run_step outcome.

    A recording within one window (``windows``, default an hour) is calibrated at once; a longer one block by
    block as it is read, in bounded memory (the same values: the map is per sample).
    """
    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step

    windows = windows or WindowParams()
    with TrialReader(path) as trial:
        name = pick_imu(trial.topics(), imu)
        topic = f"/imu/{name}"
        info = trial.channel(topic)
        rate = channel_rate_hz(info.sample_count, info.start_ns, info.end_ns, info.rate_hz)
    several = len(windows.plan(info.sample_count, rate)) > 1

    def compute(trial) -> StepResult:
        if several:
            pieces = StreamPieces(
                topics=[f"/derived/calibrated/{name}"],
                pieces=lambda: calibrated_pieces(path, topic, name, calibration),
                expected_duration_s=info.sample_count / rate,
            )
            return StepResult(streams=[pieces])
        s = trial.read(topic)
        return StepResult(streams=[compute_calibrated(s.t_ns, s.acc, s.gyr, s.mag, name, calibration)])

    return run_step(
        path,
        step=f"{STEP}:{name}",
        algorithm="imulog.calibration.linear",
        params={"imu": name, "calibration": calibration.to_dict()},
        inputs=[topic],
        compute=compute,
        force=force,
    )
