"""Reprocessing step ``phases``: movements, R2G phases, zero-velocity mask and timing table of one IMU.

Reads ``/imu/{imu}`` (gyroscope, device clock) and writes

* ``/derived/movements/{imu}``: Intervals labelled ``movement`` (raw segmentation, before event correction);
* ``/derived/phases/{imu}``: Intervals labelled ``reach``, ``lift``, ``return_bottle``, ``return_hand`` with
  ``task_index`` = repetition (1-based);
* ``/derived/static/{imu}``: SignalStream column ``static`` (1 = zero velocity), one row per IMU sample on the
  IMU device clock (the same ``t_ns`` as the raw channel, ready for ZUPT);
* metadata ``imulog.timing``: per phase repetition, label, start/end, duration (s), peak angular velocity
  (rad/s).

Interval times (movements, phases, timing table) are on the reference clock when the trial has an
``imulog.alignment`` record for this IMU (so they line up with Vicon), otherwise on the IMU device clock;
``imulog.timing["clock"]`` says which.
"""

from __future__ import annotations

import contextlib
import json
from typing import Any

import numpy as np

from imulog.model import Intervals, SignalStream
from imulog.process.segmentation.pipeline import PhaseParams, segment_phases, timing_table

STEP = "phases"


def algorithm_name(params: PhaseParams) -> str:
    return f"imulog.segmentation.{params.method}"


def pick_imu(topics: list[str], imu: str | None) -> str:
    """IMU name to segment: ``imu`` if given (must exist), else the only ``/imu/*`` topic, else ``wrist``."""
    imus = [t.split("/", 2)[2] for t in topics if t.startswith("/imu/")]
    if imu is not None:
        if imu not in imus:
            raise ValueError(f"no channel /imu/{imu} in the trial (IMU channels: {', '.join(imus) or 'none'})")
        return imu
    if len(imus) == 1:
        return imus[0]
    if "wrist" in imus:
        return "wrist"
    raise ValueError(f"choose an IMU with --imu among: {', '.join(imus) or 'none (no /imu/* channel)'}")


def _alignment_for(metadata: dict[str, Any], topic: str) -> dict | None:
    record = metadata.get("imulog.alignment")
    if not record:
        return None
    record = dict(record)
    for key, value in list(record.items()):
        if isinstance(value, str) and value[:1] in "[{":
            with contextlib.suppress(ValueError):
                record[key] = json.loads(value)
    if record.get("imu") not in (None, "", topic):
        return None
    return record


def compute_phases(
    t_ns: np.ndarray, gyr: np.ndarray, imu: str, params: PhaseParams, alignment: dict | None = None
) -> tuple[list, dict]:
    """Pure part of the step: streams and the ``imulog.timing`` record from IMU samples (no I/O)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if len(t_ns) < 10:
        raise ValueError(f"/imu/{imu} has only {len(t_ns)} samples")
    if gyr is None:
        raise ValueError(f"/imu/{imu} has no gyroscope columns")
    rate_hz = (len(t_ns) - 1) / ((t_ns[-1] - t_ns[0]) * 1e-9)
    result = segment_phases(gyr, rate_hz, params)
    t_iv, clock = t_ns, "device"
    if alignment is not None:
        from imulog.process.alignment import device_to_reference

        t_iv, clock = np.asarray(device_to_reference(t_ns, alignment), dtype=np.int64), "reference"
    last = len(t_ns) - 1
    ph = result.phases
    movements = Intervals(
        topic=f"/derived/movements/{imu}",
        start_ns=t_iv[result.movement_start],
        end_ns=t_iv[np.minimum(np.maximum(result.movement_end - 1, result.movement_start), last)],
        labels=["movement"] * len(result.movement_start),
    )
    phases = Intervals(
        topic=f"/derived/phases/{imu}",
        start_ns=t_iv[ph.start],
        end_ns=t_iv[np.minimum(np.maximum(ph.end - 1, ph.start), last)],
        labels=list(ph.labels),
        task_index=ph.repetition,
    )
    static = SignalStream(
        topic=f"/derived/static/{imu}",
        t_ns=t_ns,
        columns=["static"],
        units=["1"],
        values=result.static.astype(np.float64)[:, None],
        frame_id=imu,
    )
    rows = timing_table(ph, t_iv, gyr)
    n_rep = int(ph.repetition.max()) if len(ph) else 0
    timing = {
        "imu": f"/imu/{imu}",
        "method": params.method,
        "clock": clock,
        "rate_hz": round(rate_hz, 4),
        "n_movements": int(len(result.movement_start)),
        "n_repetitions": n_rep,
        "n_phases": int(len(ph)),
        "n_corrected_repetitions": int(ph.n_corrected),
        "static_fraction": round(float(result.static.mean()), 4),
        "phases": rows,
    }
    return [movements, phases, static], timing


def run_phases(path, *, imu: str | None = None, params: PhaseParams | None = None, force: bool = False):
    """Run the step on a trial file; returns the :func:`imulog.steps.base.run_step` outcome."""
    params = params or PhaseParams()
    from imulog.archive import TrialReader
    from imulog.steps.base import StepResult, run_step

    with TrialReader(path) as trial:
        name = pick_imu(trial.topics(), imu)
    topic = f"/imu/{name}"

    def compute(trial) -> StepResult:
        stream = trial.read(topic)
        alignment = _alignment_for(trial.metadata, topic)
        streams, timing = compute_phases(stream.t_ns, stream.gyr, name, params, alignment)
        return StepResult(streams=streams, metadata={"imulog.timing": timing})

    return run_step(
        path,
        step=STEP,
        algorithm=algorithm_name(params),
        params={"imu": name, **params.to_dict()},
        inputs=[topic],
        compute=compute,
        force=force,
    )
