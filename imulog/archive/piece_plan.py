"""What a recording given in pieces declares up front, and the check that its pieces kept to it.

A Channel record precedes its messages and the time axis (:mod:`imulog.archive.timeline`) places every message,
so the streaming writer must know, before the first piece is written, each stream's time span (the axis' origins
and whether the IMU and reference clocks overlap) and each stream's final ``meta`` (the Channel record's ``meta``).
A converter whose pieces do not show them at once (XDF: a later stream may start earlier; counts known only at the
end) declares them in its first piece's ``Recording.metadata[PIECES_RECORD]``; otherwise the first piece's are
taken. Either way :class:`SpanCheck` follows what the pieces really held, and the writer refuses to keep a trial
whose time axis or channel meta differs from what the whole recording gives.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from imulog.archive.timeline import timeline_record
from imulog.model import PIECES_RECORD, Stream

#: the time-axis fields that must equal the whole recording's
AXIS_KEYS = ("device_origin_ns", "reference_origin_ns", "clocks")


@dataclass(frozen=True)
class Span:
    """A stream's first and last sample time (ns), in the shape :func:`timeline_record` reads."""

    topic: str
    t_ns: np.ndarray


def split_plan(metadata: dict[str, dict[str, Any]]) -> tuple[dict[str, dict[str, Any]], dict[str, Any] | None]:
    """(records without the declaration, the declaration ``{"spans": ..., "meta": ...}`` or None)."""
    if PIECES_RECORD not in metadata:
        return metadata, None
    rest = {k: v for k, v in metadata.items() if k != PIECES_RECORD}
    return rest, dict(metadata[PIECES_RECORD])


def declared_spans(plan: dict[str, Any]) -> list[Span] | None:
    """The declared spans as :class:`Span` objects (None when the plan declares none); empty streams left out."""
    spans = plan.get("spans")
    if spans is None:
        return None
    return [Span(t, np.array(v, dtype=np.int64)) for t, v in spans.items() if v is not None]


class SpanCheck:
    """The first and last sample time of every stream over all pieces (intervals: first start, last end)."""

    def __init__(self) -> None:
        self.lo: dict[str, int] = {}
        self.hi: dict[str, int] = {}

    def add(self, stream: Stream) -> None:
        t = getattr(stream, "t_ns", None)
        end = t
        if t is None:
            t, end = stream.start_ns, stream.end_ns
        if not len(t):
            return
        lo, hi = int(np.min(t)), int(np.max(end))
        topic = stream.topic
        self.lo[topic] = min(lo, self.lo.get(topic, lo))
        self.hi[topic] = max(hi, self.hi.get(topic, hi))

    def spans(self) -> list[Span]:
        return [Span(t, np.array([self.lo[t], self.hi[t]], dtype=np.int64)) for t in self.lo]

    def axis_problem(self, timeline: dict[str, Any], trial: dict[str, Any] | None, declared: bool) -> str | None:
        """Why the time axis written differs from the whole recording's (one line), or None when it does not."""
        whole = timeline_record(trial, self.spans())
        for key in AXIS_KEYS:
            if timeline.get(key) != whole.get(key):
                how = "declared in its first piece" if declared else "taken from its first piece"
                return (
                    f"the time axis {how} ({key} {timeline.get(key)}) is not the whole recording's "
                    f"({whole.get(key)}): a stream starts before the first piece's samples; the converter must "
                    f"declare every stream's span up front ({PIECES_RECORD})"
                )
        return None


def meta_problem(topic: str, written: dict[str, Any], final: dict[str, Any]) -> str | None:
    """Why a channel's final ``meta`` (every piece's merged) differs from the one its Channel record holds."""
    keys = sorted(k for k in {*written, *final} if written.get(k) != final.get(k))
    if not keys:
        return None
    return f"{topic}: its meta changed after the channel was written ({', '.join(keys)})"
