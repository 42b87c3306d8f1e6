"""``imulog info``, ``imulog doctor`` and ``imulog export``: look at, validate and export a trial file."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import click

from imulog.archive import ArchiveError, TrialReader


def _open(path: str) -> TrialReader:
    try:
        return TrialReader(path)
    except ArchiveError as exc:
        raise click.ClickException(str(exc)) from None


def rerun_command(step: str) -> str:
    """The command that reruns a recorded step (``orientation:wrist`` -> ``imulog process orientation``)."""
    from imulog.cli import PROCESS_COMMANDS, TOP_LEVEL_COMMANDS

    base = step.split(":", 1)[0]
    if base in PROCESS_COMMANDS:
        return f"imulog process {base}"
    if base in TOP_LEVEL_COMMANDS:
        return f"imulog {base}"
    return f"the step {step!r}"


def trial_summary(trial: TrialReader) -> dict[str, Any]:
    """Everything ``imulog info`` shows, as a JSON-able dict (summary and metadata only: no channel or
    attachment data is read)."""
    stale = trial.stale_channels()
    stored: dict[int, int] = {}
    for ci in trial.summary.chunk_indexes:
        for cid in ci.message_index_offsets:
            stored[cid] = stored.get(cid, 0) + ci.chunk_length // len(ci.message_index_offsets)
    channels = []
    for c in trial.channels:
        md = c.metadata
        channels.append(
            {
                "topic": c.topic,
                "schema": c.schema_name,
                "kind": c.kind,
                "derived": c.derived,
                "messages": c.message_count,
                "samples": c.sample_count,
                "rate_hz": c.rate_hz,
                "start_ns": c.start_ns,
                "end_ns": c.end_ns,
                "duration_s": c.duration_s,
                "time_gaps": int(md["time_gaps"]) if "time_gaps" in md else None,
                "nan_samples": int(md["nan_samples"]) if "nan_samples" in md else None,
                "units": md.get("units", ""),
                "frame_id": md.get("frame_id", ""),
                "stored_bytes": stored.get(c.channel_id, 0),
                "out_of_date": (
                    {**stale[c.topic], "rerun": rerun_command(stale[c.topic]["step"])} if c.topic in stale else None
                ),
                "metadata": md,
            }
        )
    runs = trial.runs()
    metadata = {k: v for k, v in trial.metadata.items() if not k.startswith("imulog.run.")}
    atts = trial.attachment_infos()  # sizes from the index, hashes from imulog.raw: nothing re-read
    return {
        "path": str(trial.path),
        "bytes": trial.summary.file_size,
        "channels": channels,
        "metadata": metadata,
        "attachments": atts,
        "runs": {str(k): v for k, v in runs.items()},
        "out_of_date": sorted(stale),
    }


def _fmt_units(units: str) -> str:
    """A short form of a channel's units: ``V x38`` for many equal units, else the list, cut at 40 chars."""
    try:
        values = json.loads(units)
    except ValueError:
        return units
    if not isinstance(values, list):
        return str(values)
    if len(values) > 1 and len(set(values)) == 1:
        return f"{values[0]} x{len(values)}"
    text = ",".join(str(v) for v in values)
    return text if len(text) <= 40 else text[:37] + "..."


def _fmt_rate(rate: float | None) -> str:
    return "-" if not rate else f"{rate:.6g}"


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="print one JSON document (for scripts)")
def info(file: str, as_json: bool) -> None:
    """Show a trial's channels, metadata, attachments and derived runs.

    For every channel: schema, rate (Hz), sample count, duration, gaps (time gaps longer than 1.5
    sample periods / samples with NaN), stored (compressed) size, units and frame. Derived channels
    whose inputs (channels or metadata records such as imulog.alignment) changed since they were
    computed are marked out of date, with the command that recomputes them. Reads only the summary and
    the metadata records (fast on any trial size).

    \b
    Examples:
      imulog info trial.mcap
      imulog info trial.mcap --json | python -c "import json,sys; print(json.load(sys.stdin)['channels'][0])"
    """
    with _open(file) as trial:
        try:
            data = trial_summary(trial)
        except ArchiveError as exc:
            raise click.ClickException(str(exc)) from None
    if as_json:
        click.echo(json.dumps(data, indent=2, default=str))
        return
    click.echo(f"{data['path']}  ({data['bytes'] / 1e6:.2f} MB)")
    click.echo("channels:")
    rows = [("topic", "schema", "rate_hz", "samples", "duration_s", "gaps(t/nan)", "MB", "units")]
    for c in data["channels"]:
        gaps = f"{c['time_gaps'] if c['time_gaps'] is not None else '-'}/{c['nan_samples'] if c['nan_samples'] is not None else '-'}"
        dur = "-" if c["duration_s"] is None else f"{c['duration_s']:.3f}"
        mb = f"{c['stored_bytes'] / 1e6:.2f}"
        rows.append(
            (
                c["topic"] + (" [out of date]" if c["out_of_date"] else ""),
                c["schema"],
                _fmt_rate(c["rate_hz"]),
                str(c["samples"]),
                dur,
                gaps,
                mb,
                _fmt_units(c["units"]),
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for r in rows:
        click.echo("  " + "  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip())
    click.echo("metadata:")
    for name, values in data["metadata"].items():
        shown = ", ".join(f"{k}={v}" if isinstance(v, str) else f"{k}={json.dumps(v)}" for k, v in values.items())
        if len(shown) > 200:
            shown = shown[:197] + "..."
        click.echo(f"  {name}: {shown}")
    if data["attachments"]:
        click.echo("attachments:")
        for a in data["attachments"]:
            digest = (a["sha256"] or "-")[:16]
            click.echo(f"  {a['name']}  {a['media_type']}  {a['bytes']} bytes  sha256 {digest}")
    if data["runs"]:
        click.echo("derived runs:")
        for n, r in data["runs"].items():
            outputs = ", ".join(r.get("outputs", {})) or "-"
            click.echo(
                f"  #{n} {r.get('step', '')}: {r.get('algorithm', '')} params={json.dumps(r.get('params', {}))} "
                f"-> {outputs} ({r.get('time', '')})"
            )
    if data["out_of_date"]:
        click.echo("out of date (inputs changed since they were computed):")
        by_step: dict[str, list[str]] = {}
        for c in data["channels"]:
            if c["out_of_date"]:
                by_step.setdefault(c["out_of_date"]["step"], []).append(c["topic"])
        for step, topics in by_step.items():
            reasons = next(c["out_of_date"]["reasons"] for c in data["channels"] if c["topic"] == topics[0])
            click.echo(f"  {', '.join(topics)}: {'; '.join(reasons)} -> rerun {rerun_command(step)}")


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("-v", "--verbose", is_flag=True, help="list every check and every problem")
def doctor(file: str, verbose: bool) -> None:
    """Validate a trial: CRCs, summary/statistics, decoding, raw-data hash.

    Checks the MCAP magic and footer, the summary CRC, the data-section CRC and every chunk CRC,
    that chunk/attachment/metadata indexes and statistics match the data, that every channel decodes
    (also with only the schema embedded in the file), that every channel's content hash matches the
    one recorded when it was written, and that the raw channels and attachments still have the
    raw-data hash recorded at conversion. Exit status 0 when sound, 1 with a one-line reason if not.

    \b
    Examples:
      imulog doctor trial.mcap
      for f in archive/*.mcap; do imulog doctor "$f" || echo "$f is damaged"; done
    """
    from imulog.archive.doctor import check_file, check_length

    if sys.stderr.isatty():  # a progress bar for people, nothing extra in logs and pipes
        with click.progressbar(length=check_length(file), label="checking", file=sys.stderr) as bar:
            report = check_file(file, progress=bar.update)
    else:
        report = check_file(file)
    if verbose:
        for line in report.checks:
            click.echo(f"ok: {line}")
        for line in report.problems:
            click.echo(f"problem: {line}", err=True)
    if report.problems:
        more = f" (+{len(report.problems) - 1} more problems; -v lists them)" if len(report.problems) > 1 else ""
        raise click.ClickException(f"{file}: {report.problems[0]}{more}")
    click.echo(f"{file}: ok ({'; '.join(report.checks)})")


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("--topic", "-t", required=True, help="channel to export, e.g. /imu/wrist")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="OUT.parquet or OUT.csv")
@click.option("--start-ns", type=int, default=None, help="first time stamp to include (ns, inclusive)")
@click.option("--end-ns", type=int, default=None, help="time stamp to stop at (ns, exclusive)")
def export(file: str, topic: str, output: str, start_ns: int | None, end_ns: int | None) -> None:
    """Export one channel as a table (Parquet or CSV): a t_ns column plus one column per value.

    IMU channels give acc_x..mag_z (SI units), markers give <label>_x/_y/_z (m) and <label>_valid,
    signals their named columns, intervals start_ns/end_ns/label/task_index. Parquet keeps the channel
    metadata (units, frame, provenance) in the schema metadata.

    \b
    Examples:
      imulog export trial.mcap --topic /imu/wrist -o wrist.parquet
      imulog export trial.mcap --topic /derived/phases/wrist -o phases.csv
    """
    out = Path(output)
    if out.suffix.lower() not in (".parquet", ".csv"):
        raise click.ClickException(f"{output}: output must end in .parquet or .csv")
    if start_ns is not None and end_ns is not None and end_ns <= start_ns:
        raise click.BadParameter(
            f"{end_ns} is not after --start-ns {start_ns} (the range is empty)", param_hint="--end-ns"
        )
    with _open(file) as trial:
        try:
            table = trial.read_arrow(topic, start_ns, end_ns)
        except ArchiveError as exc:
            raise click.ClickException(str(exc)) from None
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        if out.suffix.lower() == ".parquet":
            import pyarrow.parquet as pq

            pq.write_table(table, out)
        else:
            import pyarrow.csv as pacsv

            pacsv.write_csv(table, out)
    except OSError as exc:
        raise click.ClickException(f"{output}: cannot write ({exc.strerror or exc})") from None
    click.echo(f"wrote {table.num_rows} rows x {table.num_columns} columns of {topic} to {out}")
