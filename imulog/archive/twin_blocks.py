"""Viewer twins of a stored channel rebuilt block by block, in bounded memory (issue 24).

When an append changes the trial's alignment, the orientation twins are rewritten on the new axis
(:func:`imulog.archive.writer.plan_append`). Reading the whole orientation channel for that costs a week's
recording 4.6 GB (60 M samples); the twins keep one sample in :func:`imulog.archive.twins.decimation`'s ``k``.
:func:`kept_samples` reads the channel chunk by chunk and keeps only those samples, so memory is the kept
samples plus one chunk (about 2 MiB) plus the first :data:`MEDIAN_SAMPLES` samples' intervals. The twins
built from the kept samples are the ones the whole channel gives whenever the channel has at most
:data:`MEDIAN_SAMPLES` samples (the median sampling interval is then taken over all of them, as
:func:`~imulog.archive.twins.decimation` does); longer channels take it over their first
:data:`MEDIAN_SAMPLES` samples.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from imulog.archive.twins import AXES_RATE_HZ, TWIN_RATE_HZ, decimation_step
from imulog.model import concat_samples, take_samples

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
    head: list[Any] = []
    seen = 0
    for block in it:
        head.append(block)
        seen += len(block.t_ns)
        if seen >= MEDIAN_SAMPLES:
            break
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
