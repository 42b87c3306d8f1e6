"""The evaluate step window by window: the repetitions grouped into spans of at most ``span_s``, each span's
trajectories and reference read on their own (issue 24: bounded memory at any length).

The per-repetition errors only see the samples inside each repetition, and the reference is interpolated
between its valid samples nearest each trajectory sample, so reading each span with ``pad_s`` of reference
either side gives the rows of the whole computation exactly (``tests/test_evaluate_windows.py``). One case
needs to know about samples outside the span: a trajectory sample exactly on the first valid reference sample
of the span, the previous valid one lying before the padding (then more than ``max_gap_s`` away: NaN in the
whole computation). The first valid reference time of the whole channel, gathered in a first pass block by
block, settles it.

Only trajectory samples between the reference's first and last valid sample can have a valid reference (the
interpolation is NaN outside them, and the errors use only samples with a valid reference), so each span's
trajectories are read within that extent and spans outside it are not read at all: a week-long trajectory
evaluated against an hour of markers reads about an hour, even when one repetition (or a trajectory without
repetitions) spans the whole week.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

SPAN_S = 1800.0  # at most this much recording read at once (half an hour of three methods: a few MB)
PAD_S = 1.0  # reference read either side of a span (>= max_gap_s)


def reference_part(stream: Any, source: str) -> tuple[np.ndarray, np.ndarray]:
    """(t_ns, position (N, 3) m) of one piece of a reference channel named by ``source`` (see
    :func:`imulog.steps.evaluate.reference_source`)."""
    topic, _, marker = source.partition(":")
    if not marker:  # a pose channel (cluster_pose), or any stream of (N, 3) positions
        pos = getattr(stream, "position", None)
        return np.asarray(stream.t_ns, np.int64), np.asarray(stream.values if pos is None else pos, np.float64)
    if marker in stream.labels:
        return stream.t_ns, stream.pos[:, stream.labels.index(marker)]
    labels = [label.split(":")[-1] for label in stream.labels]
    return stream.t_ns, stream.pos[:, labels.index(marker.split(":")[-1])]


def valid_extent(trial: Any, source: str) -> tuple[int, int] | None:
    """Times (ns) of the reference's first and last finite samples, None when it has none (a pass over the
    channel, one chunk at a time)."""
    first = last = None
    for block in trial.iter_blocks(source.partition(":")[0]):
        t, pos = reference_part(block, source)
        ok = np.flatnonzero(np.all(np.isfinite(np.asarray(pos, np.float64)), axis=1))
        if len(ok):
            t = np.asarray(t, np.int64)
            first = int(t[ok[0]]) if first is None else first
            last = int(t[ok[-1]]) if last is None else max(last, int(t[ok[-1]]))
    return None if first is None else (first, last)


def spans_of(windows: list[dict[str, Any]], span_s: float = SPAN_S) -> Iterator[list[dict[str, Any]]]:
    """Consecutive repetitions (in the record's order) grouped while their extent stays within ``span_s``."""
    group: list[dict[str, Any]] = []
    lo = hi = 0
    for w in windows:
        a, b = int(w["start_ns"]), int(w["end_ns"])
        if group and (max(hi, b) - min(lo, a)) * 1e-9 > span_s:
            yield group
            group = []
        lo, hi = (a, b) if not group else (min(lo, a), max(hi, b))
        group.append(w)
    if group:
        yield group


def windowed_rows(
    trial: Any,
    channels: dict[str, str],
    source: str,
    windows: list[dict[str, Any]],
    max_gap_s: float,
    rows_of: Any,
    interpolate: Any,
    span_s: float = SPAN_S,
) -> dict[str, list[dict[str, Any]]]:
    """{method: per-repetition error rows} of ``channels`` (method -> topic) against ``source``, span by span;
    ``rows_of(t_ns, pos, ref, spans)`` and ``interpolate(t_ref, pos_ref, t_ns, max_gap_s)`` are the whole
    computation's functions (:mod:`imulog.steps.evaluate`)."""
    pad = int(max(PAD_S, 2.0 * max_gap_s) * 1e9)
    out: dict[str, list[dict[str, Any]]] = {m: [] for m in channels}
    extent = valid_extent(trial, source)
    if extent is None:  # no valid reference: no rows (as in the whole computation)
        return out
    first, last = extent
    ref_topic = source.partition(":")[0]
    for group in spans_of(windows, span_s):
        lo = max(first, min(int(w["start_ns"]) for w in group))  # only where the reference can be valid
        hi = min(last, max(int(w["end_ns"]) for w in group))
        if lo > hi:
            continue  # these repetitions lie outside the reference: no rows, nothing read
        ref_t, ref_pos = reference_part(trial.read(ref_topic, lo - pad, hi + pad + 1), source)
        ref_t, ref_pos = np.asarray(ref_t, np.int64), np.asarray(ref_pos, np.float64)
        ok = np.all(np.isfinite(ref_pos), axis=1)
        head = int(ref_t[ok][0]) if ok.any() else None
        for method, topic in channels.items():
            s = trial.read(topic, lo, hi + 1)
            t_ns = np.asarray(s.t_ns, np.int64)
            ref = interpolate(ref_t, ref_pos, t_ns, max_gap_s)
            if head is not None and first < head and head >= lo:
                ref[t_ns == head] = np.nan  # its previous valid sample lies before the padding: > max_gap_s away
            out[method] += rows_of(t_ns, np.asarray(s.values, np.float64), ref, group)
    return out
