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
import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from imulog.batch.catalog_row import (
    BOOL_COLUMNS,
    FLOAT_COLUMNS,
    INT_COLUMNS,
    JSON_COLUMNS,
    KEY_COLUMNS,
    LIST_COLUMNS,
    STRING_COLUMNS,
    _record,
    schema,
    trial_row,
)

__all__ = [
    "BATCH_ROWS",
    "BOOL_COLUMNS",
    "build_catalog",
    "build_epoch_table",
    "CatalogStats",
    "discover",
    "FLOAT_COLUMNS",
    "INT_COLUMNS",
    "JSON_COLUMNS",
    "KEY_COLUMNS",
    "LIST_COLUMNS",
    "schema",
    "STRING_COLUMNS",
    "trial_row",
]

BATCH_ROWS = 256


def wall_clock_columns(wall: Any, start: Any, n: int) -> tuple[Any, Any]:
    """``(time, local_time)`` Arrow arrays of the study epoch table from a stream table's ``time`` column
    (``wall``; None when the trial has no start time), the trial's start (``TrialClock.start_time``) and the
    number of rows ``n``.

    ``time``: UTC instants, only when the start has a zone (a device clock in local time without one, as a
    ``.cwa`` or ``.gt3x`` keeps, is no instant); ``local_time``: the wall-clock time the device kept (naive: local
    time at the recording's place), whenever there is a start; both null without one (an Xsens MT Manager
    export: ``// Start Time: Unknown``).
    """
    import pyarrow as pa
    import pyarrow.compute as pc

    utc_type, local_type = pa.timestamp("ns", tz="UTC"), pa.timestamp("ns")
    if wall is None:
        return pa.nulls(n, utc_type), pa.nulls(n, local_type)
    ns = pc.cast(wall, pa.int64())
    if start is None or start.tzinfo is None:  # naive: the device's local wall clock, no instant
        return pa.nulls(n, utc_type), ns.cast(local_type)
    offset_ns = int(start.utcoffset().total_seconds() * 1e9)
    return ns.cast(utc_type), pc.add(ns, offset_ns).cast(local_type)


def build_epoch_table(
    root: str | os.PathLike[str] | Iterable[str | os.PathLike[str]],
    output: str | os.PathLike[str],
    *,
    epoch_s: float = 60.0,
) -> CatalogStats:
    """One study table of every trial's ``/derived/epochs/{epoch_s}s/{imu}`` rows (``imulog process epochs``).

    Columns: ``path``, ``subject``, ``trial``, ``imu``, ``device`` (its model) and ``serial`` (from the trial's
    ``imulog.device.IMU`` record: a study of several devices tells their epochs apart), then the times
    (:func:`wall_clock_columns`: ``time`` UTC instants and ``local_time`` the device's wall clock where known;
    ``t[s]`` seconds since the recording's start, always filled; ``t_ns`` the stored stamp) and the epoch columns. Trials without the channel are skipped
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
                    wall = table.column("time") if "time" in table.column_names else None
                    if wall is not None:
                        table = table.remove_column(0)
                    utc, local = wall_clock_columns(wall, tc.start_time, n)
                    table = table.add_column(0, "local_time", local).add_column(0, "time", utc)
                    imu = topic[len(prefix) :]
                    device = _record(trial.metadata.get(f"imulog.device.{imu}"))
                    ident = {
                        "path": str(p.resolve()),
                        "subject": None if info.get("subject") is None else str(info["subject"]),
                        "trial": None if info.get("trial") is None else str(info["trial"]),
                        "imu": imu,
                        "device": str(device.get("model") or "") or None,  # a study of several devices
                        "serial": str(device.get("serial") or "") or None,
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
