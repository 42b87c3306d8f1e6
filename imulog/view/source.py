"""Read a trial archive into what the viewer logs: streams, metadata records and channel metadata."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imulog.model import Recording


@dataclass
class TrialData:
    """One trial ready to log: ``streams`` (imulog.model objects), ``metadata`` records, ``channel_meta``."""

    label: str
    streams: list[Any]
    metadata: dict[str, dict[str, Any]] = field(default_factory=dict)
    channel_meta: dict[str, dict[str, Any]] = field(default_factory=dict)
    sample_counts: dict[str, int] = field(default_factory=dict)
    source: Path | None = None


def from_recording(recording: Recording, label: str = "trial") -> TrialData:
    """In-memory :class:`imulog.model.Recording` (e.g. from the simulator) -> :class:`TrialData`."""
    streams = recording.streams()
    return TrialData(
        label=label,
        streams=streams,
        metadata={k: dict(v) for k, v in recording.metadata.items()},
        sample_counts={s.topic: len(s) for s in streams},
    )


def read_trial(path: str | Path) -> TrialData:
    """Read every channel of an MCAP trial columnarly through :class:`imulog.archive.TrialReader`."""
    from imulog.archive import TrialReader  # imported lazily: the viewer also works on in-memory trials

    path = Path(path)
    streams: list[Any] = []
    channel_meta: dict[str, dict[str, Any]] = {}
    counts: dict[str, int] = {}
    with TrialReader(path) as trial:
        for info in trial.channels:
            channel_meta[info.topic] = dict(info.metadata or {})
            counts[info.topic] = int(info.sample_count)
        for topic in trial.topics():
            streams.append(trial.read(topic))
        metadata = {k: dict(v) for k, v in trial.metadata.items()}
    return TrialData(
        label=path.stem,
        streams=streams,
        metadata=metadata,
        channel_meta=channel_meta,
        sample_counts=counts,
        source=path,
    )
