"""The trajectory step on a recording longer than one window: the movements between rests, window by window.

Every method resets its velocity at rests, so a recording is cut only at rests
(:func:`imulog.steps.windows.rest_windows`): consecutive movements between rests make up a window of at most
``core_s`` seconds, never cut inside a repetition's phases, read with the rest before and after it, and each
window is reconstructed on its own by :func:`imulog.steps.trajectory.compute_trajectories` (the step's one
implementation; a lab trial is one window and computed as a whole). A stretch without a rest longer than
``max_s`` is cut and flagged (``imulog.trajectory["windows"]["split"]``): dead reckoning cannot bound it. A window
whose samples cannot be reconstructed (every repetition across a long gap) is listed, not fatal.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from imulog.model import Intervals, SignalStream
from imulog.process.segmentation.dynamos import runs
from imulog.steps.sample_window import SampleWindow
from imulog.steps.windows import RestWindow, rest_windows

F32 = {"precision": "float32"}  # trajectories in m stored as float32: under a micrometre on metres (docs/schemas.md)


@dataclass(frozen=True)
class TrajectoryWindows:
    """Longest window (s), longest stretch without a rest before it is cut and flagged (s), shortest rest (s)
    a window may be cut at, most of a rest read beside a movement (s: the middle of a longer rest, a night, is
    reconstructed in rest-only windows, so memory does not grow with the longest rest), and the shortest rest (s)
    where the heading carried through rests restarts (``AnchorParams.heading="gyroscope"``,
    :mod:`imulog.process.anchor_heading`). Windows are cut at rests of at least ``chain_rest_s`` outside the
    repetitions, where the whole computation restarts the heading too; a stretch between two such rests longer than
    ``max_s`` may also be cut at its rests of at least ``min_rest_s`` (the heading then restarts there in the window
    only: flagged as ``split``, as a stretch without any rest is). Half-hour windows (a lab trial is one): the
    reconstruction holds about 15 MB per minute of recording (every method's arrays), and results do not depend
    on where the rests cut (tests/test_phases_windows.py)."""

    core_s: float = 1800.0
    max_s: float = 600.0
    min_rest_s: float = 1.0
    context_s: float = 600.0
    chain_rest_s: float = 30.0

    def to_dict(self) -> dict[str, float]:
        return {
            "core_s": self.core_s,
            "max_s": self.max_s,
            "min_rest_s": self.min_rest_s,
            "context_s": self.context_s,
            "chain_rest_s": self.chain_rest_s,
        }


def has_r2g(phases: Intervals | None) -> bool:
    """Whether some repetition of ``phases`` has the four R2G phases (what ``optimized`` models)."""
    if phases is None or not len(phases):
        return False
    k = np.asarray(phases.task_index)
    return bool((np.unique(k[k >= 0], return_counts=True)[1] == 4).any())


def _blocks(trial: Any, topic: str, kind: str) -> Iterator[tuple]:
    for b in trial.iter_blocks(topic):
        if kind == "imu":
            yield np.asarray(b.t_ns, np.int64), b.gyr
        else:
            yield np.asarray(b.t_ns, np.int64), np.asarray(b.values, dtype=np.float64)


def static_rests(trial: Any, topic: str, total: int, rate_hz: float, min_rest_s: float) -> list[tuple[int, int]]:
    """Runs of ``static == 1`` of the phases' mask of at least ``min_rest_s`` (sample intervals), block by block."""
    out: list[tuple[int, int]] = []
    open_start, pos = None, 0
    shortest = max(1, int(round(min_rest_s * rate_hz)))
    for _, values in _blocks(trial, topic, "signal"):
        s, e = runs(np.asarray(values)[:, 0] > 0.5)
        s, e = s + pos, e + pos
        if open_start is not None:
            if len(s) and s[0] == pos:
                s[0] = open_start
            else:
                out.append((open_start, pos))
            open_start = None
        n = len(values)
        if len(e) and e[-1] == pos + n:
            open_start, s, e = int(s[-1]), s[:-1], e[:-1]
        out.extend((int(a), int(b)) for a, b in zip(s, e, strict=True))
        pos += n
    if open_start is not None:
        out.append((open_start, pos))
    if pos != total:
        raise ValueError(f"{topic} has {pos:,} samples, not one per sample of the {total:,} it should mark")
    return [(a, b) for a, b in out if b - a >= shortest]


def plan(
    trial: Any,
    static_topic: str | None,
    phases: Intervals | None,
    t_first: int,
    total: int,
    rate_hz: float,
    windows: TrajectoryWindows,
    to_device: Any,
) -> list[RestWindow]:
    """The windows of a recording (one when it fits a core), repetitions kept whole, cut at the rests of at least
    ``chain_rest_s`` and, within a longer stretch than ``max_s`` between two of them, at its rests of at least
    ``min_rest_s`` (windows joined at one of those are marked ``split``)."""
    rests = [] if static_topic is None else static_rests(trial, static_topic, total, rate_hz, windows.min_rest_s)
    rests, extra = chain_rests(rests, total, rate_hz, windows)
    keep: list[tuple[int, int]] = []
    if phases is not None and len(phases):
        start = to_device(np.asarray(phases.start_ns, np.int64))
        end = to_device(np.asarray(phases.end_ns, np.int64))
        for k in np.unique(phases.task_index[phases.task_index >= 0]):
            sel = phases.task_index == k
            a = int(round((int(start[sel].min()) - t_first) * 1e-9 * rate_hz))
            b = int(round((int(end[sel].max()) - t_first) * 1e-9 * rate_hz)) + 1
            keep.append((a, b))
    out = rest_windows(
        rests,
        total,
        rate_hz,
        core_s=windows.core_s,
        max_s=windows.max_s,
        keep_together=keep,
        context_s=windows.context_s,
    )
    if not extra:
        return out
    # a join in the middle of such a rest: the window restarts the heading there, the whole computation does not
    cut = {w.core_lo for w in out[1:] if any(a <= w.core_lo < b for a, b in extra)}
    return [replace(w, split=w.split or w.core_lo in cut or w.core_hi in cut) for w in out]


def chain_rests(
    rests: list[tuple[int, int]], total: int, rate_hz: float, windows: TrajectoryWindows
) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """The rests a window may be cut at: those of at least ``chain_rest_s``, and every rest of ``rests`` inside a
    stretch longer than ``max_s`` between two of them (the recording's ends count as such rests); the second list
    holds the latter (sample intervals)."""
    chain = max(1, int(round(windows.chain_rest_s * rate_hz)))
    longest = max(1, int(round(windows.max_s * rate_hz)))
    long_ = [r for r in rests if r[1] - r[0] >= chain]
    bounds = [(0, 0), *long_, (total, total)]
    extra = []
    for (_, a), (b, _) in zip(bounds[:-1], bounds[1:], strict=True):
        if b - a > longest:
            extra += [r for r in rests if a <= r[0] and r[1] <= b and r[1] - r[0] < chain]
    return sorted(long_ + extra), extra


def merge_records(records: list[dict[str, Any]], skipped: list[dict], split: list[dict], windows: Any) -> dict:
    """One ``imulog.trajectory`` record from the windows' records: repetitions and merges concatenated, rests and
    gaps summed, a method's checks failed when they failed in any window."""
    out: dict[str, Any] = {}
    for rec in records:
        for key in ("imu", "baseline", "clock", "frame", "origin", "orientation"):
            if key in rec:
                out[key] = rec[key]
        out.setdefault("methods", [])
        out["methods"] += [m for m in rec.get("methods", []) if m not in out["methods"]]
        out.setdefault("repetitions", []).extend(rec.get("repetitions", []))
        if rec.get("merged_repetitions"):
            out.setdefault("merged_repetitions", []).extend(rec["merged_repetitions"])
        if "flagged_repetitions" in rec:
            out.setdefault("flagged_repetitions", []).extend(rec["flagged_repetitions"])
        for key in ("rests",):
            if key in rec:
                acc = out.setdefault(key, {})
                for k, v in rec[key].items():
                    acc[k] = round(acc.get(k, 0) + v, 3) if isinstance(v, (int, float)) else v
        if "gaps" in rec:
            gaps = out.setdefault("gaps", {"repetitions_left_out": []})
            gaps["repetitions_left_out"] += rec["gaps"].get("repetitions_left_out", [])
            for k, v in rec["gaps"].items():
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    gaps[k] = gaps.get(k, 0) + v
        for method, check in (rec.get("checks") or {}).items():
            merged = out.setdefault("checks", {}).setdefault(method, {"ok": True, "failed": [], "windows_failed": 0})
            if not check.get("ok", True):
                merged["ok"] = False
                merged["windows_failed"] += 1
                merged["failed"] += [f for f in check.get("failed", []) if f not in merged["failed"]]
                merged.setdefault("why", check.get("why", ", ".join(check.get("failed", []))))
                if check.get("suggest"):
                    merged.setdefault("suggest", check["suggest"])
        for key in ("skipped", "notes", "waypoints_from"):
            if key in rec:
                out[key] = rec[key]
    for check in (out.get("checks") or {}).values():
        if check["windows_failed"] > 1:
            check["why"] = f"{check['why']} (in {check['windows_failed']} of {len(records)} windows)"
    out["windows"] = {**windows.to_dict(), "count": len(records) + len(skipped), "split": split, "skipped": skipped}
    return out


def trajectory_pieces(
    path: Any,
    name: str,
    topics: dict[str, str | None],
    plan_: list[RestWindow],
    compute: Any,
    record: dict[str, Any],
    out_topics: list[str],
    windows: TrajectoryWindows,
    to_reference: Any,
    total: int,
    frame: str,
    attrs: dict[str, str] | None = None,
    skip_rest_only: bool = False,
) -> Iterator[SignalStream]:
    """Yield each window's trajectories (rows it owns), an empty piece for a topic a window has none of; fill
    ``record`` at the end. ``topics``: acc, static, orientation, imu topics (None when absent); ``compute(acc,
    static, orientation, gyr)`` reconstructs one window (its arguments ``(t_ns, values)``, or None); ``attrs``:
    channel metadata of every piece (a per-IMU trajectory's ``clock``); ``skip_rest_only``: rest-only windows
    give no samples (with phases, trajectories are written for the repetitions only)."""
    from imulog.archive import TrialReader
    from imulog.heap import bound_heap

    bound_heap()  # the same temporaries window after window: keep them out of the heap (imulog.heap)
    records, skipped, split = [], [], []
    with TrialReader(path) as trial:
        bufs = {
            key: SampleWindow(_blocks(trial, topic, "imu" if key == "imu" else "signal"), total)
            for key, topic in topics.items()
            if topic is not None
        }
        for w in plan_:
            got = {key: buf.get(w.lo, w.hi) for key, buf in bufs.items()}
            t = got["acc"][0]
            for key, (tk, _) in got.items():
                if len(tk) != len(t) or tk[0] != t[0]:
                    raise ValueError(f"{topics[key]} is not one row per sample of {topics['acc']} (window {w.index})")
            t_own = to_reference(t[[w.core_lo - w.lo, max(w.core_hi - w.lo - 1, 0)]])
            if w.split:
                split.append({"start_ns": int(t_own[0]), "end_ns": int(t_own[1])})
            if skip_rest_only and w.rest_only:
                streams, rec = [], None
            else:
                try:
                    streams, rec = compute(*(got.get(k) for k in ("acc", "static", "orientation", "imu")))
                except ValueError as exc:
                    skipped.append({"start_ns": int(t_own[0]), "end_ns": int(t_own[1]), "why": str(exc)})
                    streams, rec = [], None
            if rec is not None and not w.rest_only:  # a rest-only window: its samples, not a repetition
                records.append(rec)
            by_topic = {s.topic: s for s in streams}
            for topic in out_topics:
                s = by_topic.get(topic)
                if s is None:
                    empty = np.zeros((0, 3))
                    yield SignalStream(
                        topic,
                        np.zeros(0, np.int64),
                        ["x", "y", "z"],
                        ["m"] * 3,
                        empty,
                        frame_id=frame,
                        attrs=attrs or {},
                    )
                    continue
                keep = (s.t_ns >= t_own[0]) & (s.t_ns <= t_own[1])  # the rows this window owns
                yield SignalStream(
                    topic,
                    s.t_ns[keep],
                    s.columns,
                    s.units,
                    s.values[keep],
                    frame_id=frame,
                    attrs={**(attrs or {}), **F32},
                )
            if w.index + 1 < len(plan_):
                for buf in bufs.values():
                    buf.drop_before(plan_[w.index + 1].lo)
    record.update(merge_records(records, skipped, split, windows))
