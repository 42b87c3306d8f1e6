"""Reprocessing step ``orientation``: sensor orientation and gravity-free global acceleration of one IMU.

Reads ``/imu/{imu}`` (or ``/derived/calibrated/{imu}`` when present, see ``source``) and writes, on
the IMU device clock (the raw channel's ``t_ns``):

* ``/derived/orientation/{imu}``: ``qw,qx,qy,qz``, sensor-to-global (z up, heading arbitrary unless
  the magnetometer is fused);
* ``/derived/acc_global/{imu}``: ``ax,ay,az`` m/s^2 in the global frame, gravity removed;
* ``/derived/orientation_static/{imu}``: ``static`` (1 = gyro norm below the threshold), the mask
  used for initialisation and gravity magnitude (``/derived/static/{imu}`` belongs to the
  segmentation step).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from imulog.model import SignalStream
from imulog.process.gaps import GapParams, GapReport, per_run, prepare
from imulog.process.orientation import OrientationParams, estimate_orientation, gravity_free_acceleration
from imulog.steps.common import mean_rate_hz, pick_imu
from imulog.steps.long_orientation import LONG_SAMPLES, WindowParams, windowed_pieces

STEP = "orientation"
CALIBRATED_TOPIC = "/derived/calibrated/{imu}"


def source_topic(topics: list[str], imu: str, source: str) -> str:
    """Input topic for ``source`` ``auto`` (calibrated if present), ``raw`` or ``calibrated``."""
    cal = CALIBRATED_TOPIC.format(imu=imu)
    if source == "raw":
        return f"/imu/{imu}"
    if source == "calibrated":
        if cal not in topics:
            raise ValueError(f"no {cal} in the trial: run `imulog process calibrate` first or use --source raw")
        return cal
    if source != "auto":
        raise ValueError(f"source must be auto, raw or calibrated, got {source!r}")
    return cal if cal in topics else f"/imu/{imu}"


def read_imu_arrays(trial: Any, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(t_ns, acc, gyr, mag)`` from a raw ImuStream or a calibrated SignalStream topic."""
    return imu_arrays(trial.read(topic), topic)


def imu_arrays(stream: Any, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(t_ns, acc, gyr, mag)`` of a raw ImuStream or a calibrated SignalStream (or a piece of either)."""
    if topic.startswith("/imu/"):
        if stream.acc is None or stream.gyr is None:
            raise ValueError(f"{topic} needs accelerometer and gyroscope columns")
        return stream.t_ns, stream.acc, stream.gyr, stream.mag
    cols = {c: i for i, c in enumerate(stream.columns)}
    need = ["ax", "ay", "az", "gx", "gy", "gz"]
    if any(c not in cols for c in need):
        raise ValueError(f"{topic} lacks columns {', '.join(c for c in need if c not in cols)}")
    v = stream.values
    acc = v[:, [cols["ax"], cols["ay"], cols["az"]]]
    gyr = v[:, [cols["gx"], cols["gy"], cols["gz"]]]
    mag = v[:, [cols["mx"], cols["my"], cols["mz"]]] if all(c in cols for c in ("mx", "my", "mz")) else None
    return stream.t_ns, acc, gyr, mag


def compute_orientation(
    t_ns: np.ndarray,
    acc: np.ndarray,
    gyr: np.ndarray,
    mag: np.ndarray | None,
    imu: str,
    params: OrientationParams,
    gaps: GapParams | None = None,
) -> list[SignalStream]:
    """Pure part of the step: the three derived streams from IMU arrays (see :func:`orientation_with_gaps`)."""
    return orientation_with_gaps(t_ns, acc, gyr, mag, imu, params, gaps)[0]


def orientation_with_gaps(
    t_ns: np.ndarray,
    acc: np.ndarray,
    gyr: np.ndarray,
    mag: np.ndarray | None,
    imu: str,
    params: OrientationParams,
    gaps: GapParams | None = None,
) -> tuple[list[SignalStream], GapReport]:
    """The three derived streams and the gap report: missing samples (NaN) follow :mod:`imulog.process.gaps`
    (short gaps bridged, the filter restarted after long ones, NaN outputs inside them)."""
    if params.use_mag and mag is None:
        raise ValueError(f"/imu/{imu} has no magnetometer: drop --mag")
    (acc, gyr, mag_used), report = prepare([acc, gyr, mag if params.use_mag else None], gaps)

    def run(t, a, g, m):
        res = estimate_orientation(g, a, mean_rate_hz(t), m, params, t_ns=t)
        return res.quat, gravity_free_acceleration(res.quat, a, res.static), res.static.astype(np.float64)

    try:
        quat, lin, static = per_run(run, report, t_ns, acc, gyr, mag_used)
    except ValueError as exc:
        raise ValueError(f"/imu/{imu}: {exc}") from None
    if not params.use_mag:
        _continue_heading(quat, lin, report.runs)
    frame = f"{imu}_global"
    return [
        SignalStream(f"/derived/orientation/{imu}", t_ns, ["qw", "qx", "qy", "qz"], ["1"] * 4, quat, frame_id=frame),
        SignalStream(f"/derived/acc_global/{imu}", t_ns, ["ax", "ay", "az"], ["m/s^2"] * 3, lin, frame_id=frame),
        SignalStream(f"/derived/orientation_static/{imu}", t_ns, ["static"], ["1"], static[:, None], frame_id=imu),
    ], report


def _continue_heading(quat: np.ndarray, lin: np.ndarray, runs: tuple[tuple[int, int], ...]) -> None:
    """Without a magnetometer each restarted run has its own arbitrary heading: turn each run about the global z
    axis so that its first sample has the heading of the previous run's last one (in place). This assumes the
    heading did not change during the gap; the steps record ``gaps.runs`` so the assumption is visible."""
    from imulog.process import quaternion as qmath

    for (_, b0), (a1, b1) in zip(runs, runs[1:], strict=False):
        r = np.tile(qmath.heading_offset(quat[a1 : a1 + 1], quat[b0 - 1 : b0]), (b1 - a1, 1))
        quat[a1:b1] = qmath.multiply(r, quat[a1:b1])
        lin[a1:b1] = qmath.rotate(r, lin[a1:b1])


def params_dict(params: OrientationParams) -> dict:
    return dataclasses.asdict(params)


def global_frame(params: OrientationParams) -> str:
    """The orientation's global frame: ENU when the magnetometer is fused, else z-up with arbitrary heading."""
    from imulog.process.orientation import GLOBAL_FRAME_6D, GLOBAL_FRAME_9D

    return GLOBAL_FRAME_9D if params.use_mag else GLOBAL_FRAME_6D


def run_orientation(
    path,
    *,
    imu: str | None = None,
    params: OrientationParams | None = None,
    source: str = "auto",
    force: bool = False,
    gaps: GapParams | None = None,
    windowed: WindowParams | None = None,
):
    """Run the step on a trial file; returns the :func:`imulog.steps.base.run_step` outcome.

    Recordings longer than :data:`~imulog.steps.long_orientation.LONG_SAMPLES` samples (or any, with
    ``windowed``) are processed in overlapping windows in bounded memory (:mod:`imulog.steps.long_orientation`).

    ``gaps``: how missing IMU samples are treated (default :class:`~imulog.process.gaps.GapParams`); what was
    bridged or split is recorded in the run's ``gaps`` entry.
    """
    params = params or OrientationParams()
    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step

    with TrialReader(path) as trial:
        topics = trial.topics()
        name = pick_imu(topics, imu)
        topic = source_topic(topics, name, source)
        total = trial.channel(topic).sample_count
        duration_s = total / (trial.channel(topic).rate_hz or 100.0)
    windows = windowed if windowed is not None else (WindowParams() if total > LONG_SAMPLES else None)
    step_params = {"imu": name, **params_dict(params), "global_frame": global_frame(params)}
    if windows is not None:
        step_params["windows"] = windows.to_dict()

    def compute(trial) -> StepResult:
        if windows is not None:  # long recording: window by window while the result is written
            pieces = StreamPieces(
                topics=[f"/derived/{kind}/{name}" for kind in ("orientation", "acc_global", "orientation_static")],
                pieces=lambda: windowed_pieces(path, topic, name, params, gaps, windows, total),
                expected_duration_s=duration_s,  # the viewer twins keep their message budget
            )
            return StepResult(streams=[pieces])
        t_ns, acc, gyr, mag = read_imu_arrays(trial, topic)
        streams, report = orientation_with_gaps(t_ns, acc, gyr, mag, name, params, gaps)
        return StepResult(streams=streams, provenance={"gaps": report.as_dict()} if report.missing else {})

    return run_step(
        path,
        step=f"{STEP}:{name}",
        algorithm=f"imulog.orientation.{params.backend}",
        # the global frame (ENU with the magnetometer fused) is recorded in every output channel's params
        params=step_params,
        inputs=[topic],
        compute=compute,
        force=force,
    )
