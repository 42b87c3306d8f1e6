"""Which clock a channel is on, and mapping it to the reference (Vicon) clock for the one viewer timeline.

The formula ``t_ref_ns = t_dev_ns + offset_ns + drift_ppm*1e-6*(t_dev_ns - t0_ns)`` is
:func:`imulog.process.alignment.device_to_reference`.

Clock of a channel, decided in this order (matching what the steps in :mod:`imulog.steps` write):

1. channel metadata ``clock``: ``reference`` (already on the reference clock) or an IMU topic/name
   (``/imu/wrist`` or ``wrist``: on that IMU's device clock);
2. raw IMU topics ``/imu/{name}`` are on their device clock;
3. ``/derived/phases/{name}`` and ``/derived/movements/{name}`` follow ``imulog.timing["clock"]``
   (``reference`` or ``device``, written by the phases step); without that record, the device clock;
   ``/derived/trajectory/{method}`` follows ``imulog.trajectory["clock"]`` (device clock of
   ``imulog.trajectory["imu"]``); without that record, the reference clock;
4. other derived topics ending in an IMU name of the trial (``/derived/orientation/{name}``,
   ``/derived/acc_global/{name}``, ``/derived/static/{name}``, ``/derived/orientation_static/{name}``,
   ``/derived/metrics/*/{name}``...) are on that IMU's device clock, except under ``/derived/reference/``,
   ``/derived/vicon/`` and ``/derived/trajectory/``;
5. everything else (markers, Vicon-derived channels, trajectories) is on the reference clock.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from imulog.archive.alignment_records import alignments_from_metadata, imu_name  # noqa: F401  (re-exported)
from imulog.process.alignment import device_to_reference as _device_to_reference

DEVICE_CLOCK_DERIVED = ("orientation", "acc_global", "static", "orientation_static", "movements", "phases")
REFERENCE_CLOCK_DERIVED = ("reference", "vicon")
#: derived kind -> metadata record whose ``clock`` (and ``imu``) say which clock the step wrote
STEP_CLOCK_RECORDS = {"phases": "imulog.timing", "movements": "imulog.timing", "trajectory": "imulog.trajectory"}


def device_to_reference(t_dev_ns: np.ndarray, alignment: Mapping[str, Any]) -> np.ndarray:
    """Map IMU device time stamps (int64 ns) to the reference clock (int64 ns)."""
    return np.asarray(_device_to_reference(np.asarray(t_dev_ns, dtype=np.int64), dict(alignment)), np.int64)


def device_imu_of(
    topic: str,
    channel_meta: Mapping[str, Any] | None = None,
    imu_names: set[str] | None = None,
    step_records: Mapping[str, Mapping[str, Any]] | None = None,
) -> str | None:
    """Name of the IMU whose device clock ``topic`` is on, or None when it is on the reference clock.

    ``imu_names``: the trial's IMUs (without it only the standard per-IMU derived topics are recognised);
    ``step_records``: metadata records by name (``imulog.timing``, ``imulog.trajectory``) whose ``clock``
    (``reference`` or ``device``) says how phases, movements and trajectories were written.
    """
    clock = (channel_meta or {}).get("clock")
    if clock:
        clock = str(clock)
        return None if clock in ("reference", "ref", "vicon") else imu_name(clock)
    parts = topic.strip("/").split("/")
    if len(parts) == 2 and parts[0] == "imu":
        return parts[1]
    if len(parts) < 3 or parts[0] != "derived" or parts[1] in REFERENCE_CLOCK_DERIVED:
        return None
    name = parts[-1]
    if parts[1] in STEP_CLOCK_RECORDS and len(parts) == 3:
        record = (step_records or {}).get(STEP_CLOCK_RECORDS[parts[1]]) or {}
        step_clock = record.get("clock")
        if parts[1] == "trajectory":
            if step_clock != "device":
                return None
            return imu_name(str(record.get("imu") or "")) or None
        return None if step_clock == "reference" else name
    if imu_names is not None:
        return name if name in imu_names else None
    return name if len(parts) == 3 and parts[1] in DEVICE_CLOCK_DERIVED else None


class ClockMap:
    """Maps each channel's time stamps to the reference clock using the trial's alignment records."""

    def __init__(
        self,
        metadata: Mapping[str, Mapping[str, Any]],
        channel_meta: Mapping[str, Mapping[str, Any]],
        imu_names: set[str] | None = None,
    ):
        self.alignments = alignments_from_metadata(metadata)
        self.channel_meta = channel_meta
        self.imu_names = imu_names
        self.step_records = {name: metadata[name] for name in set(STEP_CLOCK_RECORDS.values()) if name in metadata}
        self.unaligned: set[str] = set()  # IMU names on a device clock without alignment

    def to_reference(self, topic: str, t_ns: np.ndarray) -> np.ndarray:
        """Reference-clock time stamps (int64 ns) of ``topic``'s samples ``t_ns``."""
        imu = device_imu_of(topic, self.channel_meta.get(topic), self.imu_names, self.step_records)
        if imu is None:
            return np.asarray(t_ns, dtype=np.int64)
        alignment = self.alignments.get(imu)
        if alignment is None:
            self.unaligned.add(imu)
            return np.asarray(t_ns, dtype=np.int64)
        return device_to_reference(t_ns, alignment)
