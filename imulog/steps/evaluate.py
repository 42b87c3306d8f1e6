"""Reprocessing step ``evaluate``: every ``/derived/trajectory/{method}`` against the optical reference.

Reference: the Vicon cluster origin, ``/derived/vicon/cluster_pose`` (align step) when present, else the
origin marker ``O`` of the trial's ``/markers/*`` channel (the cluster origin in the conventions). The
reference is interpolated linearly onto each trajectory's time stamps (both on the reference clock; samples
further than ``max_gap_s`` from a valid reference sample are dropped). Errors per repetition window from the
``imulog.trajectory`` record (else over the whole channel), each trajectory and reference taken relative to
the window's first sample (:mod:`imulog.process.evaluation`). Writes metadata ``imulog.evaluation``:
reference topic, per method the per-repetition errors and the summary (mean, std over repetitions) per axis.
"""

from __future__ import annotations

import json
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.process.evaluation import (
    AXES,
    METRICS,
    aggregate,
    format_robust,
    format_table,
    summarize,
    trajectory_errors,
)
from imulog.process.trajectory_opt import BASELINE, METHODS
from imulog.steps.common import names_trial

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "evaluate"
WHOLE_NS = 2**62  # a window over a whole channel (from -WHOLE_NS to WHOLE_NS ns)
POSE_TOPIC = "/derived/vicon/cluster_pose"


def interpolate_reference(
    t_ref_ns: np.ndarray, pos_m: np.ndarray, t_ns: np.ndarray, max_gap_s: float = 0.05
) -> np.ndarray:
    """Reference positions (N, 3) m at ``t_ns``: linear between valid samples, NaN across gaps > ``max_gap_s``."""
    t_ref = np.asarray(t_ref_ns, dtype=np.int64)
    pos = np.asarray(pos_m, dtype=np.float64)
    ok = np.all(np.isfinite(pos), axis=1)
    t_ok, p_ok = t_ref[ok], pos[ok]
    out = np.full((len(t_ns), 3), np.nan)
    if len(t_ok) < 2:
        return out
    tq = np.asarray(t_ns, dtype=np.int64)
    base = float(t_ok[0])
    for j in range(3):
        out[:, j] = np.interp(tq - base, t_ok - base, p_ok[:, j], left=np.nan, right=np.nan)
    idx = np.clip(np.searchsorted(t_ok, tq), 1, len(t_ok) - 1)
    span = (t_ok[idx] - t_ok[idx - 1]) / 1e9
    out[span > max_gap_s] = np.nan
    return out


def compute_evaluation(
    trajectories: dict[str, tuple[np.ndarray, np.ndarray]],
    reference: tuple[np.ndarray, np.ndarray],
    *,
    reference_topic: str,
    windows: list[dict[str, Any]] | None = None,
    max_gap_s: float = 0.05,
    baseline: str | None = None,
) -> dict[str, Any]:
    """The ``imulog.evaluation`` record from {method: (t_ns, (N, 3) m)} and the reference (t_ns, (M, 3) m).

    Per method also ``exceeds_motion`` (windows whose 3D RMS error exceeds the reference's reach) and, with
    ``baseline`` (a key of ``trajectories``: the de-drift baseline), ``beats_baseline`` per axis (mean MAE)."""
    per_method: dict[str, list[dict[str, Any]]] = {}
    for method, (t_ns, pos) in trajectories.items():
        t_ns = np.asarray(t_ns, dtype=np.int64)
        ref = interpolate_reference(reference[0], reference[1], t_ns, max_gap_s)
        spans = windows or [{"index": -1, "start_ns": int(t_ns[0]), "end_ns": int(t_ns[-1])}]
        per_method[method] = error_rows(t_ns, pos, ref, spans)
    return evaluation_record(per_method, reference_topic, baseline)


def error_rows(t_ns: np.ndarray, pos: np.ndarray, ref: np.ndarray, spans: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Errors of ``pos`` (N, 3) m against ``ref`` (N, 3) m (both at ``t_ns``) in each span (``start_ns``,
    ``end_ns`` inclusive, ``index``); spans with fewer than 2 samples or no valid reference are left out."""
    rows = []
    for w in spans:
        sel = (t_ns >= w["start_ns"]) & (t_ns <= w["end_ns"])
        if np.count_nonzero(sel) < 2:
            continue
        try:
            r = trajectory_errors(pos[sel], ref[sel])
        except ValueError:
            continue
        r["repetition"] = int(w.get("index", -1))
        rows.append(r)
    return rows


def evaluation_record(
    per_method: dict[str, list[dict[str, Any]]], reference_topic: str, baseline: str | None = None
) -> dict[str, Any]:
    """The ``imulog.evaluation`` record from each method's per-repetition error rows."""
    methods = {m: {"summary": summarize(rows), "repetitions": rows} for m, rows in per_method.items()}
    for rec in methods.values():  # windows where the error is larger than the motion itself (issue 32)
        rec["exceeds_motion"] = [int(r["repetition"]) for r in rec["repetitions"] if r.get("exceeds_motion")]
    if baseline and baseline in methods:
        base = methods[baseline]["summary"]
        for m, rec in methods.items():
            if m != baseline:
                rec["beats_baseline"] = {
                    a: bool(rec["summary"][a]["mae_cm"]["mean"] < base[a]["mae_cm"]["mean"]) for a in AXES
                }
    return {
        "reference": reference_topic,
        "metrics": list(METRICS),
        "units": {
            "mae_cm": "cm",
            "rom_pct": "%",
            "rmse_cm": "cm",
            "final_cm": "cm",
            "spearman": "1",
            "median_cm": "cm",
            "p90_cm": "cm",
            "rom_cm": "cm",
        },
        **({"baseline": baseline} if baseline and baseline in methods else {}),
        "methods": methods,
    }


def _order(methods: dict[str, Any]) -> list[str]:
    return sorted(methods, key=lambda m: (METHODS.index(m) if m in METHODS else len(METHODS), m))


def table_from_record(record: dict[str, Any]) -> str:
    """Table 3.1-shaped text (method x axis, mean±std) from an ``imulog.evaluation`` record."""
    methods = record.get("methods", {})
    return format_table(aggregate({m: methods[m]["repetitions"] for m in _order(methods)}))


def robust_from_record(record: dict[str, Any]) -> str:
    """The robust table (median, 90th percentile, ROM per window, windows with error > motion, beats the
    baseline) from an ``imulog.evaluation`` record; empty for records of an older imulog."""
    methods = record.get("methods", {})
    rows = {m: methods[m]["repetitions"] for m in _order(methods)}
    if not rows or not all("median_cm" in r.get("x", {}) for v in rows.values() for r in v):
        return ""
    exceeding = {m: (len(methods[m].get("exceeds_motion") or []), len(rows[m])) for m in rows}
    return format_robust(aggregate(rows), exceeding, record.get("baseline"))


def warning_lines(record: dict[str, Any]) -> list[str]:
    """One line per method whose assumptions failed (from its channel) or whose error exceeds the motion in
    some windows, and per method that does not beat the baseline on any axis."""
    lines = []
    base = record.get("baseline")
    for m in _order(record.get("methods", {})):
        rec = record["methods"][m]
        why = rec.get("assumptions_why")
        if why:
            lines.append(f"{m}: assumptions fail: {why}")
        bad = rec.get("exceeds_motion") or []
        if bad:
            n = len(rec.get("repetitions") or [])
            lines.append(f"{m}: the error exceeds the motion itself in {len(bad)} of {n} windows ({_list(bad)})")
        beats = rec.get("beats_baseline")
        if beats is not None and not any(beats.values()):
            lines.append(f"{m}: no better than the {base} baseline on any axis")
    return lines


def _list(values: list[int], most: int = 8) -> str:
    text = ", ".join(map(str, values[:most]))
    return text + (f", ... ({len(values) - most} more)" if len(values) > most else "")


def reference_source(trial, topics: list[str], imu: str | None = None) -> str:
    """The optical reference to compare with, from channel metadata only (no data read).

    ``/derived/vicon/cluster_pose`` when the align step ran on a cluster (``.../cluster_pose/{imu}`` for ``imu``
    of a setup aligned as a whole), ``{markers topic}:{marker}`` when it aligned on one marker
    (``reference_marker``), else ``{markers topic}:O`` (the cluster origin).
    """
    from imulog.steps.common import alignment_for, alignment_record

    own = None if imu is None else alignment_record(trial.metadata, f"/imu/{imu}")
    record = (alignment_for(trial.metadata, f"/imu/{imu}") if imu else trial.metadata.get("imulog.alignment")) or {}
    marker = record.get("reference_marker")
    if marker and str(record.get("reference", "")).startswith("/markers/") and record["reference"] in topics:
        return f"{record['reference']}:{marker}"
    if imu is not None and f"{POSE_TOPIC}/{imu}" in topics:
        return f"{POSE_TOPIC}/{imu}"
    if POSE_TOPIC in topics and own in (None, "imulog.alignment"):
        return POSE_TOPIC
    markers = [t for t in topics if t.startswith("/markers/")]
    for topic in markers:
        labels = [label.split(":")[-1] for label in json.loads(trial.channel(topic).metadata.get("labels", "[]"))]
        if "O" in labels:
            return f"{topic}:O"
    if not markers:
        poses = [t for t in topics if t.startswith("/poses/")]
        unused = (
            f" ({', '.join(poses)}: trajectories are evaluated against markers, an orientation against poses)"
            if poses
            else ""
        )
        raise ValueError(
            "no optical reference: evaluate needs Vicon markers (a /markers/* channel) or a rigid body's poses "
            f"(/poses/*), aligned with `imulog process align`, and this trial has neither{unused}"
        )
    raise ValueError(
        "no optical reference: neither /derived/vicon/cluster_pose (run `imulog process align`) nor a marker 'O' "
        f"in {', '.join(markers)}"
    )


def read_reference(trial, source: str) -> tuple[np.ndarray, np.ndarray]:
    """(t_ns, position (N, 3) m) of a :func:`reference_source`."""
    if source == POSE_TOPIC or source.startswith(f"{POSE_TOPIC}/"):
        pose = trial.read(source)
        return pose.t_ns, pose.position
    topic, _, marker = source.partition(":")
    stream = trial.read(topic)
    if marker in stream.labels:
        return stream.t_ns, stream.pos[:, stream.labels.index(marker)]
    labels = [label.split(":")[-1] for label in stream.labels]
    return stream.t_ns, stream.pos[:, labels.index(marker.split(":")[-1])]


def check_clock(path, metadata: dict[str, Any], info: dict[str, Any] | None = None) -> dict[str, Any]:
    """The alignment the trajectories were put on the reference clock with; a one-line ValueError naming
    the command to run when there is none, or when the trajectories are still on the IMU device clock.
    ``info``: the IMU's trajectory record (default ``imulog.trajectory``)."""
    from imulog.steps.align import require_alignment

    info = metadata.get("imulog.trajectory") or {} if info is None else info
    imu = info.get("imu")
    record = require_alignment(metadata, path, imu, needed_for="evaluate (IMU trajectories against Vicon)")
    if info.get("clock") == "device":
        raise ValueError(
            "the trajectories are on the IMU device clock (computed before the alignment): "
            f"run `imulog process trajectory {path}` again"
        )
    return record


WALK_SPAN_S = 3600.0  # a longer recording is judged on one hour: the reference's middle (bounded memory; issue 24)


def walking_of(path, span_s: float = WALK_SPAN_S) -> dict[str, Any] | None:
    """Why the trial at ``path`` is a walking trial (evaluated per stride), else None
    (:func:`imulog.steps.gait_evaluate.walking_trial`). Each IMU's gyroscope is read whole when it spans at most
    ``span_s`` seconds, else only ``span_s`` around the middle of the optical reference (:func:`judged_span`; it
    holds the middle two minutes :func:`imulog.process.gait.walking_period` looks at), so a week is not read whole
    to decide this, and a week at home with an hour in the lab is judged on the lab hour it is evaluated on."""
    from imulog.archive import TrialReader
    from imulog.steps.common import mean_rate_hz
    from imulog.steps.gait_evaluate import WALK_TASKS, walking_trial

    with TrialReader(path) as trial:
        metadata = trial.metadata
        if str((metadata.get("imulog.trial") or {}).get("task", "")).lower() in WALK_TASKS:
            return walking_trial(metadata, {})
        gyros = {}
        for topic in trial.topics():
            if topic.startswith("/imu/"):
                info = trial.channel(topic)
                a, b = info.start_ns, info.end_ns
                if a is None or b is None or (b - a) * 1e-9 <= span_s:
                    s = trial.read(topic)
                else:
                    s = trial.read(topic, *judged_span(trial, topic, span_s))
                if s.gyr is not None and len(s.t_ns) > 10:
                    gyros[topic[5:]] = (s.gyr, mean_rate_hz(s.t_ns))
    return walking_trial(metadata, gyros)


def judged_span(trial, imu_topic: str, span_s: float) -> tuple[int, int]:
    """(start_ns, end_ns) on ``imu_topic``'s clock: ``span_s`` around the middle of the optical reference (the
    ``/markers/*`` and ``/derived/vicon/cluster_pose*`` channels, through the IMU's alignment when it has one),
    or around the IMU's middle when the trial has no reference."""
    from imulog.process.alignment_clock import reference_to_device
    from imulog.steps.common import alignment_for

    refs = [trial.channel(t) for t in trial.topics() if t.startswith(("/markers/", POSE_TOPIC))]
    refs = [c for c in refs if c.start_ns is not None and c.end_ns is not None]
    if refs:
        ends = np.array([min(c.start_ns for c in refs), max(c.end_ns for c in refs)], np.int64)
        alignment = alignment_for(trial.metadata, imu_topic)
        lo, hi = (int(v) for v in (reference_to_device(ends, alignment) if alignment else ends))
    else:
        info = trial.channel(imu_topic)
        lo, hi = int(info.start_ns), int(info.end_ns)
    mid = (lo + hi) // 2
    return mid - int(span_s * 5e8), mid + int(span_s * 5e8)


WHAT = ("auto", "orientation", "trajectory")  # what `imulog evaluate --what` chooses (docs/alignment.md)


@names_trial
def run_evaluate(
    path: str | os.PathLike[str],
    *,
    methods: list[str] | None = None,
    max_gap_s: float = 0.05,
    strides: bool | None = None,
    imus: list[str] | None = None,
    what: str = "auto",
    force: bool = False,
) -> tuple[StepOutcome, dict[str, Any]]:
    """Run the step on a trial file; returns ``(outcome, record)``. ``what``: ``orientation`` evaluates the IMU's
    orientation against the rigid body's poses its alignment was made on (:mod:`imulog.steps.evaluate_orientation`,
    ``kind`` = ``orientation``, record ``imulog.orientation_evaluation``), ``trajectory`` the trajectories (or the
    strides) against the optical reference (record ``imulog.evaluation``); ``auto`` chooses the orientation for a
    trial without trajectories whose alignment is on poses (or whose only optical reference is poses), else the
    trajectories. The two records are separate: neither evaluation replaces the other. ``strides``: None evaluates a walking trial
    (:func:`walking_of`) per stride and foot (:func:`imulog.steps.gait_evaluate.run_gait_evaluate`, on ``imus``)
    and any other over the trajectory step's windows; True or False forces either.

    Over windows, a trial with one set of trajectories gives ``imulog.evaluation``; a trial with trajectories
    per IMU (:mod:`imulog.steps.trajectory_topics`) is evaluated per IMU (``imus``: which; default every one
    with trajectories), one ``evaluate:IMU`` run and record each (``imulog.evaluation`` for the primary IMU,
    ``imulog.evaluation.IMU`` for the others), each against its own cluster, and returns the last outcome with
    ``{"kind": "imus", "imus": {imu: record, or {"failed": why}}}``; a ValueError only when none could be."""
    from imulog.archive import TrialReader

    if what not in WHAT:
        raise ValueError(f"what={what!r}: choose one of {', '.join(WHAT)}")
    if what == "orientation" and strides:
        raise ValueError("--strides evaluates trajectories per stride: it does not go with --what orientation")
    if what != "trajectory" and not strides:  # an orientation against a rigid body's poses (BROAD, OptiTrack)
        from imulog.steps.evaluate_orientation import pose_reference, run_evaluate_orientations

        with TrialReader(path) as trial:
            topics, metadata = trial.topics(), trial.metadata
        only_poses = any(t.startswith("/poses/") for t in topics) and not any(t.startswith("/markers/") for t in topics)
        if what == "orientation" or (
            not any(t.startswith("/derived/trajectory/") for t in topics)
            and (pose_reference(metadata, imus[0] if imus else None) or only_poses)
        ):
            return run_evaluate_orientations(path, imus=imus, force=force)
    walking = walking_of(path) if strides is None else ({"source": "asked"} if strides else None)
    if walking is not None:
        from imulog.steps.gait_evaluate import run_gait_evaluate

        return run_gait_evaluate(path, imus=imus, walking=walking, force=force)

    from imulog.steps.trajectory_topics import baselines_by_imu, per_imu_layout, trajectories_by_imu

    with TrialReader(path) as trial:
        topics = trial.topics()
        metadata = trial.metadata
    by_imu = trajectories_by_imu(topics, metadata)
    if imus:
        missing = [n for n in imus if n not in by_imu]
        if missing:
            have = ", ".join(n for n in by_imu if n) or "none"
            raise ValueError(f"no trajectory of {', '.join(missing)} (IMUs with trajectories: {have})")
        by_imu = {n: by_imu[n] for n in imus}
    if not by_imu:  # what is missing first: the optical reference, the alignment, then the trajectories
        with TrialReader(path) as trial:
            reference_source(trial, topics)
        check_clock(path, metadata)
        raise ValueError("no /derived/trajectory/* channel: run `imulog process trajectory` first")
    baselines = baselines_by_imu(topics, metadata)
    if len(by_imu) == 1 and not per_imu_layout(topics):  # one IMU: the trial's evaluation, as always
        imu, channels = next(iter(by_imu.items()))
        return _evaluate_imu(
            path, imu, channels, baselines.get(imu, {}), "imulog.evaluation", STEP, methods, max_gap_s, force
        )
    from imulog.steps.common import record_for

    outcomes, records = [], {}
    for imu, channels in by_imu.items():
        with TrialReader(path) as trial:
            name = record_for("imulog.evaluation", imu, trial.topics(), trial.metadata)
        try:
            outcome, record = _evaluate_imu(
                path, imu, channels, baselines.get(imu, {}), name, f"{STEP}:{imu}", methods, max_gap_s, force
            )
        except ValueError as exc:  # this IMU cannot be evaluated (no cluster, not aligned): the others still are
            records[imu] = {"failed": str(exc)}
            continue
        outcomes.append(outcome)
        records[imu] = record
    if not outcomes:
        raise ValueError("; ".join(f"{imu}: {r['failed']}" for imu, r in records.items()))
    import dataclasses

    last = dataclasses.replace(outcomes[-1], skipped=all(o.skipped for o in outcomes))  # computed if any IMU was
    return last, {"kind": "imus", "imus": records}


def _evaluate_imu(path, imu, channels, baselines, record_name, step, methods, max_gap_s, force):
    """Evaluate one IMU's trajectories (``channels``: method -> topic) into ``record_name``."""
    from imulog.archive import TrialReader
    from imulog.steps.base import run_record_step
    from imulog.steps.common import alignment_note, alignment_record
    from imulog.steps.trajectory_topics import record_name_of, record_of_imu

    with TrialReader(path) as trial:
        topics = trial.topics()
        metadata = trial.metadata
        info = record_of_imu(imu, metadata)
        ref_topic = reference_source(trial, topics, imu or None)
    alignment = check_clock(path, metadata, info)
    available = sorted(channels)
    chosen = available if not methods else [m for m in methods if m in available]
    missing = sorted(set(methods or []) - set(available))
    if missing:
        raise ValueError(f"no trajectory for method(s) {', '.join(missing)} (available: {', '.join(available)})")
    baseline_topic = baselines.get(BASELINE, "")
    inputs = [channels[m] for m in chosen] + [ref_topic.split(":")[0]]
    inputs += [baseline_topic] if baseline_topic in topics else []

    def compute(trial) -> dict[str, Any]:
        from imulog.steps.evaluate_windows import windowed_rows

        ref_name = ref_topic
        checks = {m: trial.channel(channels[m]).metadata for m in chosen}
        read = {m: channels[m] for m in chosen}
        if baseline_topic in topics:  # the de-drift baseline every method must beat
            read[BASELINE] = baseline_topic
        # repetition by repetition, half an hour of recording read at a time, and only where the reference is
        # valid (bounded memory); without repetitions (a record of an older imulog), one window over each channel
        reps = info.get("repetitions") or [{"index": -1, "start_ns": -WHOLE_NS, "end_ns": WHOLE_NS}]
        rows = windowed_rows(trial, read, ref_topic, reps, max_gap_s, error_rows, interpolate_reference)
        record = evaluation_record(rows, ref_name, BASELINE)
        for m, meta in checks.items():  # the trajectory step's verdict on each method's assumptions
            if meta.get("assumptions"):
                record["methods"][m]["assumptions"] = meta["assumptions"]
            if meta.get("assumptions") == "failed":
                record["methods"][m]["assumptions_why"] = meta.get("assumptions_why", "")
        record["alignment"] = alignment_note(alignment)
        if imu:
            record["imu"] = f"/imu/{imu}"
        return record

    trajectory_record = record_name_of(imu, metadata) or "imulog.trajectory"
    return run_record_step(
        path,
        record_name=record_name,
        compute_record=compute,
        step=step,
        algorithm="imulog.evaluation",
        params={"methods": chosen, "max_gap_s": max_gap_s},
        inputs=inputs,
        metadata_inputs=(alignment_record(metadata, f"/imu/{imu}") if imu else "imulog.alignment",)
        + ((trajectory_record,) if step != STEP else ()),
        force=force,
    )
