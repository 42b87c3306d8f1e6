"""One channel as a typed table file (Parquet or CSV), block by block and atomically.

The columns are those of :func:`imulog.archive.tables.stream_table` (wall-clock time, seconds from start,
units in names).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from imulog.archive.errors import ArchiveError
from imulog.archive.tables import column_units, labelled, stream_table
from imulog.archive.trial_clock import ClockError, trial_clock
from imulog.export._atomic import ExportError, atomic_file

if TYPE_CHECKING:
    from imulog.archive.reader import TrialReader

FORMATS = ("parquet", "csv")


@dataclass
class ExportResult:
    """What an export wrote (``to_dict`` is what ``--json`` prints)."""

    path: str
    format: str
    clock: str
    rows: int = 0
    columns: list[str] = field(default_factory=list)
    topics: list[str] = field(default_factory=list)
    files: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in ("path", "format", "clock", "rows", "columns", "topics", "files", "notes")}


def channel_table(
    trial,
    topic: str,
    *,
    clock: str = "device",
    imu: str | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
):
    """The whole channel (optionally ``start_ns <= t < end_ns`` on its stored clock) as one table."""
    tc = trial_clock(trial, clock, imu)
    stream = trial.read(topic, start_ns, end_ns)
    return stream_table(stream, trial.channel(topic).metadata, topic, tc)


def format_of(path: str | Path, fmt: str | None = None) -> str:
    """``parquet`` or ``csv`` from ``fmt`` or the file's suffix."""
    fmt = (fmt or Path(path).suffix.lstrip(".")).lower()
    if fmt not in FORMATS:
        raise ExportError(f"{path}: a table export ends in .parquet or .csv (or give --to parquet|csv)")
    return fmt


def export_table(
    trial: TrialReader,
    topic: str,
    out: str | Path,
    *,
    fmt: str | None = None,
    clock: str = "device",
    imu: str | None = None,
    start_ns: int | None = None,
    end_ns: int | None = None,
) -> ExportResult:
    """Write one channel to Parquet or CSV, block by block (memory bounded by one chunk), atomically."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    fmt = format_of(out, fmt)
    tc = trial_clock(trial, clock, imu)
    meta = trial.channel(topic).metadata
    result = ExportResult(path=str(out), format=fmt, clock=clock, topics=[topic], files=[str(out)])
    if meta.get("kind") == "intervals":
        pieces = iter([trial.read(topic, start_ns, end_ns)])
    else:
        pieces = trial.iter_blocks(topic, start_ns, end_ns)
    with atomic_file(out) as tmp:
        writer = None
        try:
            for stream in pieces:
                table = stream_table(stream, meta, topic, tc)
                if writer is None:
                    writer = (
                        pq.ParquetWriter(tmp, table.schema) if fmt == "parquet" else pacsv.CSVWriter(tmp, table.schema)
                    )
                    result.columns = table.column_names
                writer.write_table(table)
                result.rows += table.num_rows
            if writer is None:  # nothing in range: an empty table with the right columns
                table = stream_table(trial.read(topic, start_ns, end_ns), meta, topic, tc)
                result.columns = table.column_names
                if fmt == "parquet":
                    pq.write_table(table, tmp)
                else:
                    pacsv.write_csv(table, tmp)
        finally:
            if writer is not None:
                writer.close()
    result.notes = tc.export_notes()
    return result


__all__ = [
    "ArchiveError",
    "ClockError",
    "ExportResult",
    "channel_table",
    "column_units",
    "export_table",
    "format_of",
    "labelled",
    "stream_table",
]
