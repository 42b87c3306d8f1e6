"""Viewer twins of a stored channel rebuilt block by block, in bounded memory (issue 24).

When an append changes the trial's alignment, the twins of the orientations and of the raw reference-clock
markers and events are rewritten on the new axis (:func:`imulog.archive.writer.plan_append`, through
:func:`stored_twins`). Reading a whole orientation channel for that costs a week's recording 4.6 GB (60 M
samples); the twins keep one sample in :func:`imulog.archive.twins.decimation`'s ``k``. :func:`kept_samples`
reads the channel chunk by chunk and keeps only those samples, so memory is the kept samples plus one chunk
(about 2 MiB) plus the first :data:`MEDIAN_SAMPLES` samples' intervals. The twins built from the kept samples
(orientation frames and axes, marker point clouds) are the ones the whole channel gives whenever the channel has
at most :data:`MEDIAN_SAMPLES` samples (the median sampling interval is then taken over all of them, as
:func:`~imulog.archive.twins.decimation` does); longer channels take it over their first :data:`MEDIAN_SAMPLES`
samples. An event channel's twin has one message per interval: its blocks' twins are joined in order
(:func:`joined_log_twin`), so memory is one block plus the messages."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from imulog.archive.timeline import LogMap
from imulog.archive.twins import (
    AXES_RATE_HZ,
    ORIENTATION_COLUMNS,
    TWIN_RATE_HZ,
    Origin,
    Twin,
    decimation_step,
    log_twin,
    marker_twin,
    orientation_twins,
)
from imulog.model import Intervals, MarkerStream, SignalStream, concat_samples, first_pieces, take_samples

MEDIAN_SAMPLES = 1_000_000  # samples whose intervals give the median sampling interval (8 MB of int64)


def kept_samples(
    blocks: Callable[[], Iterator[Any]], n: int, rates_hz: Sequence[float] = (TWIN_RATE_HZ, AXES_RATE_HZ)
) -> tuple[Any, list[np.ndarray]] | None:
    """The samples a twin at each of ``rates_hz`` keeps of a channel, read block by block.

    ``blocks``: a fresh iterator over the channel's pieces in time order (e.g. ``TrialReader.iter_blocks``);
    ``n``: its sample count (0: unknown, counted in a first pass). Returns the union of the kept samples as
    one stream and, per rate, the indices into it of that twin's samples; None for an empty channel.
    """
    if n <= 0:
        n = sum(len(b.t_ns) for b in blocks())
    it = blocks()
    head, seen = first_pieces(it, MEDIAN_SAMPLES, lambda block: len(block.t_ns))
    if not head:
        return None
    if seen < MEDIAN_SAMPLES:  # the whole channel is in ``head``: its own count
        n = seen
    t_head = np.concatenate([np.asarray(b.t_ns, dtype=np.int64) for b in head])
    median = float(np.median(np.diff(t_head))) if len(t_head) > 1 else 0.0
    steps = [decimation_step(n, median, r) if n > 1 else 1 for r in rates_hz]
    del t_head
    parts: list[Any] = []
    flags: list[np.ndarray] = []
    offset = 0

    def take(block: Any) -> None:
        nonlocal offset
        index = offset + np.arange(len(block.t_ns))
        hit = np.stack([index % k == 0 for k in steps])  # (rates, samples): which twin keeps which sample
        union = hit.any(axis=0)
        if union.any():
            parts.append(take_samples(block, np.flatnonzero(union)))
            flags.append(hit[:, union])
        offset += len(block.t_ns)

    for block in head:
        take(block)
    head.clear()
    for block in it:
        take(block)
    hit = np.concatenate(flags, axis=1)
    return concat_samples(parts), [np.flatnonzero(row) for row in hit]


def joined_log_twin(blocks: Iterable[Intervals], log_map: LogMap, clock: str) -> Twin | None:
    """:func:`~imulog.archive.twins.log_twin` of an interval channel given block by block (in channel order): each
    block's messages in turn, the count summed and the span widened; None when the channel holds no interval."""
    twin: Twin | None = None
    for block in blocks:
        if not len(block):
            continue
        part = log_twin(block, log_map, clock)
        if twin is None:
            twin = part
            continue
        twin.log_times.extend(part.log_times)
        twin.payloads.extend(part.payloads)
        meta, new = twin.metadata, part.metadata
        meta["sample_count"] = str(int(meta["sample_count"]) + int(new["sample_count"]))
        meta["start_ns"] = str(min(int(meta["start_ns"]), int(new["start_ns"])))
        meta["end_ns"] = str(max(int(meta["end_ns"]), int(new["end_ns"])))
    return twin


def stored_twins(
    kind: str,
    blocks: Callable[[], Iterator[Any]],
    n: int,
    log_map: LogMap,
    clock: str,
    metadata: Mapping[str, Mapping[str, Any]] | None = None,
    origin: Origin | None = None,
) -> list[Twin]:
    """The viewer twins of a stored channel read block by block, equal to
    :func:`~imulog.archive.twins.twins_for` of the whole channel (see the module docstring for the median).

    ``kind``: ``"orientation"`` (a ``/derived/orientation/{imu}`` channel), ``"markers"`` or ``"intervals"``;
    ``blocks`` and ``n`` as :func:`kept_samples`. Other kinds, and a channel that is not what ``kind`` says, give [].
    """
    if kind == "intervals":
        twin = joined_log_twin(blocks(), log_map, clock)
        return [twin] if twin is not None else []
    if kind not in ("orientation", "markers"):
        return []
    kept = kept_samples(blocks, n, (TWIN_RATE_HZ, AXES_RATE_HZ) if kind == "orientation" else (TWIN_RATE_HZ,))
    if kept is None:
        return []
    stream, keeps = kept
    if kind == "markers":
        return [marker_twin(stream, log_map, keeps[0])] if isinstance(stream, MarkerStream) else []
    if not isinstance(stream, SignalStream) or stream.columns[:4] != ORIENTATION_COLUMNS:
        return []
    return orientation_twins(stream, log_map, clock, metadata, origin, (keeps[0], keeps[1]))
