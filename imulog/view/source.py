"""Read a trial archive into what the viewer logs: streams, metadata records and channel metadata.

:func:`open_trial` reads the archive's summary and metadata at once and each channel only when the viewer
reaches it (:class:`ArchiveStreams`), so Rerun encodes one channel while the next is read; :func:`read_trial`
reads every channel first (read errors surface before anything is logged).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from imulog.model import Recording
from imulog.view.layout import CLUSTER_POSE_TOPIC


@dataclass
class TrialData:
    """One trial ready to log: ``streams`` (imulog.model objects), ``metadata`` records, ``channel_meta``.

    ``streams`` is a list, or an :class:`ArchiveStreams` that reads each channel as it is iterated.
    """

    label: str
    streams: list[Any] | ArchiveStreams
    metadata: dict[str, dict[str, Any]] = field(default_factory=dict)
    channel_meta: dict[str, dict[str, Any]] = field(default_factory=dict)
    sample_counts: dict[str, int] = field(default_factory=dict)
    source: Path | None = None


def logging_rank(kind: str, topic: str) -> int:
    """Where a channel comes in the viewer's logging order: intervals (small) first, so a viewer still loading a
    long trial already shows the phases; then the Vicon cluster poses (one per IMU of a setup), the reference the IMU trajectories are
    anchored on and compared with; then everything else in its own order."""
    if kind == "intervals":
        return 0
    return 1 if topic == CLUSTER_POSE_TOPIC or topic.startswith(f"{CLUSTER_POSE_TOPIC}/") else 2


class ArchiveStreams:
    """The channels of an archive trial, read one by one as iteration reaches them, in the viewer's logging order.

    Nothing is kept: a channel can be dropped once it is logged. Each iteration opens the archive again; a
    damaged chunk raises :class:`imulog.archive.ArchiveCorruptError` when its channel is reached.
    """

    ordered_for_viewer = True  # log_streams logs them as they come, without sorting (which would read them all)

    def __init__(self, path: Path, topics: list[str]) -> None:
        self.path = Path(path)
        self.topics = list(topics)

    def __len__(self) -> int:
        return len(self.topics)

    def __iter__(self) -> Iterator[Any]:
        from imulog.archive import TrialReader

        with TrialReader(self.path) as trial:
            for topic in self.topics:
                yield trial.read(topic)


def from_recording(recording: Recording, label: str = "trial") -> TrialData:
    """In-memory :class:`imulog.model.Recording` (e.g. from the simulator) -> :class:`TrialData`."""
    streams = recording.streams()
    return TrialData(
        label=label,
        streams=streams,
        metadata={k: dict(v) for k, v in recording.metadata.items()},
        sample_counts={s.topic: len(s) for s in streams},
    )


def open_trial(path: str | Path) -> TrialData:
    """An MCAP trial whose channels are read through :class:`imulog.archive.TrialReader` while they are logged.

    The summary, channel list and metadata records are read now (a truncated file or bad metadata fails here);
    the channels' data when :func:`imulog.view.streams.log_streams` reaches them.
    """
    from imulog.archive import TrialReader  # imported lazily: the viewer also works on in-memory trials

    path = Path(path)
    channel_meta: dict[str, dict[str, Any]] = {}
    counts: dict[str, int] = {}
    with TrialReader(path) as trial:
        kinds: dict[str, str] = {}
        for info in trial.channels:
            channel_meta[info.topic] = dict(info.metadata or {})
            counts[info.topic] = int(info.sample_count)
            kinds[info.topic] = info.kind
        topics = sorted(trial.topics(), key=lambda t: logging_rank(kinds.get(t, ""), t))
        metadata = {k: dict(v) for k, v in trial.metadata.items()}
    return TrialData(
        label=path.stem,
        streams=ArchiveStreams(path, topics),
        metadata=metadata,
        channel_meta=channel_meta,
        sample_counts=counts,
        source=path,
    )


def read_trial(path: str | Path) -> TrialData:
    """Read every channel of an MCAP trial columnarly through :class:`imulog.archive.TrialReader`."""
    data = open_trial(path)
    data.streams = list(data.streams)
    return data
