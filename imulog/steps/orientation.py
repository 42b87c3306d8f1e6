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
from imulog.process.orientation import OrientationParams, estimate_orientation, gravity_free_acceleration
from imulog.steps.common import mean_rate_hz, pick_imu

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
    stream = trial.read(topic)
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
    t_ns: np.ndarray, acc: np.ndarray, gyr: np.ndarray, mag: np.ndarray | None, imu: str, params: OrientationParams
) -> list[SignalStream]:
    """Pure part of the step: the three derived streams from IMU arrays."""
    if params.use_mag and mag is None:
        raise ValueError(f"/imu/{imu} has no magnetometer: drop --mag")
    res = estimate_orientation(gyr, acc, mean_rate_hz(t_ns), mag, params, t_ns=t_ns)
    lin = gravity_free_acceleration(res.quat, acc, res.static)
    frame = f"{imu}_global"
    return [
        SignalStream(
            f"/derived/orientation/{imu}", t_ns, ["qw", "qx", "qy", "qz"], ["1"] * 4, res.quat, frame_id=frame
        ),
        SignalStream(f"/derived/acc_global/{imu}", t_ns, ["ax", "ay", "az"], ["m/s^2"] * 3, lin, frame_id=frame),
        SignalStream(
            f"/derived/orientation_static/{imu}",
            t_ns,
            ["static"],
            ["1"],
            res.static.astype(np.float64)[:, None],
            frame_id=imu,
        ),
    ]


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
):
    """Run the step on a trial file; returns the :func:`imulog.steps.base.run_step` outcome."""
    params = params or OrientationParams()
    from imulog.archive import TrialReader
    from imulog.steps.base import StepResult, run_step

    with TrialReader(path) as trial:
        topics = trial.topics()
        name = pick_imu(topics, imu)
        topic = source_topic(topics, name, source)

    def compute(trial) -> StepResult:
        t_ns, acc, gyr, mag = read_imu_arrays(trial, topic)
        return StepResult(streams=compute_orientation(t_ns, acc, gyr, mag, name, params))

    return run_step(
        path,
        step=f"{STEP}:{name}",
        algorithm=f"imulog.orientation.{params.backend}",
        # the global frame (ENU with the magnetometer fused) is recorded in every output channel's params
        params={"imu": name, **params_dict(params), "global_frame": global_frame(params)},
        inputs=[topic],
        compute=compute,
        force=force,
    )
