"""``imulog info``, ``imulog doctor`` and ``imulog export``: look at, validate and export a trial file."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from imulog.archive import ArchiveError, TrialReader
from imulog.commands.outputs import overwrite_option, refuse_existing


def open_trial(path: str) -> TrialReader:
    """The trial at ``path``, or a one-line click error naming what is wrong with it."""
    try:
        return TrialReader(path)
    except ArchiveError as exc:
        raise click.ClickException(str(exc)) from None


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
    "-o",
    "--output",
    required=True,
    type=click.Path(),
    help="OUT.parquet, .csv, .sto, .trc, .c3d, or a folder for --to bids",
)
@click.option(
    "--to",
    "target",
    type=click.Choice(["parquet", "csv", "sto", "trc", "bids", "c3d"]),
    default=None,
    help="what to write (default: from OUTPUT's suffix; no suffix means bids)",
)
@click.option(
    "--topic",
    "-t",
    "topics",
    multiple=True,
    help="channel for parquet/csv, e.g. /imu/wrist (one per output file); trc: the marker channel (default: the only one)",
)
@click.option(
    "--clock",
    type=click.Choice(["device", "reference"]),
    default=None,
    help="device: every channel on the IMU's clock; reference: on the Vicon clock through imulog.alignment "
    "(default: device; c3d and trc: reference)",
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
    trc          OpenSim marker file: one marker channel, mm, the trial's marker names
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
      imulog export trial.mcap -o markers.trc                       # OpenSim's marker file
    """
    from imulog.export import ClockError, ExportError

    suffix = Path(output).suffix.lower().lstrip(".")
    target = target or (suffix if suffix in ("parquet", "csv", "sto", "trc", "c3d") else "bids" if not suffix else None)
    if target is None:
        raise click.BadParameter(f"{output}: cannot tell the format from .{suffix}; give --to", param_hint="--to")
    if start_ns is not None and end_ns is not None and end_ns <= start_ns:
        raise click.BadParameter(
            f"{end_ns} is not after --start-ns {start_ns} (the range is empty)", param_hint="--end-ns"
        )
    if target in ("parquet", "csv") and not topics:
        raise click.UsageError(f"--to {target} exports one channel: give --topic, {_channel_choice(file)}")
    if topics and target not in ("parquet", "csv", "trc"):
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
    with open_trial(file) as trial:
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
            elif target == "trc":
                from imulog.export.trc import export_trc

                result = export_trc(trial, output, topic=topic, clock=clock or "reference", imu=imu)
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


def _channel_choice(file) -> str:
    """For a table export without --topic: an example and the trial's channels (the viewer twins left out), read
    from the summary; the ``imulog info`` hint when the file cannot be read."""
    try:
        with open_trial(file) as trial:
            channels = [t for t in trial.topics() if not t.startswith("/derived/viewer/")]
    except (click.ClickException, OSError, ValueError):
        channels = []
    if not channels:
        return f"e.g. --topic /imu/NAME (imulog info {file} lists them)"
    most = 6
    shown = ", ".join(channels[:most]) + (f", ... ({len(channels) - most} more)" if len(channels) > most else "")
    return f"e.g. --topic {channels[0]} (the trial's channels: {shown})"
