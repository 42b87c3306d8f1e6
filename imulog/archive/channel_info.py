"""What a trial lists without reading data: a channel's summary entry and an attachment."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

#: channel metadata from the stream's ``meta`` (:func:`imulog.archive.codec.encode`) that a recording's later pieces
#: may change (a text reader refines ``rate_hz`` as it reads): a streamed trial's closing ``imulog.channel_stats``
#: record holds the final values, which replace the Channel record's when read (``TrialReader``)
FINAL_META_KEYS = ("meta", "source")


def _kinds() -> dict[str, str]:
    from imulog.archive.codec import SCHEMA_KIND  # imported on first use: listing a trial needs no protobuf

    return SCHEMA_KIND


@dataclass
class ChannelInfo:
    """One channel as listed in the file's summary (no data read)."""

    topic: str
    schema_name: str
    message_count: int
    sample_count: int
    start_ns: int | None
    end_ns: int | None
    rate_hz: float | None
    metadata: dict[str, str] = field(default_factory=dict)
    channel_id: int = -1

    @property
    def kind(self) -> str:
        return self.metadata.get("kind") or _kinds().get(self.schema_name, "unknown")

    @property
    def derived(self) -> bool:
        return self.topic.startswith("/derived/")

    @property
    def duration_s(self) -> float | None:
        if self.start_ns is None or self.end_ns is None:
            return None
        return (self.end_ns - self.start_ns) / 1e9

    @property
    def params(self) -> dict[str, Any] | None:
        """Parsed ``params`` of a derived channel (None for raw channels)."""
        return json.loads(self.metadata["params"]) if "params" in self.metadata else None

    @property
    def inputs(self) -> dict[str, str] | None:
        """Parsed ``inputs`` (topic -> content hash) of a derived channel."""
        return json.loads(self.metadata["inputs"]) if "inputs" in self.metadata else None


@dataclass
class Attachment:
    name: str
    media_type: str
    data: bytes
    sha256: str
    log_time: int = 0


def _float(value: str | None) -> float | None:
    try:
        return float(value) if value else None
    except ValueError:
        return None


def _int(meta: dict[str, str], key: str) -> int | None:
    try:
        return int(meta[key])
    except (KeyError, ValueError):
        return None
