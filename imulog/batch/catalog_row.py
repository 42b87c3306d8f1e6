"""One catalog row of a trial (from its summary and metadata records only) and the catalog's flat Parquet schema."""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path
from typing import Any

STRING_COLUMNS = (
    "path",
    "raw_sha256",
    "subject",
    "trial",
    "task",
    "side",
    "date",
    "protocol",
    "imulog_version",
    "alignment_method",
    "phases_method",
    "phases_clock",
    "flagged_reasons",
    "error",
)


INT_COLUMNS = (
    "file_size",
    "mtime_ns",
    "n_channels",
    "n_derived_channels",
    "n_runs",
    "n_attachments",
    "alignment_offset_ns",
    "n_imus",
    "n_imus_aligned",
    "n_imus_aligned_good",
    "n_repetitions",
    "n_phases",
    "n_forced_phases",
    "n_low_confidence_repetitions",
    "n_flagged_repetitions",
    "valid_days",
)


FLOAT_COLUMNS = (
    "duration_s",
    "imu_duration_s",
    "imu_rate_hz",
    "markers_duration_s",
    "markers_rate_hz",
    "alignment_drift_ppm",
    "alignment_score",
    "repetition_mean_s",
    "phases_confidence",
    "best_mae_cm",
    "eval_inclination_rmse_deg",
    "eval_heading_free_rmse_deg",
    "wear_h",
    "enmo_mean_mg",
)


BOOL_COLUMNS = ("simulated",)


LIST_COLUMNS = ("devices", "imus", "markers", "channels", "derived_channels", "steps", "eval_methods")


JSON_COLUMNS = (
    "device_json",
    "channels_json",
    "runs_json",
    "alignment_json",
    "alignment_imus_json",
    "timing_json",
    "evaluation_json",
    "orientation_evaluation_json",
    "metrics_json",
    "epochs_json",
    "anthropometrics_json",
    "trial_json",
)


KEY_COLUMNS = ("path", "file_size", "mtime_ns")


def schema():
    """The catalog's fixed pyarrow schema (every row has every column; absent values are null)."""
    import pyarrow as pa

    fields = [pa.field(c, pa.string()) for c in STRING_COLUMNS]
    fields += [pa.field(c, pa.int64()) for c in INT_COLUMNS]
    fields += [pa.field(c, pa.float64()) for c in FLOAT_COLUMNS]
    fields += [pa.field(c, pa.bool_()) for c in BOOL_COLUMNS]
    fields += [pa.field(c, pa.list_(pa.string())) for c in LIST_COLUMNS]
    fields += [pa.field(c, pa.string()) for c in JSON_COLUMNS]
    fields.append(pa.field("cataloged_at", pa.string()))
    return pa.schema(fields)


def _json(value: Any) -> str | None:
    if value is None:
        return None
    return json.dumps(value, sort_keys=True, default=str, allow_nan=True)


def _record(record: Any) -> dict[str, Any]:
    """A metadata record as a dict (``{}`` when absent); values are already typed by the archive reader."""
    return dict(record) if isinstance(record, dict) else {}


def _num(value: Any, kind=float):
    try:
        return kind(value) if value is not None and value != "" else None
    except (TypeError, ValueError):
        return None


def _best_mae(evaluation: dict[str, Any]) -> float | None:
    """Lowest mean (over axes) of the per-method mean MAE, cm."""
    best = None
    for summ in (evaluation.get("methods") or {}).values():
        s = summ.get("summary", {}) if isinstance(summ, dict) else {}
        vals = [s.get(a, {}).get("mae_cm", {}).get("mean") for a in ("x", "y", "z")]
        vals = [v for v in vals if isinstance(v, int | float) and v == v]
        if len(vals) == 3:
            m = sum(vals) / 3
            best = m if best is None else min(best, m)
    return best


def trial_row(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The catalog row of one trial (summary and metadata only; raises ArchiveError on unreadable files)."""
    from imulog import __version__
    from imulog.archive import TrialReader

    p = Path(path)
    st = p.stat()
    row: dict[str, Any] = {"path": str(p.resolve()), "file_size": st.st_size, "mtime_ns": st.st_mtime_ns}
    with TrialReader(p) as trial:
        channels = trial.channels
        meta = trial.metadata
        runs = trial.runs()
        n_att = len(trial.summary.attachment_indexes)
    info = _record(meta.get("imulog.trial"))
    raw = _record(meta.get("imulog.raw"))
    row.update(
        raw_sha256=raw.get("sha256"),
        subject=None if info.get("subject") is None else str(info.get("subject")),
        trial=None if info.get("trial") is None else str(info.get("trial")),
        task=None if info.get("task") is None else str(info.get("task")),
        side=info.get("side") if isinstance(info.get("side"), str) else None,
        date=None if info.get("date") is None else str(info.get("date")),
        protocol=str(info.get("protocol") or info.get("task") or "") or None,
        simulated=bool(info["simulated"]) if "simulated" in info else None,
        imulog_version=__version__,
        trial_json=_json(info),
        anthropometrics_json=_json(_record(meta.get("imulog.anthropometrics")) or None),
        n_attachments=n_att,
    )
    devices = {k.split(".", 2)[2]: _record(v) for k, v in meta.items() if k.startswith("imulog.device.")}
    row["devices"] = sorted(devices)
    row["device_json"] = _json(devices)
    raw_ch = [c for c in channels if not c.derived]
    derived = [c for c in channels if c.derived]
    row["channels"] = [c.topic for c in raw_ch]
    row["derived_channels"] = [c.topic for c in derived]
    row["imus"] = [c.topic.split("/", 2)[2] for c in raw_ch if c.topic.startswith("/imu/")]
    row["n_imus"] = len(row["imus"])
    row["markers"] = [c.topic.split("/", 2)[2] for c in raw_ch if c.topic.startswith("/markers/")]
    row["n_channels"] = len(channels)
    row["n_derived_channels"] = len(derived)
    row["channels_json"] = _json(
        [
            {
                "topic": c.topic,
                "schema": c.schema_name,
                "samples": c.sample_count,
                "rate_hz": c.rate_hz,
                "duration_s": c.duration_s,
                "derived": c.derived,
                "run": c.metadata.get("run"),
            }
            for c in channels
        ]
    )
    durations = [c.duration_s for c in raw_ch if c.duration_s is not None]
    row["duration_s"] = max(durations) if durations else None
    imu = next((c for c in raw_ch if c.topic.startswith("/imu/")), None)
    mk = next((c for c in raw_ch if c.topic.startswith("/markers/")), None)
    row["imu_duration_s"] = imu.duration_s if imu else None
    row["imu_rate_hz"] = imu.rate_hz if imu else None
    row["markers_duration_s"] = mk.duration_s if mk else None
    row["markers_rate_hz"] = mk.rate_hz if mk else None
    run_rows = []
    for n, rec in runs.items():
        rec = _record(rec)
        run_rows.append(
            {
                "run": n,
                "step": rec.get("step"),
                "algorithm": rec.get("algorithm"),
                "params": rec.get("params"),
                "inputs": rec.get("inputs"),
                "outputs": sorted(rec.get("outputs") or {}),
                "time": rec.get("time"),
                "imulog_version": rec.get("imulog_version"),
            }
        )
    row["n_runs"] = len(run_rows)
    latest: dict[str, dict] = {}
    for r in run_rows:
        latest[str(r["step"])] = r
    row["steps"] = sorted(latest)
    row["runs_json"] = _json(run_rows)
    al = _record(meta.get("imulog.alignment"))
    if al:
        row["alignment_offset_ns"] = _num(al.get("offset_ns"), int)
        row["alignment_drift_ppm"] = _num(al.get("drift_ppm"))
        row["alignment_score"] = _num(al.get("score"))
        row["alignment_method"] = None if al.get("method") is None else str(al.get("method"))
        row["alignment_json"] = _json(al)
    row.update(_imu_alignment_columns(meta, row["imus"]))
    timing = _record(meta.get("imulog.timing"))
    if timing:
        row["n_repetitions"] = _num(timing.get("n_repetitions"), int)
        row["n_phases"] = _num(timing.get("n_phases"), int)
        row["phases_method"] = timing.get("method")
        row["phases_clock"] = timing.get("clock")
        if "repetition_quality" in timing:  # what event correction did (issue 19)
            row["n_forced_phases"] = _num(timing.get("n_forced_phases"), int)
            row["n_low_confidence_repetitions"] = len(timing.get("low_confidence_repetitions") or [])
            row["phases_confidence"] = _num(timing.get("mean_confidence"))
        spans = {}
        for ph in timing.get("phases") or []:
            with contextlib.suppress(KeyError, TypeError, ValueError):
                k = int(ph["repetition"])
                s, e = float(ph["start_s"]), float(ph["end_s"])
                lo, hi = spans.get(k, (s, e))
                spans[k] = (min(lo, s), max(hi, e))
        if spans:
            row["repetition_mean_s"] = sum(e - s for s, e in spans.values()) / len(spans)
        row["timing_json"] = _json(timing)
    row.update(_flag_columns(timing, _record(meta.get("imulog.trajectory"))))
    from imulog.steps.evaluate_orientation import RECORD, orientation_record_of

    ev = _record(meta.get("imulog.evaluation"))
    others = {k.split(".", 2)[2]: _record(v) for k, v in meta.items() if k.startswith("imulog.evaluation.")}
    orient = _record(orientation_record_of(meta))
    if orient:  # an orientation against a rigid body's poses (BROAD): its two RMSEs, deg
        row["eval_inclination_rmse_deg"] = orient.get("inclination_rmse_deg")
        row["eval_heading_free_rmse_deg"] = orient.get("heading_free_rmse_deg")
        more = {k.split(".", 2)[2]: _record(v) for k, v in meta.items() if k.startswith(RECORD + ".")}
        row["orientation_evaluation_json"] = _json({**orient, "per_imu": more} if more else orient)
    if ev and ev.get("kind") != "orientation":  # the trajectories' (an older imulog kept orientations here too)
        row["eval_methods"] = sorted((ev.get("methods") or {}).keys())
        row["best_mae_cm"] = _best_mae(ev)
    if ev or others:  # a setup evaluated per IMU: the primary IMU's record, the others under per_imu
        row["evaluation_json"] = _json({**ev, "per_imu": others} if others else ev)
    mt = _record(meta.get("imulog.metrics"))
    if mt:
        row["metrics_json"] = _json(mt)
    row.update(_epoch_columns(_record(meta.get("imulog.epochs"))))
    return row


#: what ``alignment_imus_json`` keeps of each IMU's alignment record: the clock (``t_ref = t_dev + offset_ns +
#: drift_ppm 1e-6 (t_dev - t0_ns)``, ns), its standard errors and its grade
IMU_ALIGNMENT_KEYS = (
    "reference",
    "offset_ns",
    "t0_ns",
    "offset_uncertainty_ns",
    "drift_ppm",
    "drift_uncertainty_ppm",
    "drift_estimated",
    "score",
    "quality",
    "clock",
    "clock_of",
)


def _imu_alignment_columns(meta: dict[str, Any], imus: list[str]) -> dict[str, Any]:
    """``n_imus_aligned``, ``n_imus_aligned_good`` and ``alignment_imus_json`` of the trial's IMUs (``imus``, the raw
    ``/imu/*`` channels): one rule for one IMU and several, from the records every alignment path writes
    (``imulog.alignment`` and ``imulog.alignment.{imu}``, :func:`imulog.archive.alignment_records.alignments_from_metadata`).
    Aligned: a record with a clock (``offset_ns``); an IMU a setup could not align is listed with ``quality``
    ``failed`` and why. Nothing when the trial has no alignment record."""
    from imulog.archive.alignment_records import alignments_from_metadata

    records = {n: r for n, r in alignments_from_metadata(meta, failed=True).items() if n in imus}
    if not records:
        return {}
    per_imu: dict[str, dict[str, Any]] = {}
    for name in imus:
        rec = records.get(name)
        if rec is None:
            continue
        entry = {k: rec[k] for k in IMU_ALIGNMENT_KEYS if k in rec}
        if "offset_ns" not in rec:
            entry.setdefault("quality", "failed")
            entry["why"] = "; ".join(str(r) for r in rec.get("quality_reasons") or [])
        per_imu[name] = entry
    aligned = [e for e in per_imu.values() if "offset_ns" in e]
    return {
        "n_imus_aligned": len(aligned),
        "n_imus_aligned_good": sum(e.get("quality") == "good" for e in aligned),
        "alignment_imus_json": _json(per_imu),
    }


def _flag_columns(timing: dict[str, Any], trajectory: dict[str, Any]) -> dict[str, Any]:
    """``n_flagged_repetitions`` and ``flagged_reasons`` ("drift: 3, merged: 1") of the repetition flags (issue
    31): the trajectory step's when it ran (it adds drift to event correction's reasons), else the phases step's."""
    from imulog.process.repetition_flags import trial_flags

    found = trial_flags(timing, trajectory)
    if found is None:
        return {}
    flagged = found[0]
    counts: dict[str, int] = {}
    for f in flagged:
        for reason in f.get("reasons") or []:
            counts[reason] = counts.get(reason, 0) + 1
    return {
        "n_flagged_repetitions": len(flagged),
        "flagged_reasons": ", ".join(f"{k}: {v}" for k, v in sorted(counts.items())),
    }


def _epoch_columns(ep: dict[str, Any]) -> dict[str, Any]:
    """Catalog columns of an ``imulog.epochs`` record: valid days, hours worn, wear-weighted mean ENMO (mg)."""
    if not ep:
        return {}
    days = [d for d in ep.get("by_day") or [] if isinstance(d, dict)]
    wear = sum(float(d.get("wear_h") or 0) for d in days)
    enmo = [(float(d["enmo_mean_mg"]), float(d.get("wear_h") or 0)) for d in days if d.get("enmo_mean_mg") is not None]
    return {
        "valid_days": _num(ep.get("valid_days"), int),
        "wear_h": wear,
        "enmo_mean_mg": sum(v * w for v, w in enmo) / wear if enmo and wear > 0 else None,
        "epochs_json": _json(ep),
    }
