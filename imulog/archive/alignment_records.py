"""Which alignment record belongs to which IMU, from the trial's metadata alone: plain dicts, no numpy (``imulog info``
reads it without loading numpy; :mod:`imulog.archive.clocks` applies the records)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def imu_name(topic_or_name: str) -> str:
    """``/imu/wrist`` or ``wrist`` -> ``wrist``."""
    return topic_or_name.rsplit("/", 1)[-1] if topic_or_name.startswith("/imu/") else topic_or_name.strip("/")


def alignments_from_metadata(
    metadata: Mapping[str, Mapping[str, Any]], *, failed: bool = False
) -> dict[str, dict[str, Any]]:
    """IMU name -> alignment record, from ``imulog.alignment`` (and ``imulog.alignment.<imu>``) records. A record
    without a clock (``offset_ns``: an IMU a setup could not align, ``quality`` ``failed``) is left out, so no IMU is
    put on the reference clock with a made-up offset of 0; ``failed`` keeps them (to list them)."""
    found: dict[str, dict[str, Any]] = {}
    for key, record in metadata.items():
        if key != "imulog.alignment" and not key.startswith("imulog.alignment."):
            continue
        if not failed and "offset_ns" not in (record or {}):
            continue
        record = dict(record)
        name = record.get("imu") or (key.split(".", 2)[2] if key.count(".") >= 2 else "")
        if not name:
            continue
        found[imu_name(str(name))] = record
    return found
