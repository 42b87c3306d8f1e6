"""``imulog info``, ``imulog doctor`` and ``imulog export``: look at, validate and export a trial file."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import click

from imulog.archive import ArchiveError, TrialReader
from imulog.commands.outputs import overwrite_option, refuse_existing


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
    stored = trial.summary.stored_bytes_by_channel()
    channels = []
    for c in trial.channels:
        md = c.metadata
        if c.message_count == 0:  # nothing stored (salvaged, interrupted): the recorded statistics do not hold
            channels.append(
                {
                    "topic": c.topic,
                    "schema": c.schema_name,
                    "kind": c.kind,
                    "derived": c.derived,
                    "messages": 0,
                    "samples": 0,
                    "rate_hz": None,
                    "start_ns": None,
                    "end_ns": None,
                    "duration_s": None,
                    "time_gaps": None,
                    "nan_samples": None,
                    "units": md.get("units", ""),
                    "frame_id": md.get("frame_id", ""),
                    "stored_bytes": 0,
                    "out_of_date": None,
                    "metadata": md,
                }
            )
            continue
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
    # runs are listed on their own; the closing statistics of streamed channels (imulog.channel_stats[.N]) are
    # already merged into those channels' metadata above, and the records of replaced channels are history
    metadata = {k: v for k, v in trial.metadata.items() if not k.startswith(("imulog.run.", "imulog.channel_stats"))}
    atts = trial.attachment_infos()  # sizes from the index, hashes from imulog.raw: nothing re-read
    return {
        "path": str(trial.path),
        "bytes": trial.summary.file_size,
        "channels": channels,
        "metadata": metadata,
        "attachments": atts,
        "runs": {str(k): v for k, v in runs.items()},
        "out_of_date": sorted(stale),
        "out_of_date_steps": {step: {**v, "rerun": rerun_command(step)} for step, v in trial.stale_steps().items()},
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


def _echo_periods(metrics: dict) -> None:
    """Daily-life summaries of long recordings (``imulog.metrics`` by_day, else by_hour) as a small table."""
    key = "by_day" if isinstance(metrics.get("by_day"), list) else "by_hour"
    rows = metrics.get(key)
    if not isinstance(rows, list) or not rows:
        return
    click.echo(f"daily life ({'per day' if key == 'by_day' else 'per hour'}, from imulog.metrics):")
    click.echo("  start                      valid_h  arm_use_%  activities  distance_area")
    for r in rows[:48]:
        if not isinstance(r, dict):
            continue
        use = r.get("arm_use_percent")
        click.echo(
            f"  {str(r.get('start') or r.get('start_ns')):<26} {float(r.get('valid_s') or 0) / 3600:7.2f}  "
            f"{'-' if use is None else f'{float(use):9.2f}'}  {r.get('activity_count', ''):>10}  "
            f"{float(r.get('distance_weighted_area') or 0):13.1f}"
        )
    if len(rows) > 48:
        click.echo(f"  ... {len(rows) - 48} more (info --json lists all)")


def _echo_flags(metadata: dict) -> None:
    """One line per IMU: the repetitions to distrust and why (issue 31), from the trajectory step when it ran (it
    adds drift to event correction's reasons), else from the phases step. A setup's other IMUs have their records
    as ``imulog.timing.IMU`` / ``imulog.trajectory.IMU``; the IMU is named only when there are several."""
    from imulog.process.repetition_flags import flag_line, trial_flags

    lines = []
    for imu, timing, trajectory in _per_imu_records(metadata, "imulog.timing", "imulog.trajectory"):
        found = trial_flags(timing, trajectory)
        line = flag_line(*found) if found else ""
        if line:
            lines.append((imu, line))
    for imu, line in lines:
        click.echo(f"repetitions ({imu}): {line}" if len(lines) > 1 and imu else f"repetitions: {line}")


def _per_imu_records(metadata: dict, *bases: str) -> list[tuple[str, dict, dict]]:
    """``(imu, record of bases[0], record of bases[1], ...)`` for the unsuffixed records (the primary IMU's,
    named by their ``imu`` key) and every ``BASE.IMU`` record of another IMU; missing records are ``{}``."""
    others = sorted({key[len(base) + 1 :] for key in metadata for base in bases if key.startswith(base + ".")})
    primary = next((str(metadata[b].get("imu") or "") for b in bases if isinstance(metadata.get(b), dict)), "")
    rows = [(primary.removeprefix("/imu/"), *(metadata.get(b) or {} for b in bases))]
    rows += [(imu, *(metadata.get(f"{b}.{imu}") or {} for b in bases)) for imu in others]
    return rows


def _echo_phase_quality(timing: dict) -> None:
    """One line on what event correction did to the phases (imulog.timing, issue 19): forced phases are
    visible as forced."""
    quality = timing.get("repetition_quality") or []
    if not quality:
        return
    total = {k: sum(int(q.get(k) or 0) for q in quality) for k in ("merged", "dropped", "split", "missing")}
    corrected = sum(1 for q in quality if any(int(q.get(k) or 0) for k in total))
    low = timing.get("low_confidence_repetitions") or []
    click.echo(
        f"phases: {timing.get('n_phases', 0)} in {len(quality)} repetitions from {timing.get('n_movements', 0)} "
        f"movements; event correction changed {corrected} (merged {total['merged']}, dropped {total['dropped']}, "
        f"split {total['split']}, missing {total['missing']})"
    )
    low_text = ", ".join(map(str, low[:20])) + (f" +{len(low) - 20} more" if len(low) > 20 else "")
    click.echo(
        f"  {timing.get('n_forced_phases', 0)} forced phases; confidence mean {timing.get('mean_confidence')}, "
        f"low in repetitions {low_text or '-'}"
    )


def _echo_alignment(record: dict) -> None:
    """The IMU-to-Vicon alignment: offset and drift with uncertainty, markers, windows, quality flag."""
    if not record:
        return
    from imulog.steps.align_summary import alignment_summary, setup_lines

    if record.get("setup"):  # several IMUs aligned together: one line per IMU, then the clocks
        click.echo(f"alignment ({len(record['setup'])} IMUs on {record.get('reference', '?')}):")
        for line in setup_lines(record):
            click.echo(f"  {line}")
        return
    lines = alignment_summary(record)
    if lines:
        click.echo(f"alignment ({record.get('imu', '?')} on {record.get('reference', '?')}): {lines[0]}")
        for line in lines[1:]:
            click.echo(f"  {line}")


def _echo_heading(record: dict, channels: list[dict[str, Any]]) -> None:
    """Whether the oriented IMUs share one heading frame (``imulog process heading``); with several
    orientations and no record, that their headings are not related yet."""
    oriented = [c["topic"].rsplit("/", 1)[1] for c in channels if c["topic"].startswith("/derived/orientation/")]
    if not record:
        if len(oriented) > 1:
            click.echo(
                f"heading: not related between {', '.join(oriented)} (no imulog.heading record: "
                "run `imulog process heading`)"
            )
        return
    names = ", ".join(record.get("imus") or {})
    left = [n for n in oriented if n not in (record.get("imus") or {})]
    if left:
        click.echo(f"heading: {', '.join(left)} oriented but not in imulog.heading (run `imulog process heading`)")
    if record.get("source") == "none":
        click.echo(f"heading: not related between {names}: " + "; ".join(record.get("rejected") or []))
    else:
        click.echo(f"heading: one frame for {names}: {record.get('source')} ({record.get('frame')})")


def _echo_wrapped(text: str, width: int | None) -> None:
    """``text`` on lines of at most ``width`` characters (continuations indented); as is when None."""
    import textwrap

    click.echo(text if width is None else textwrap.fill(text, width, subsequent_indent="    "))


def _cut(text: str, width: int | None) -> str:
    return text if width is None or len(text) <= width else text[: width - 3] + "..."


def _channel_row(c: dict[str, Any]) -> tuple[str, ...]:
    """One row of the channels table; a channel without samples (salvaged, interrupted) shows only that."""
    salvaged = str(c["metadata"].get("salvaged", ""))
    topic = (
        c["topic"]
        + (" [out of date]" if c["out_of_date"] else "")
        + (" [assumptions failed]" if c["metadata"].get("assumptions") == "failed" else "")
    )
    if salvaged:
        topic += f" [{salvaged.split(':', 1)[0]}]"
    if not c["samples"]:
        return (topic + " [empty]", c["schema"], "-", "0", "-", "-", f"{c['stored_bytes'] / 1e6:.2f}", "-")
    gaps = f"{c['time_gaps'] if c['time_gaps'] is not None else '-'}/{c['nan_samples'] if c['nan_samples'] is not None else '-'}"
    dur = "-" if c["duration_s"] is None else f"{c['duration_s']:.3f}"
    return (
        topic,
        c["schema"],
        _fmt_rate(c["rate_hz"]),
        str(c["samples"]),
        dur,
        gaps,
        f"{c['stored_bytes'] / 1e6:.2f}",
        _fmt_units(c["units"]),
    )


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("-v", "--verbose", is_flag=True, help="also every run's parameters, the viewer twins, full metadata")
@click.option("--json", "as_json", is_flag=True, help="print one JSON document (for scripts)")
def info(file: str, verbose: bool, as_json: bool) -> None:
    """Show a trial's channels, metadata, attachments and derived runs (compact; -v for everything).

    For every channel: schema, rate (Hz), sample count, duration, gaps (time gaps longer than 1.5
    sample periods / samples with NaN), stored (compressed) size, units and frame. A salvaged channel
    says [partial] (chunks were lost) and a channel with no samples [empty] (no rate, duration or
    gaps). Derived channels whose inputs (channels or metadata records such as imulog.alignment)
    changed since they were computed are marked out of date, with the command that recomputes them.
    By default the viewer twins (/derived/viewer/...) are one line, metadata records one line each
    (cut at 110 characters) and runs one line without their parameters; -v lists them all in full.
    Reads only the summary and the metadata records (fast on any trial size).

    \b
    Examples:
      imulog info trial.mcap
      imulog info trial.mcap -v          # every run's parameters, the viewer twins
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
    width = None if verbose else 110
    click.echo(f"{data['path']}  ({data['bytes'] / 1e6:.2f} MB)")
    click.echo("channels:")
    twins = [c for c in data["channels"] if c["metadata"].get("twin_of") or c["topic"].startswith("/derived/viewer/")]
    shown = data["channels"] if verbose else [c for c in data["channels"] if c not in twins]
    rows = [("topic", "schema", "rate_hz", "samples", "duration_s", "gaps(t/nan)", "MB", "units")]
    rows += [_channel_row(c) for c in shown]
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    for r in rows:
        click.echo("  " + "  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip())
    if twins and not verbose:
        mb = sum(c["stored_bytes"] for c in twins) / 1e6
        click.echo(f"  + {len(twins)} viewer twins under /derived/viewer/ ({mb:.2f} MB; -v lists them)")
    from imulog.archive.timeline import TrialAxis

    _echo_wrapped(f"time axis (MCAP log time): {TrialAxis(data['metadata']).describe()}", width)
    click.echo("metadata:")
    for name, values in data["metadata"].items():
        text = ", ".join(f"{k}={v}" if isinstance(v, str) else f"{k}={json.dumps(v)}" for k, v in values.items())
        click.echo(_cut(f"  {name}: {text}", width))
    _echo_periods(data["metadata"].get("imulog.metrics") or {})
    _echo_alignment(data["metadata"].get("imulog.alignment") or {})
    _echo_heading(data["metadata"].get("imulog.heading") or {}, data["channels"])
    _echo_phase_quality(data["metadata"].get("imulog.timing") or {})
    _echo_flags(data["metadata"])
    failed = [c for c in data["channels"] if c["metadata"].get("assumptions") == "failed"]
    if failed:  # trajectories whose method does not apply to this recording (issue 32)
        click.echo("assumptions failed:")
        for c in failed:
            click.echo(f"  {c['topic']}: {c['metadata'].get('assumptions_why', '')}")
    if data["attachments"]:
        click.echo("attachments:")
        for a in data["attachments"]:
            digest = (a["sha256"] or "-")[:16]
            click.echo(f"  {a['name']}  {a['media_type']}  {a['bytes']} bytes  sha256 {digest}")
    if data["runs"]:
        click.echo("derived runs:" + ("" if verbose else " (-v: their parameters)"))
        for n, r in data["runs"].items():
            outputs = list(r.get("outputs", {}))
            out = ", ".join(outputs) or "-"
            if not verbose and len(outputs) > 3:
                out = f"{', '.join(outputs[:3])} +{len(outputs) - 3} more"
            params = f" params={json.dumps(r.get('params', {}))}" if verbose else ""
            line = f"  #{n} {r.get('step', '')}: {r.get('algorithm', '')}{params} -> {out} ({r.get('time', '')})"
            click.echo(_cut(line, None if verbose else 160))
    if data["out_of_date"] or data["out_of_date_steps"]:
        click.echo("out of date (inputs changed since they were computed):")
        by_step: dict[str, list[str]] = {}
        for c in data["channels"]:
            if c["out_of_date"]:
                by_step.setdefault(c["out_of_date"]["step"], []).append(c["topic"])
        for step, topics in by_step.items():
            reasons = next(c["out_of_date"]["reasons"] for c in data["channels"] if c["topic"] == topics[0])
            click.echo(f"  {', '.join(topics)}: {'; '.join(reasons)} -> rerun {rerun_command(step)}")
        for step, v in data["out_of_date_steps"].items():
            if step not in by_step:  # steps that wrote only metadata records (evaluate, ...)
                click.echo(f"  step {step} (run #{v['run']}): {'; '.join(v['reasons'])} -> rerun {v['rerun']}")


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("-v", "--verbose", is_flag=True, help="list every check and every problem")
@click.option("--json", "as_json", is_flag=True, help="print the report (ok, problems, checks) as one JSON document")
@click.option(
    "--original",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="also check that this file is one the trial was converted from (its SHA-256 against the recorded one)",
)
def doctor(file: str, verbose: bool, as_json: bool, original: str | None = None) -> None:
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
      imulog doctor week.mcap --original week.cwa     # the .cwa kept apart is the one it was converted from
    """
    from imulog.archive.doctor import check_file, check_length, check_original

    if sys.stderr.isatty() and not as_json:  # a progress bar for people, nothing extra in logs and pipes
        with click.progressbar(length=check_length(file), label="checking", file=sys.stderr) as bar:
            report = check_file(file, progress=bar.update)
    else:
        report = check_file(file)
    if original is not None:
        ok, line = check_original(file, original)
        (report.checks.append if ok else report.fail)(line)
    if as_json:
        click.echo(
            json.dumps(
                {
                    "path": file,
                    "ok": not report.problems,
                    "problems": list(report.problems),
                    "checks": list(report.checks),
                },
                indent=2,
            )
        )
        if report.problems:
            raise click.exceptions.Exit(1)
        return
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
@click.option(
    "-o", "--output", required=True, type=click.Path(), help="OUT.parquet, .csv, .sto, .c3d, or a folder for --to bids"
)
@click.option(
    "--to",
    "target",
    type=click.Choice(["parquet", "csv", "sto", "bids", "c3d"]),
    default=None,
    help="what to write (default: from OUTPUT's suffix; no suffix means bids)",
)
@click.option(
    "--topic", "-t", "topics", multiple=True, help="channel for parquet/csv, e.g. /imu/wrist (one per output file)"
)
@click.option(
    "--clock",
    type=click.Choice(["device", "reference"]),
    default=None,
    help="device: every channel on the IMU's clock; reference: on the Vicon clock through imulog.alignment "
    "(default: device; c3d: reference)",
)
@click.option("--imu", default=None, help="which IMU's device clock --clock device means (default: the only one)")
@click.option("--start-ns", type=int, default=None, help="parquet/csv: first stored time stamp to include (ns)")
@click.option("--end-ns", type=int, default=None, help="parquet/csv: stored time stamp to stop at (ns, exclusive)")
@click.option(
    "--name",
    "names",
    multiple=True,
    metavar="IMU=COLUMN",
    help="sto: column (OpenSim body frame) of an IMU, by name, serial or label (wrist=hand_r_imu; repeatable); "
    "a name that matches no IMU is refused",
)
@click.option(
    "--source",
    "orientation_source",
    type=click.Choice(["auto", "derived", "device"]),
    default="auto",
    show_default=True,
    help="sto: per IMU, imulog's /derived/orientation (auto: where present) or the device's own /orientation",
)
@click.option("--rate", type=float, default=None, help="sto: rate of the uniform grid in Hz (default: the IMU's)")
@click.option("--no-imu", is_flag=True, help="c3d: markers, analogs and events only")
@overwrite_option("replace OUTPUT (a file, or the bids folder) if it exists; refused otherwise")
@click.option("--json", "as_json", is_flag=True, help="print what was written as one JSON document")
def export(
    file: str,
    output: str,
    target: str | None,
    topics: tuple[str, ...],
    clock: str | None,
    imu: str | None,
    start_ns: int | None,
    end_ns: int | None,
    names: tuple[str, ...],
    orientation_source: str,
    rate: float | None,
    no_imu: bool,
    overwrite: bool,
    as_json: bool,
) -> None:
    """Export a trial to the files other tools read (docs/export.md).

    \b
    parquet/csv  one channel: time (timestamp with the trial's time zone), t[s], t_ns, then
                 columns with units in their names (acc_x[m/s^2]); Parquet also keeps units
                 and provenance in field and schema metadata
    sto          OpenSense orientation file, every IMU: /derived/orientation/* or the device's
                 own /orientation/* (w,x,y,z per IMU; says when headings are not shared)
    bids         a BIDS-motion folder: *_motion.tsv, *_channels.tsv, *_motion.json, *_events.tsv
    c3d          markers (mm), IMU and analog channels as analogs, phases as events

    Every export puts all channels on one clock; --clock reference needs an alignment
    (imulog process align). Files are written to a temporary name and renamed; an existing
    OUTPUT is refused unless --overwrite. c3d needs the c3d extra: pip install 'imulog[c3d]'.

    \b
    Examples:
      imulog export trial.mcap --topic /imu/wrist -o wrist.parquet
      imulog export trial.mcap --topic /derived/phases/wrist -o phases.csv --clock reference
      imulog export trial.mcap -o trial.sto --name wrist=hand_r_imu
      imulog export xsens.mcap -o xsens.sto --source device --name 00B421AF=pelvis_imu
      imulog export trial.mcap --to bids -o bids/
      imulog export trial.mcap -o trial.c3d
    """
    from imulog.export import ClockError, ExportError

    suffix = Path(output).suffix.lower().lstrip(".")
    target = target or (suffix if suffix in ("parquet", "csv", "sto", "c3d") else "bids" if not suffix else None)
    if target is None:
        raise click.BadParameter(f"{output}: cannot tell the format from .{suffix}; give --to", param_hint="--to")
    if start_ns is not None and end_ns is not None and end_ns <= start_ns:
        raise click.BadParameter(
            f"{end_ns} is not after --start-ns {start_ns} (the range is empty)", param_hint="--end-ns"
        )
    if target in ("parquet", "csv") and not topics:
        raise click.UsageError(f"--to {target} exports one channel: give --topic (imulog info {file} lists them)")
    if topics and target not in ("parquet", "csv"):
        raise click.UsageError(f"--to {target} takes no --topic (it writes every channel it supports): {topics[0]}")
    if len(topics) > 1:
        raise click.UsageError(
            f"--to {target} writes one channel per file, got {len(topics)} ({', '.join(topics)}): "
            "run export once per --topic"
        )
    topic = topics[0] if topics else None
    refuse_existing(output, overwrite=overwrite)
    rename = {}
    for item in names:
        key, sep, value = item.partition("=")
        if not sep or not key or not value:
            raise click.BadParameter(f"{item!r} is not IMU=COLUMN", param_hint="--name")
        rename[key] = value
    with _open(file) as trial:
        try:
            if target in ("parquet", "csv"):
                from imulog.export.table import export_table

                result = export_table(
                    trial, topic, output, fmt=target, clock=clock or "device", imu=imu, start_ns=start_ns, end_ns=end_ns
                )
            elif target == "sto":
                from imulog.export.sto import export_sto

                result = export_sto(
                    trial,
                    output,
                    clock=clock or "device",
                    imu=imu,
                    names=rename,
                    rate_hz=rate,
                    source=orientation_source,
                )
            elif target == "bids":
                from imulog.export.bids import export_bids

                # an empty folder is free to use (refuse_existing above)
                result = export_bids(trial, output, clock=clock or "device", imu=imu, overwrite=True)
            else:
                from imulog.export.c3d import export_c3d

                result = export_c3d(trial, output, clock=clock or "reference", imu=imu, include_imu=not no_imu)
        except (ArchiveError, ClockError, ExportError) as exc:
            raise click.ClickException(str(exc)) from None
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=2))
        return
    for note in result.notes:
        click.echo(f"note: {note}", err=True)
    what = f"{result.rows} rows x {len(result.columns)} columns of {topic}" if topic else f"{result.rows} samples"
    if target == "bids":
        what += f" in {len(result.files)} files"
    click.echo(f"wrote {what} to {output} ({target}, {result.clock} clock)")


@click.command()
@click.argument("file", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False), help="FIXED.mcap to write")
@overwrite_option("replace OUTPUT if it exists; refused otherwise")
@click.option("--json", "as_json", is_flag=True, help="print the report as one JSON document")
def salvage(file: str, output: str, overwrite: bool, as_json: bool) -> None:
    """Recover every intact channel, attachment and metadata record of a damaged or truncated MCAP file.

    Scans the records from the start (the summary may be missing: a writer that died, an interrupted
    copy, another MCAP writer), keeps every chunk that passes its CRC and every attachment that passes
    its own, and writes them to OUTPUT (atomically) with an imulog.salvage record of what was lost: per
    channel the time spans lost, and the metadata records dropped because they failed their checks.
    Channels recovered in part get their sample count, start, end and content hash recomputed and
    imulog.raw is rewritten to what was recovered, so OUTPUT passes `imulog doctor`; it is checked
    before it is written. FILE is never modified. Exit status 0 only when OUTPUT passes doctor; 1 with
    a one-line reason (nothing written) when nothing is recoverable (e.g. the first chunk is cut) or
    the output would not pass.

    \b
    Examples:
      imulog salvage broken.mcap -o fixed.mcap
      imulog salvage broken.mcap -o fixed.mcap --json | python -c "import json,sys; print(json.load(sys.stdin)['lost'])"
    """
    from imulog.archive.salvage import lines
    from imulog.archive.salvage import salvage as run_salvage

    if not (Path(output).exists() and Path(output).resolve() == Path(file).resolve()):  # salvage names that one
        refuse_existing(output, overwrite=overwrite)
    try:
        report = run_salvage(file, output, overwrite=overwrite)
    except ArchiveError as exc:
        raise click.ClickException(str(exc)) from None
    if as_json:
        click.echo(json.dumps(report.to_dict(), indent=2))
        return
    for line in lines(report):
        click.echo(line)
