"""Which alignment record belongs to which IMU, from the trial's metadata alone: plain dicts, no numpy (``imulog info``
reads it without loading numpy; :mod:`imulog.archive.clocks` applies the records)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def imu_name(topic_or_name: str) -> str:
    """``/imu/wrist`` or ``wrist`` -> ``wrist``."""
    return topic_or_name.rsplit("/", 1)[-1] if topic_or_name.startswith("/imu/") else topic_or_name.strip("/")


def alignments_from_metadata(metadata: Mapping[str, Mapping[str, Any]]) -> dict[str, dict[str, Any]]:
    """IMU name -> alignment record, from ``imulog.alignment`` (and ``imulog.alignment.<imu>``) records."""
    found: dict[str, dict[str, Any]] = {}
    for key, record in metadata.items():
        if key != "imulog.alignment" and not key.startswith("imulog.alignment."):
            continue
        record = dict(record)
        name = record.get("imu") or (key.split(".", 2)[2] if key.count(".") >= 2 else "")
        if not name:
            continue
        found[imu_name(str(name))] = record
    return found
