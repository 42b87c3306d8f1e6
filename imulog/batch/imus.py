"""The batch's per-IMU steps run on every IMU of a trial, like the commands (:mod:`imulog.commands.imus`).

calibrate, orientation, phases, trajectory, metrics and epochs take one IMU (``imu=NAME``); without that option
the batch runs the step once per IMU of the trial, one ``step:IMU`` run each, and the file's step record sums
them (skipped when every IMU was up to date). Which IMUs: every ``/imu/*`` channel that has what the step
reads (the accelerometer, the gyroscope; an ActiGraph's accelerometer-only stream beside its IMU is left out),
and for trajectory every oriented IMU with the phases step's zero-velocity mask when a method needs it.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any

#: the quantities each per-IMU step reads (as the commands choose their IMUs)
PER_IMU_NEEDS: dict[str, tuple[str, ...]] = {
    "calibrate": (),
    "orientation": ("acc", "gyr"),
    "phases": ("gyr",),
    "trajectory": (),
    "metrics": ("acc",),
    "epochs": ("acc",),
}


@dataclass
class ImusOutcome:
    """The step over several IMUs: ``skipped`` when every IMU was up to date, the last run, one reason."""

    skipped: bool
    run: int | None
    reason: str
    imus: list[str]


def step_imus(path: str | os.PathLike[str], step: str, methods: Any = None) -> list[str]:
    """The IMUs ``step`` runs on in the trial at ``path`` when none is named (see the module docstring)."""
    from imulog.archive import TrialReader
    from imulog.steps.common import imu_names

    with TrialReader(path) as trial:
        topics = trial.topics()
        columns = {
            c.topic: json.loads(c.metadata.get("columns") or "null") for c in trial.channels if c.topic in topics
        }
    if step == "trajectory":
        from imulog.process.trajectory_opt import METHODS
        from imulog.steps.trajectory import NEEDS_STATIC

        names = imu_names(topics, "/derived/acc_global/")
        chosen = list(methods or METHODS) if not isinstance(methods, str) else methods.split(",")
        if NEEDS_STATIC.intersection(chosen):
            ready = [n for n in names if f"/derived/static/{n}" in topics]
            names = ready or names  # none ready: the step's own error says what to run
        return names
    names = imu_names(topics)
    needs = PER_IMU_NEEDS.get(step, ())
    able = [
        n
        for n in names
        if not any(isinstance(columns.get(f"/imu/{n}"), list) and q not in columns[f"/imu/{n}"] for q in needs)
    ]
    return able or names


def run_every_imu(path: str | os.PathLike[str], step: str, call: Any, kwargs: dict[str, Any]) -> Any:
    """``call(imu=NAME, **kwargs)`` on every IMU of :func:`step_imus`; one IMU returns its own outcome, several
    an :class:`ImusOutcome`. An IMU that fails does not stop the others; the step then raises naming them."""
    names = step_imus(path, step, kwargs.get("methods"))
    if len(names) <= 1:
        return call(imu=names[0] if names else None, **kwargs)
    outcomes, failed = [], []
    for name in names:
        try:
            outcomes.append(call(imu=name, **kwargs))
        except (ValueError, KeyError, OSError, RuntimeError) as exc:
            failed.append(f"{name}: {str(exc).removeprefix(f'{path}: ')}")  # the file is named once, by the batch
    if failed:
        raise ValueError(f"{len(failed)} of {len(names)} IMUs failed: " + "; ".join(failed))
    skipped = all(o.skipped for o in outcomes)
    runs = [o.run for o in outcomes if o.run is not None]
    done = sum(not o.skipped for o in outcomes)
    reason = "every IMU up to date" if skipped else f"computed on {done} of {len(names)} IMUs"
    return ImusOutcome(skipped, max(runs) if runs else None, reason, names)
