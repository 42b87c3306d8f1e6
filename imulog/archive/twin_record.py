"""A viewer twin as written (:class:`Twin`), its topic name and the pieces every twin message shares.

Part of :mod:`imulog.archive.twins` (which re-exports these names): the channel record a twin is written from,
``/derived/viewer/...`` topics, the channel metadata of a twin and the protobuf timestamps of its messages.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from imulog.model import Stream

TWIN_PREFIX = "/derived/viewer"
ORIENTATION_COLUMNS = ["qw", "qx", "qy", "qz"]


@dataclass
class Twin:
    """One viewer channel, ready to write: schema, channel metadata, log times and payloads."""

    topic: str
    schema_name: str
    schema_encoding: str  # "protobuf" or "ros2msg"
    schema_data: bytes
    message_encoding: str  # "protobuf" or "cdr"
    metadata: dict[str, str] = field(default_factory=dict)
    log_times: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)
    rows: np.ndarray | None = None  # or: the messages as (N, W) uint8 rows (imulog.archive.wire.Rows) ...
    mask: np.ndarray | None = None  # ... with the bytes each message uses (None: whole rows)

    def set_rows(self, log_times: np.ndarray, rows: np.ndarray, mask: np.ndarray | None = None) -> None:
        """Hold the messages as rows (written and hashed with numpy, no per-message Python)."""
        self.log_times = np.asarray(log_times, dtype=np.uint64)
        self.rows, self.mask, self.payloads = rows, mask, []

    def __len__(self) -> int:
        return len(self.rows) if self.rows is not None else len(self.payloads)

    def payload_list(self) -> list[bytes]:
        """The messages as one ``bytes`` each, whichever form the twin holds."""
        if self.rows is None:
            return self.payloads
        from imulog.archive.wire import row_messages

        return row_messages(self.rows, self.mask)


def twin_topic(topic: str) -> str:
    """``/markers/vicon`` -> ``/derived/viewer/markers/vicon``; ``/derived/x/y`` -> ``/derived/viewer/x/y``."""
    rest = topic[len("/derived") :] if topic.startswith("/derived/") else topic
    return TWIN_PREFIX + rest


def is_twin(topic: str, channel_meta: Mapping[str, str] | None = None) -> bool:
    return bool((channel_meta or {}).get("twin_of")) or topic.startswith(TWIN_PREFIX + "/")


def set_stamp(msg: Any, t: int) -> None:
    msg.timestamp.seconds, msg.timestamp.nanos = divmod(int(t), 1_000_000_000)


def twin_meta(stream: Stream, canonical: str, clock: str, keep: np.ndarray, t: np.ndarray) -> dict[str, str]:
    out = {"twin_of": canonical, "clock": clock, "kind": "viewer", "sample_count": str(len(keep))}
    if len(keep):
        out.update(start_ns=str(int(t[keep[0]])), end_ns=str(int(t[keep[-1]])))
        if len(keep) > 1:
            out["rate_hz"] = f"{1e9 * (len(keep) - 1) / max(1, int(t[keep[-1]] - t[keep[0]])):.6g}"
    return out


def protobuf_twin(topic: str, schema_name: str, meta: dict[str, str]) -> Twin:
    from imulog.archive import codec

    return Twin(topic, schema_name, "protobuf", codec.file_descriptor_set(schema_name), "protobuf", meta)


def timestamp_message(stamps: np.ndarray) -> Any:
    """``google.protobuf.Timestamp`` sub-messages of int64 ns stamps, as :class:`imulog.archive.wire.Rows`."""
    from imulog.archive.wire import Rows

    sec, nsec = np.divmod(np.asarray(stamps, dtype=np.int64), 1_000_000_000)
    return Rows(len(sec)).varint(1, sec).varint(2, nsec)
