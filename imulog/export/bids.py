"""BIDS-motion export: one dataset folder per trial (BIDS 1.9+ "motion" data type).

::

    OUT/dataset_description.json   participants.tsv
    OUT/sub-<subject>/motion/sub-<subject>_task-<task>_tracksys-<system>_run-<trial>_motion.tsv   (no header)
                                   ..._run-<trial>_channels.tsv   ..._run-<trial>_motion.json
                                   sub-<subject>_task-<task>_run-<trial>_events.tsv            (from the phases)

One tracking system per device: each IMU (``ACCEL``/``GYRO``/``MAGN`` x, y, z in m/s^2, rad/s, uT,
plus ``ORNT`` quat_w..quat_z from ``/derived/orientation/{imu}`` when present) and each marker
channel (``POS`` x, y, z in m per marker). Every file starts with a ``LATENCY`` channel: seconds of
each sample from the trial's start on the chosen clock, so the systems (and ``events.tsv`` onsets,
seconds on the same axis) line up and gaps are explicit. Missing values are ``n/a``.
"""

from __future__ import annotations

import json
import re
import sys
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog import __version__
from imulog.archive.trial_clock import seconds_from, trial_clock
from imulog.export._atomic import ExportError, atomic_folder
from imulog.export.table import ExportResult

if TYPE_CHECKING:
    from imulog.archive.reader import TrialReader

BIDS_VERSION = "1.10.0"
_AXES = ("x", "y", "z")
_IMU_TYPES = (("acc", "ACCEL", "m/s^2"), ("gyr", "GYRO", "rad/s"), ("mag", "MAGN", "uT"))


def bids_label(value: Any, fallback: str) -> str:
    """A BIDS entity label: letters and digits only (``S 01-a`` -> ``S01a``)."""
    text = re.sub(r"[^A-Za-z0-9]", "", str(value if value not in (None, "") else fallback))
    return text or fallback


def tsv(rows: list[list[Any]], header: list[str] | None = None) -> str:
    """Tab-separated text; NaN and None as ``n/a``."""

    def cell(v: Any) -> str:
        if v is None:
            return "n/a"
        if isinstance(v, float | np.floating):
            return "n/a" if not np.isfinite(v) else repr(float(v))
        return str(v)

    lines = (["\t".join(header)] if header else []) + ["\t".join(cell(v) for v in r) for r in rows]
    return "\n".join(lines) + "\n"


#: rows of ``_motion.tsv`` formatted at a time: the text of all rows at once took 8.4 GB for a day at 50 Hz
MOTION_ROWS_PER_PIECE = 100_000


def write_matrix_tsv(path: Path, columns: list[np.ndarray], rows_per_piece: int | None = None) -> None:
    """:func:`matrix_tsv` of ``columns`` written to ``path`` ``rows_per_piece`` rows at a time (the same bytes,
    in bounded memory): :func:`write_pieces_tsv` of the columns as one piece."""
    write_pieces_tsv(path, [columns], len(columns[0]) if columns else 0, rows_per_piece)


def write_pieces_tsv(
    path: Path, pieces: Iterable[list[np.ndarray]], total_rows: int, rows_per_piece: int | None = None
) -> tuple[int, float, float]:
    """The ``_motion.tsv`` of a channel read block by block: each piece's columns (the first: latency, s) as
    :func:`matrix_tsv` text, ``rows_per_piece`` rows at a time, so the file is the bytes of the whole columns and
    memory holds one block. On a terminal a bar ticks per ``rows_per_piece`` of ``total_rows``
    (:func:`imulog.console.progress_bar`). Returns (rows, first latency, last latency) for the sidecar."""
    from imulog.console import progress_bar

    rows_per_piece = rows_per_piece or MOTION_ROWS_PER_PIECE
    ticks = -(-total_rows // rows_per_piece)
    bar = progress_bar(ticks, path.name, unit="piece") if ticks > 1 and sys.stderr.isatty() else None
    rows, first, last, done = 0, float("nan"), float("nan"), 0
    try:
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            for columns in pieces:
                n = len(columns[0]) if columns else 0
                for lo in range(0, n, rows_per_piece):
                    f.write(matrix_tsv([c[lo : lo + rows_per_piece] for c in columns]))
                if n:
                    first = float(columns[0][0]) if rows == 0 else first
                    last, rows = float(columns[0][-1]), rows + n
                    if bar is not None and rows // rows_per_piece > done:
                        bar.update(rows // rows_per_piece - done)
                        done = rows // rows_per_piece
    finally:
        if bar is not None:
            bar.close()
    return rows, first, last


def matrix_tsv(columns: list[np.ndarray]) -> str:
    """A header-less TSV of float columns with ``n/a`` for NaN (the ``_motion.tsv`` body)."""
    if not columns:
        return ""
    data = np.column_stack([np.asarray(c, np.float64) for c in columns])
    text = np.char.mod("%.17g", data)
    text[~np.isfinite(data)] = "n/a"
    return "\n".join("\t".join(r) for r in text) + "\n"


def _system(
    name: str,
    kind: str,
    chans: list[tuple[str, str, str, str, str]],
    pieces: Callable[[], Iterator[list[np.ndarray]]],
    total_rows: int,
    rate: float,
    meta: dict[str, Any],
    task: str,
) -> dict[str, Any]:
    """One tracking system: channel rows (name, component, type, tracked_point, units) and ``pieces()``, its
    columns block by block (latency first, then one per channel row)."""
    return {
        "name": name,
        "kind": kind,
        "channels": chans,
        "pieces": pieces,
        "total_rows": total_rows,
        "rate": rate,
        "meta": meta,
        "task": task,
    }


def _effective_rate(rows: int, first: float, last: float) -> float | str:
    return float((rows - 1) / (last - first)) if rows > 1 and last > first else "n/a"


def _blocks(trial, topic: str) -> Iterator[Any]:
    """``topic`` block by block (:meth:`TrialReader.iter_blocks`); an empty channel as its one empty stream."""
    empty = True
    for block in trial.iter_blocks(topic):
        empty = False
        yield block
    if empty:
        yield trial.read(topic)


class _Rows:
    """A channel's blocks handed out ``n`` rows at a time: another channel's rows lined up with these blocks.

    Holds the blocks that the rows not yet handed out are in, and no copy of them: a take within one block is a
    view of it; one across blocks copies its ``n`` rows only. (It concatenated what was left with each new block
    and kept a view of that copy, so it held up to about three blocks, more the longer the channel: 12.9 MB traced
    peak at 400,000 rows, 14.0 MB at 1.6 M, for quaternion blocks of 112,750 rows taken 42,500 at a time.)"""

    def __init__(self, blocks: Iterator[Any]) -> None:
        self._blocks = blocks
        self._queue: deque[tuple[np.ndarray, np.ndarray]] = deque()  # (t_ns, values), non-empty blocks
        self._at = 0  # rows of the first queued block already handed out
        self._n = 0  # rows queued and not handed out

    def take(self, n: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The next ``n`` rows as (``t_ns``, ``values``); None when the channel has fewer left."""
        while self._n < n:
            block = next(self._blocks, None)
            if block is None:
                return None
            if len(block.t_ns):
                self._queue.append((np.asarray(block.t_ns), np.asarray(block.values)))
                self._n += len(block.t_ns)
        times, values = [], []
        left = n
        while left:
            t, v = self._queue[0]
            k = min(left, len(t) - self._at)
            times.append(t[self._at : self._at + k])
            values.append(v[self._at : self._at + k])
            self._at, left = self._at + k, left - k
            if self._at == len(t):
                self._queue.popleft()
                self._at = 0
        self._n -= n
        if len(times) == 1:
            return times[0], values[0]
        if not times:  # n == 0 (an empty channel)
            return np.zeros(0, np.int64), np.zeros((0, self._queue[0][1].shape[1] if self._queue else 0))
        return np.concatenate(times), np.concatenate(values)

    def exhausted(self) -> bool:
        return self._n == 0 and all(len(b.t_ns) == 0 for b in self._blocks)


def _same_stamps(trial, topic: str, other: str) -> bool:
    """True when ``other`` has exactly ``topic``'s time stamps (the orientation step writes on the IMU's own),
    compared block by block."""
    rows = _Rows(trial.iter_blocks(other))
    for block in trial.iter_blocks(topic):
        got = rows.take(len(block.t_ns))
        if got is None or not np.array_equal(got[0], block.t_ns):
            return False
    return rows.exhausted()


def _imu_pieces(trial, tc, topic: str, groups: list[str], ori_topic: str | None) -> Iterator[list[np.ndarray]]:
    """An IMU's motion columns block by block: latency (s), the x/y/z of each of ``groups``, then the
    quaternion of ``ori_topic`` (lined up row for row) when given."""
    quats = _Rows(trial.iter_blocks(ori_topic)) if ori_topic else None
    for s in _blocks(trial, topic):
        cols = [seconds_from(tc.times(topic, s.t_ns), tc.origin_ns)]
        for group in groups:
            arr = getattr(s, group)
            cols += [arr[:, k] for k in range(len(_AXES))]
        if quats is not None and not len(s.t_ns):  # an empty channel (and orientation): empty columns
            cols += [np.zeros(0)] * 4
        elif quats is not None:
            got = quats.take(len(s.t_ns))
            if got is None:  # _same_stamps checked the row counts before anything was written
                raise ExportError(f"{trial.path}: {ori_topic} ended before {topic}")
            cols += [got[1][:, k] for k in range(4)]
        yield cols


def _marker_pieces(trial, tc, topic: str) -> Iterator[list[np.ndarray]]:
    """A marker channel's motion columns block by block: latency (s), then x/y/z of each marker (NaN invalid)."""
    for mk in _blocks(trial, topic):
        pos = np.where(mk.valid[:, :, None], mk.pos, np.nan)
        cols = [seconds_from(tc.times(topic, mk.t_ns), tc.origin_ns)]
        cols += [pos[:, j, k] for j in range(pos.shape[1]) for k in range(len(_AXES))]
        yield cols


def export_bids(
    trial: TrialReader, out: str | Path, *, clock: str = "device", imu: str | None = None, overwrite: bool = False
) -> ExportResult:
    """Write the trial as a BIDS-motion dataset folder ``out`` (atomically: a temporary folder renamed)."""
    tc = trial_clock(trial, clock, imu)
    md = trial.metadata
    rec = md.get("imulog.trial", {})
    sub = bids_label(rec.get("subject"), "01")
    task = bids_label(rec.get("task"), "unknown")
    run = rec.get("trial")
    run_entity = f"_run-{int(run)}" if isinstance(run, int) and run >= 0 else ""
    stem = f"sub-{sub}_task-{task}{run_entity}"  # events; motion files put tracksys before run
    topics = trial.topics()
    systems: list[dict[str, Any]] = []
    for topic in [t for t in topics if t.startswith("/imu/") and t.count("/") == 2]:
        name = topic.rsplit("/", 1)[1]
        info = trial.channel(topic)
        first = next(_blocks(trial, topic))  # which quantities the IMU has
        groups = [g for g, _, _ in _IMU_TYPES if getattr(first, g) is not None]
        chans = [
            (f"{name}_{group}_{a}", a, typ, name, unit)
            for group, typ, unit in _IMU_TYPES
            if group in groups
            for a in _AXES
        ]
        ori_topic: str | None = f"/derived/orientation/{name}"
        if ori_topic in topics and _same_stamps(trial, topic, ori_topic):
            chans += [(f"{name}_{c}", c, "ORNT", name, "n/a") for c in ("quat_w", "quat_x", "quat_y", "quat_z")]
        else:
            ori_topic = None
        dev = md.get(f"imulog.device.{name}", {})
        systems.append(
            _system(
                bids_label(name, "imu"),
                "imu",
                chans,
                partial(_imu_pieces, trial, tc, topic, groups, ori_topic),
                info.sample_count,
                float(dev.get("rate_hz") or info.rate_hz or 0.0),
                dev,
                task,
            )
        )
    for topic in [t for t in topics if t.startswith("/markers/")]:
        name = topic.rsplit("/", 1)[1]
        info = trial.channel(topic)
        labels = next(_blocks(trial, topic)).labels
        chans = [(f"{label}_{a}", a, "POS", label, "m") for label in labels for a in _AXES]
        dev = md.get(f"imulog.device.{name}", {})
        systems.append(
            _system(
                bids_label(name, "markers"),
                "markers",
                chans,
                partial(_marker_pieces, trial, tc, topic),
                info.sample_count,
                float(dev.get("rate_hz") or info.rate_hz or 0.0),
                dev,
                task,
            )
        )
    if not systems:
        raise ExportError(f"{trial.path}: no IMU or marker channel to export to BIDS-motion")
    events = []
    for topic in [t for t in topics if t.startswith("/derived/phases/") or t.startswith("/events/")]:
        iv = trial.read(topic)
        a = seconds_from(tc.times(topic, iv.start_ns), tc.origin_ns)
        b = seconds_from(tc.times(topic, iv.end_ns), tc.origin_ns)
        for k in range(len(iv)):
            events.append(
                [round(float(a[k]), 9), round(float(b[k] - a[k]), 9), str(iv.labels[k]), int(iv.task_index[k]), topic]
            )
    events.sort(key=lambda r: r[0])
    files: list[str] = []
    rows = 0
    with atomic_folder(out, overwrite=overwrite) as tmp:
        desc = {
            "Name": f"imulog trial {Path(str(trial.path)).name}",
            "BIDSVersion": BIDS_VERSION,
            "DatasetType": "raw",
            "GeneratedBy": [{"Name": "imulog", "Version": __version__}],
        }
        (tmp / "dataset_description.json").write_text(json.dumps(desc, indent=2) + "\n")
        (tmp / "participants.tsv").write_text(tsv([[f"sub-{sub}"]], ["participant_id"]))
        folder = tmp / f"sub-{sub}" / "motion"
        folder.mkdir(parents=True)
        for sysd in systems:
            base = f"sub-{sub}_task-{task}_tracksys-{sysd['name']}{run_entity}"
            chans = [("latency", "n/a", "LATENCY", "n/a", "s"), *sysd["channels"]]
            n, first, last = write_pieces_tsv(folder / f"{base}_motion.tsv", sysd["pieces"](), sysd["total_rows"])
            ch_rows = [[c[0], c[1], c[2], c[3], c[4], sysd["rate"] or "n/a"] for c in chans]
            (folder / f"{base}_channels.tsv").write_text(
                tsv(ch_rows, ["name", "component", "type", "tracked_point", "units", "sampling_frequency"])
            )
            counts: dict[str, int] = {}
            for c in chans:
                counts[c[2]] = counts.get(c[2], 0) + 1
            dev = sysd["meta"]
            sidecar: dict[str, Any] = {
                "TaskName": sysd["task"],
                "TrackingSystemName": sysd["name"],
                "SamplingFrequency": sysd["rate"] or "n/a",
                "SamplingFrequencyEffective": _effective_rate(n, first, last),
                "RecordingDuration": float(last - first) if n > 1 else 0.0,
                "MotionChannelCount": len(chans),
                "TrackedPointsCount": len({c[3] for c in sysd["channels"]}),
                "MissingValues": "n/a",
                "SoftwareVersions": f"imulog {__version__}",
                **{f"{typ}ChannelCount": n for typ, n in sorted(counts.items())},
            }
            if dev.get("model"):
                sidecar["ManufacturersModelName"] = str(dev["model"])
            if dev.get("serial"):
                sidecar["DeviceSerialNumber"] = str(dev["serial"])
            sidecar["imulog"] = {"source": str(trial.path), **tc.record()}
            (folder / f"{base}_motion.json").write_text(json.dumps(sidecar, indent=2) + "\n")
            files += [f"{base}_motion.tsv", f"{base}_channels.tsv", f"{base}_motion.json"]
            rows += n
        (folder / f"{stem}_events.tsv").write_text(
            tsv(events, ["onset", "duration", "trial_type", "repetition", "source"])
        )
        (folder / f"{stem}_events.json").write_text(
            json.dumps(
                {
                    "onset": {"Description": "seconds from the trial's start on the chosen clock", "Units": "s"},
                    "duration": {"Description": "phase or event duration", "Units": "s"},
                    "trial_type": {"Description": "phase label (reach, lift, return_bottle, return_hand, movement...)"},
                    "repetition": {"Description": "task repetition (task_index), 0 = none"},
                    "source": {"Description": "imulog channel the event comes from"},
                },
                indent=2,
            )
            + "\n"
        )
        files += [f"{stem}_events.tsv", f"{stem}_events.json"]
    return ExportResult(
        path=str(out),
        format="bids",
        clock=clock,
        rows=rows,
        columns=[],
        topics=[],
        files=[f"sub-{sub}/motion/{f}" for f in files],
        notes=tc.export_notes(),
    )
