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
from pathlib import Path
from typing import Any

import numpy as np

from imulog import __version__
from imulog.archive.trial_clock import seconds_from, trial_clock
from imulog.export._atomic import ExportError, atomic_folder
from imulog.export.table import ExportResult

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
    in bounded memory); on a terminal a bar ticks once per piece (:func:`imulog.console.window_progress`)."""
    from imulog.console import window_progress

    rows_per_piece = rows_per_piece or MOTION_ROWS_PER_PIECE
    n = len(columns[0]) if columns else 0
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        for lo in window_progress(range(0, n, rows_per_piece), f"{path.name}", unit="piece"):
            f.write(matrix_tsv([c[lo : lo + rows_per_piece] for c in columns]))


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
    t_s: np.ndarray,
    chans: list[tuple[str, str, str, str, str, np.ndarray]],
    rate: float,
    meta: dict[str, Any],
    task: str,
) -> dict[str, Any]:
    """One tracking system: channel rows (name, component, type, tracked_point, units) and columns."""
    return {"name": name, "kind": kind, "t_s": t_s, "channels": chans, "rate": rate, "meta": meta, "task": task}


def _effective_rate(t_s: np.ndarray) -> float | str:
    return float((len(t_s) - 1) / (t_s[-1] - t_s[0])) if len(t_s) > 1 and t_s[-1] > t_s[0] else "n/a"


def export_bids(
    trial, out: str | Path, *, clock: str = "device", imu: str | None = None, overwrite: bool = False
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
        s = trial.read(topic)
        info = trial.channel(topic)
        t = tc.times(topic, s.t_ns)
        chans = []
        for group, typ, unit in _IMU_TYPES:
            arr = getattr(s, group)
            if arr is None:
                continue
            chans += [(f"{name}_{group}_{a}", a, typ, name, unit, arr[:, k]) for k, a in enumerate(_AXES)]
        ori_topic = f"/derived/orientation/{name}"
        if ori_topic in topics:
            q = trial.read(ori_topic)
            if len(q) == len(s) and np.array_equal(q.t_ns, s.t_ns):
                for k, comp in enumerate(("quat_w", "quat_x", "quat_y", "quat_z")):
                    chans.append((f"{name}_{comp}", comp, "ORNT", name, "n/a", q.values[:, k]))
        dev = md.get(f"imulog.device.{name}", {})
        systems.append(
            _system(
                bids_label(name, "imu"),
                "imu",
                seconds_from(t, tc.origin_ns),
                chans,
                float(dev.get("rate_hz") or info.rate_hz or 0.0),
                dev,
                task,
            )
        )
    for topic in [t for t in topics if t.startswith("/markers/")]:
        name = topic.rsplit("/", 1)[1]
        mk = trial.read(topic)
        info = trial.channel(topic)
        t = tc.times(topic, mk.t_ns)
        pos = np.where(mk.valid[:, :, None], mk.pos, np.nan)
        chans = [
            (f"{label}_{a}", a, "POS", label, "m", pos[:, j, k])
            for j, label in enumerate(mk.labels)
            for k, a in enumerate(_AXES)
        ]
        dev = md.get(f"imulog.device.{name}", {})
        systems.append(
            _system(
                bids_label(name, "markers"),
                "markers",
                seconds_from(t, tc.origin_ns),
                chans,
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
            latency = ("latency", "n/a", "LATENCY", "n/a", "s", sysd["t_s"])
            chans = [latency, *sysd["channels"]]
            write_matrix_tsv(folder / f"{base}_motion.tsv", [c[5] for c in chans])
            ch_rows = [[c[0], c[1], c[2], c[3], c[4], sysd["rate"] or "n/a"] for c in chans]
            (folder / f"{base}_channels.tsv").write_text(
                tsv(ch_rows, ["name", "component", "type", "tracked_point", "units", "sampling_frequency"])
            )
            counts: dict[str, int] = {}
            for c in chans:
                counts[c[2]] = counts.get(c[2], 0) + 1
            t_s = sysd["t_s"]
            dev = sysd["meta"]
            sidecar: dict[str, Any] = {
                "TaskName": sysd["task"],
                "TrackingSystemName": sysd["name"],
                "SamplingFrequency": sysd["rate"] or "n/a",
                "SamplingFrequencyEffective": _effective_rate(t_s),
                "RecordingDuration": float(t_s[-1] - t_s[0]) if len(t_s) > 1 else 0.0,
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
            rows += len(t_s)
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
        notes=list(tc.notes),
    )
