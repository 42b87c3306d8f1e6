"""The catalog: one Parquet row per trial, readable by pandas, pyarrow and DuckDB, updated incrementally.

    from imulog.batch.catalog import build_catalog
    stats = build_catalog("archive/", "catalog.parquet")     # re-reads only new or changed files

A row is built from a trial's summary and metadata records only (no channel data is read): identity (path,
size, mtime, raw-data hash), ``imulog.trial`` (subject, trial, task, side, date), devices, per-channel
durations and rates, every derived run with its parameters, the alignment, the phase timing table, the
evaluation (per method: summary and per-repetition errors) and the clinical metrics. Nested content is stored
as JSON text columns (``runs_json``, ``evaluation_json``, ``timing_json``, ``metrics_json``, ...) so that every
reader sees the same flat schema; DuckDB reads them with ``json_extract``.

Incremental: a file whose path, size and mtime match its existing row keeps that row without being opened;
rows of files that disappeared are dropped. Rows are written in batches with ``pyarrow.parquet.ParquetWriter``
(to a temporary file, then ``os.replace``), so memory holds one batch of rows, never the archive.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

BATCH_ROWS = 256

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
    "timing_json",
    "evaluation_json",
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
    ev = _record(meta.get("imulog.evaluation"))
    others = {k.split(".", 2)[2]: _record(v) for k, v in meta.items() if k.startswith("imulog.evaluation.")}
    if ev:
        row["eval_methods"] = sorted((ev.get("methods") or {}).keys())
        row["best_mae_cm"] = _best_mae(ev)
    if ev or others:  # a setup evaluated per IMU: the primary IMU's record, the others under per_imu
        row["evaluation_json"] = _json({**ev, "per_imu": others} if others else ev)
    mt = _record(meta.get("imulog.metrics"))
    if mt:
        row["metrics_json"] = _json(mt)
    row.update(_epoch_columns(_record(meta.get("imulog.epochs"))))
    return row


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


def build_epoch_table(
    root: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    output: str | os.PathLike[str],
    *,
    epoch_s: float = 60.0,
) -> CatalogStats:
    """One study table of every trial's ``/derived/epochs/{epoch_s}s/{imu}`` rows (``imulog process epochs``).

    Columns: ``path``, ``subject``, ``trial``, ``imu``, then the export's time columns (``time`` as UTC
    instants, ``t[s]``, ``t_ns``; docs/export.md) and the epoch columns. Trials without the channel are skipped
    (counted in ``dropped``). Written trial by trial to a temporary file, then renamed (Parquet or CSV by suffix).
    """
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    from imulog.archive import TrialReader
    from imulog.archive.tables import stream_table
    from imulog.archive.trial_clock import trial_clock
    from imulog.export.table import format_of

    t0 = time.perf_counter()
    output = Path(output)
    fmt = format_of(output)
    stats = CatalogStats(output)
    tmp = output.with_name(f".{output.name}.{os.getpid()}.tmp")
    output.parent.mkdir(parents=True, exist_ok=True)
    writer = None
    prefix = f"/derived/epochs/{epoch_s:g}s/"
    try:
        for p in discover(root):
            if p.resolve() == output.resolve():
                continue
            with TrialReader(p) as trial:
                topics = [c.topic for c in trial.channels if c.topic.startswith(prefix)]
                if not topics:
                    stats.dropped += 1
                    continue
                info = _record(trial.metadata.get("imulog.trial"))
                tc = trial_clock(trial, "device", None)
                for topic in topics:
                    table = stream_table(trial.read(topic), trial.channel(topic).metadata, topic, tc)
                    table = table.replace_schema_metadata(None)
                    n = table.num_rows
                    if "time" in table.column_names:
                        table = table.set_column(0, "time", table.column("time").cast(pa.timestamp("ns", tz="UTC")))
                    else:
                        table = table.add_column(0, "time", pa.nulls(n, pa.timestamp("ns", tz="UTC")))
                    ident = {
                        "path": str(p.resolve()),
                        "subject": None if info.get("subject") is None else str(info["subject"]),
                        "trial": None if info.get("trial") is None else str(info["trial"]),
                        "imu": topic[len(prefix) :],
                    }
                    for k, (name, value) in enumerate(ident.items()):
                        table = table.add_column(k, name, pa.array([value] * n, pa.string()))
                    table = pa.Table.from_arrays(table.columns, names=table.column_names)  # plain field metadata
                    if writer is None:
                        writer = (
                            pq.ParquetWriter(tmp, table.schema)
                            if fmt == "parquet"
                            else pacsv.CSVWriter(tmp, table.schema)
                        )
                        schema_ = table.schema
                    writer.write_table(table.cast(schema_))
                    stats.rows += n
                stats.read += 1
        if writer is None:
            raise ValueError(f"no trial has {prefix}* (run imulog process epochs first)")
        writer.close()
        writer = None
        os.replace(tmp, output)
    except BaseException:
        if writer is not None:
            writer.close()
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    stats.seconds = time.perf_counter() - t0
    return stats


def _error_row(path: Path, error: str) -> dict[str, Any]:
    st = path.stat()
    return {"path": str(path.resolve()), "file_size": st.st_size, "mtime_ns": st.st_mtime_ns, "error": error}


def discover(root: str | os.PathLike[str] | Iterable[str | os.PathLike[str]]) -> list[Path]:
    """Trial files: every ``*.mcap`` below a folder (hidden files skipped), or the given paths / patterns."""
    from imulog.batch.runner import expand_paths

    return [Path(p) for p in expand_paths(root) if os.path.isfile(p)]


@dataclass
class CatalogStats:
    """What :func:`build_catalog` did: rows written, files read (new/changed), rows reused, rows dropped."""

    output: Path
    rows: int = 0
    read: int = 0
    reused: int = 0
    dropped: int = 0
    errors: int = 0
    seconds: float = 0.0

    def summary(self) -> str:
        return (
            f"{self.output}: {self.rows} trials ({self.read} read, {self.reused} unchanged, {self.dropped} removed, "
            f"{self.errors} unreadable) in {self.seconds:.1f} s"
        )


def _old_rows(output: Path) -> dict[str, dict[str, Any]]:
    """Existing rows by path (a catalog that cannot be read, or has another schema, is rebuilt)."""
    if not output.is_file():
        return {}
    import pyarrow.parquet as pq

    try:
        pf = pq.ParquetFile(output)
        if not pf.schema_arrow.equals(schema()):
            return {}
        out = {}
        for batch in pf.iter_batches(batch_size=BATCH_ROWS):
            for row in batch.to_pylist():
                out[row["path"]] = row
        return out
    except Exception:
        return {}


def build_catalog(
    root: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    output: str | os.PathLike[str],
    *,
    progress: bool = False,
    full: bool = False,
) -> CatalogStats:
    """Write (or update) the Parquet catalog ``output`` of every trial under ``root``; return the stats.

    ``full`` re-reads every file. Unreadable files get a row with ``error`` set (and are retried next time).
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    t0 = time.perf_counter()
    output = Path(output)
    out_abs = output.resolve()
    files = [p for p in discover(root) if p.resolve() != out_abs]
    old = {} if full else _old_rows(output)
    stats = CatalogStats(output)
    sch = schema()
    output.parent.mkdir(parents=True, exist_ok=True)
    tmp = output.with_name(f".{output.name}.{os.getpid()}.tmp")
    stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    bar = None
    if progress and files:
        from imulog.console import progress_bar  # tqdm on a terminal, plain lines in logs

        bar = progress_bar(len(files), "catalog", unit="file")
    seen = set()
    try:
        with pq.ParquetWriter(tmp, sch) as writer:
            buffer: list[dict[str, Any]] = []

            def flush() -> None:
                if buffer:
                    writer.write_table(pa.Table.from_pylist(buffer, schema=sch))
                    buffer.clear()

            for p in files:
                key = str(p.resolve())
                seen.add(key)
                prev = old.get(key)
                try:
                    st = p.stat()
                except OSError:
                    continue
                if (
                    prev is not None
                    and not prev.get("error")
                    and (prev["file_size"], prev["mtime_ns"])
                    == (
                        st.st_size,
                        st.st_mtime_ns,
                    )
                ):
                    row = prev
                    stats.reused += 1
                else:
                    try:
                        row = trial_row(p)
                    except Exception as exc:  # an unreadable file is a row with its error, not a failed catalog
                        row = _error_row(p, f"{type(exc).__name__}: {exc}")
                        stats.errors += 1
                    row["cataloged_at"] = stamp
                    stats.read += 1
                buffer.append(row)
                stats.rows += 1
                if len(buffer) >= BATCH_ROWS:
                    flush()
                if bar is not None:
                    bar.update(1)
            flush()
        os.replace(tmp, output)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    finally:
        if bar is not None:
            bar.close()
    stats.dropped = len(set(old) - seen)
    stats.seconds = time.perf_counter() - t0
    return stats
