"""Where the trajectory step's channels and record are, for one IMU or many, in new and older archives.

A trial with one IMU keeps one set: ``/derived/trajectory/{method}``, ``/derived/trajectory_baseline/dedrift``
and the record ``imulog.trajectory``. A trial with several IMUs (``/imu/*`` channels) gets one set per IMU:
``/derived/trajectory/{method}/{imu}`` and ``/derived/trajectory_baseline/dedrift/{imu}``, like every other
per-IMU derived channel (the IMU last), and the record :func:`imulog.steps.common.record_for` names
(``imulog.trajectory`` for the primary IMU, ``imulog.trajectory.{imu}`` for the others). Readers (evaluate,
metrics, view, batch) find both layouts with :func:`trajectories_by_imu`: a channel of the one-set layout
belongs to the IMU its record names (``""`` when it names none).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from imulog.steps.common import imu_names, record_of

PREFIX = "/derived/trajectory/"
BASELINE_PREFIX = "/derived/trajectory_baseline/"
RECORD = "imulog.trajectory"


def per_imu_layout(topics: list[str]) -> bool:
    """Whether the trial's trajectories are written per IMU: it has more than one ``/imu/*`` channel."""
    return len(imu_names(topics)) > 1


def trajectory_topic(method: str, imu: str | None = None) -> str:
    """``/derived/trajectory/{method}`` or, per IMU, ``/derived/trajectory/{method}/{imu}``."""
    return f"{PREFIX}{method}" + (f"/{imu}" if imu else "")


def baseline_topic(method: str, imu: str | None = None) -> str:
    """``/derived/trajectory_baseline/{method}`` or, per IMU, ``.../{method}/{imu}``."""
    return f"{BASELINE_PREFIX}{method}" + (f"/{imu}" if imu else "")


def _owner(metadata: Mapping[str, Mapping[str, Any]]) -> str:
    return str((metadata.get(RECORD) or {}).get("imu") or "").removeprefix("/imu/")


def split_topic(topic: str, metadata: Mapping[str, Mapping[str, Any]]) -> tuple[str, str] | None:
    """``(imu, method)`` of a trajectory or baseline channel (``imu`` "" when an older one-set archive names
    none), None for any other topic."""
    for prefix in (PREFIX, BASELINE_PREFIX):
        if topic.startswith(prefix):
            parts = topic[len(prefix) :].split("/")
            if len(parts) == 2:
                return parts[1], parts[0]
            if len(parts) == 1:
                return _owner(metadata), parts[0]
    return None


def trajectories_by_imu(topics: list[str], metadata: Mapping[str, Mapping[str, Any]]) -> dict[str, dict[str, str]]:
    """``{imu: {method: topic}}`` of the trial's trajectory channels (not the baselines), both layouts."""
    out: dict[str, dict[str, str]] = {}
    for topic in topics:
        if topic.startswith(PREFIX):
            found = split_topic(topic, metadata)
            if found:
                out.setdefault(found[0], {})[found[1]] = topic
    return out


def baselines_by_imu(topics: list[str], metadata: Mapping[str, Mapping[str, Any]]) -> dict[str, dict[str, str]]:
    """``{imu: {method: topic}}`` of the baselines (``dedrift``), both layouts."""
    out: dict[str, dict[str, str]] = {}
    for topic in topics:
        if topic.startswith(BASELINE_PREFIX):
            found = split_topic(topic, metadata)
            if found:
                out.setdefault(found[0], {})[found[1]] = topic
    return out


def record_name_of(imu: str, metadata: Mapping[str, Mapping[str, Any]]) -> str | None:
    """The trajectory record of ``imu`` (``imulog.trajectory`` or ``imulog.trajectory.{imu}``), None if none."""
    return record_of(RECORD, imu, metadata) if imu else (RECORD if RECORD in metadata else None)


def record_of_imu(imu: str, metadata: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The trajectory record of ``imu`` ({} when there is none)."""
    name = record_name_of(imu, metadata)
    return dict(metadata.get(name) or {}) if name else {}
