"""``imulog record`` and ``imulog replay``: live capture from Lab Streaming Layer, and a trial sent as LSL outlets."""

from __future__ import annotations

import signal
import threading
from pathlib import Path

import click

from imulog.commands.convert import load_meta_file, parse_meta

CONTEXT = {"help_option_names": ["-h", "--help"]}


def _stop_on_signals(stop: threading.Event) -> None:
    """Ctrl-C (SIGINT) and SIGTERM set ``stop``: the loop finishes the file and prints its summary."""

    def handler(signum, frame) -> None:  # noqa: ARG001
        if stop.is_set():  # a second Ctrl-C: the user insists
            raise KeyboardInterrupt
        # Event.set takes the event's lock, which the interrupted main thread may hold (inside the loop's stop.wait):
        # set from a helper thread that waits for the lock, never in the handler (where it could deadlock forever)
        threading.Thread(target=stop.set, name="imulog-stop", daemon=True).start()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


@click.command(context_settings=CONTEXT)
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), help="Trial file (required).")
@click.option(
    "--stream",
    "filters",
    multiple=True,
    metavar="KEY=VALUE",
    help="Record the streams with this name=, type= or source_id= (repeatable; default: every visible stream). "
    "A name or type can be shared by other programs' streams: source_id= picks one device.",
)
@click.option(
    "--wait",
    "wait_s",
    type=click.FloatRange(min=0.0),
    default=5.0,
    show_default=True,
    help="Seconds to wait for the streams (without --stream: the whole wait, then every stream found).",
)
@click.option("--duration", "duration_s", type=click.FloatRange(min=0.0, min_open=True), help="Stop after this many s.")
@click.option("--meta", multiple=True, metavar="KEY=VALUE", help="Trial metadata, as for imulog convert (repeatable).")
@click.option("--meta-file", type=click.Path(exists=True, dir_okay=False, path_type=Path), help="JSON/TOML metadata.")
@click.option("--list", "list_only", is_flag=True, help="List the streams found and exit (nothing is recorded).")
@click.option("--overwrite", is_flag=True, help="Replace an existing OUTPUT (or the .part of a killed recording).")
@click.option("--view", is_flag=True, help="Show the streams live in Rerun (native viewer), with VQF orientation.")
@click.option("--web", is_flag=True, help="With --view: serve the viewer in the browser, on localhost.")
@click.option("--port", "web_port", type=click.IntRange(0, 65535), default=9090, show_default=True, help="--web port.")
@click.option("--grpc-port", type=click.IntRange(0, 65535), default=9876, show_default=True, help="Rerun gRPC port.")
def record(
    output: Path,
    filters: tuple[str, ...],
    wait_s: float,
    duration_s: float | None,
    meta: tuple[str, ...],
    meta_file: Path | None,
    list_only: bool,
    overwrite: bool,
    view: bool,
    web: bool,
    web_port: int,
    grpc_port: int,
) -> None:
    """Record Lab Streaming Layer streams into a trial, crash-safe, until Ctrl-C / SIGTERM (or --duration).

    Each stream is written as it arrives into the channels imulog convert makes for the same stream in
    an XDF file: IMU streams (channel labels acc_x.., gyro_x.. with units) as /imu/<stream>, MoCap
    streams as /markers/<stream>, other numeric streams as /signals/<stream>, string streams as
    /events/<stream>; the streams' XML headers, the clock offsets (time_correction) applied and the raw
    LSL stamps (/signals/<stream>_lsl_clock) are kept. Until it stops the file is OUTPUT.part, with every
    chunk flushed at least every second: after a kill, `imulog salvage OUTPUT.part -o OUTPUT` recovers all
    but the last second. Then `imulog process ...` as for a converted trial. liblsl's info lines are left
    out unless an LSL config file of yours sets its [log] level (docs/record.md); its warnings and
    errors are shown.

    \b
    Examples:
      imulog record -o trial.mcap                                  # every stream, until Ctrl-C
      imulog record -o trial.mcap --stream type=IMU --stream name=Mocap --meta subject=S01
      imulog record -o trial.mcap --duration 60 --meta-file trial_meta.json
      imulog record -o trial.mcap --view --web                     # and watch it in the browser
      imulog record --list                                         # what is on the network
      imulog record -o trial.mcap --stream source_id=xio-1234      # one device, whatever its name
      imulog replay trial.mcap                                     # (another terminal) a trial as outlets
    """
    from imulog.archive.errors import ArchiveError
    from imulog.live.lsl import LslError, StreamFilter, describe, resolve, shared_names

    if output is None and not list_only:
        raise click.UsageError("Missing option '-o' / '--output' (only --list needs none).")
    try:
        wanted = [StreamFilter.parse(f) for f in filters]
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--stream") from None
    metadata = load_meta_file(meta_file) if meta_file else {}
    for name, values in parse_meta(meta).items():
        metadata[name] = {**metadata.get(name, {}), **values}
    if not list_only and not overwrite:  # refused before waiting for streams (the writer checks again, locked)
        from imulog.live.writer import part_path

        for existing in (output, part_path(output)):
            if existing.exists():
                hint = f"; recover it with: imulog salvage {existing} -o OUT.mcap" if existing != output else ""
                raise click.ClickException(f"{existing} exists (use --overwrite){hint}")
    try:
        infos = resolve(wanted, wait_s)
    except LslError as exc:
        raise click.ClickException(str(exc)) from None
    click.echo(f"found {len(infos)} stream(s):", err=True)
    for info in infos:
        click.echo(f"  {describe(info)}", err=True)
    for line in shared_names(infos):
        click.echo(f"warning: {line}", err=True)
    if list_only:
        return
    if web and not view:
        raise click.UsageError("--web goes with --view")
    stop = threading.Event()
    _stop_on_signals(stop)
    live = None
    try:
        if view:
            from imulog.live.view import LiveView

            live = LiveView(web=web, web_port=web_port, grpc_port=grpc_port, spawn_port=grpc_port)
            if live.url:
                click.echo(f"live view: {live.url}", err=True)
        _record(output, infos, metadata, overwrite, stop, duration_s, live)
    except (ArchiveError, LslError, OSError, RuntimeError, KeyboardInterrupt) as exc:
        from imulog.live.writer import part_path

        part = part_path(output)
        message = "interrupted" if isinstance(exc, KeyboardInterrupt) else str(exc)
        if part.exists():
            message += f"; the recording so far is in {part}: imulog salvage {part} -o {output}"
        raise click.ClickException(message) from None
    finally:
        if live is not None:
            try:
                live.close()
            except RuntimeError as exc:  # the trial is written all the same
                click.echo(f"warning: {exc}", err=True)
            click.echo(live.summary(), err=True)


def _record(output, infos, metadata, overwrite, stop, duration_s, live=None) -> None:
    from imulog.live.recorder import Recorder, open_streams, summary_lines
    from imulog.live.writer import LiveTrialWriter

    streams = open_streams(infos)
    metadata = {
        **metadata,
        "imulog.conversion": {"format": "lsl", "recorder": "imulog record", "streams": [s.name for s in streams]},
    }
    with LiveTrialWriter(output, metadata=metadata, overwrite=overwrite, expected_duration_s=duration_s) as writer:
        click.echo(f"recording into {writer.part} (Ctrl-C to stop)", err=True)
        show = (lambda piece: live.submit(piece, writer.metadata)) if live is not None else None
        if live is not None:
            live.start()
        recorder = Recorder(
            streams,
            writer,
            stop=stop,
            duration_s=duration_s,
            on_piece=show,
            on_first_flush=lambda: click.echo("first samples written", err=True),
        )
        recorder.run()
        recorder.finish()
    for line in summary_lines(streams):
        click.echo(line)
    click.echo(f"wrote {writer.path}")


@click.command(context_settings=CONTEXT)
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--speed", type=click.FloatRange(min=0.01), default=1.0, show_default=True, help="Playback speed.")
@click.option("--start", "start_s", type=click.FloatRange(min=0.0), default=0.0, help="Skip this many s first.")
@click.option("--duration", "duration_s", type=click.FloatRange(min=0.0, min_open=True), help="Send this many s.")
@click.option(
    "--wait-consumers",
    "wait_s",
    type=click.FloatRange(min=0.0),
    default=0.0,
    show_default=True,
    help="Wait up to this many s until a recorder has connected to every outlet before sending.",
)
@click.option("--source-id", default="imulog-replay", show_default=True, help="Prefix of the outlets' source_id.")
def replay(trial: Path, speed: float, start_s: float, duration_s: float | None, wait_s: float, source_id: str) -> None:
    """Publish TRIAL's raw channels as LSL outlets in real time (a recording demonstrated without hardware).

    One outlet per channel, named after it (/imu/wrist -> wrist, type IMU; /markers/vicon -> vicon,
    type MoCap; signals; events as a string stream), with channel labels and units that imulog record
    and LabRecorder + imulog convert map back to the same channels. Ctrl-C stops.

    \b
    Examples:
      imulog replay trial.mcap                              # real time, until the trial ends
      imulog replay trial.mcap --speed 2 --duration 30      # the first 30 s of the trial, twice as fast
      imulog replay trial.mcap --wait-consumers 30          # start once a recorder is connected
    """
    stream_trial(trial, speed=speed, start_s=start_s, duration_s=duration_s, wait_s=wait_s, source_id=source_id)


def stream_trial(
    trial: Path,
    *,
    speed: float = 1.0,
    start_s: float = 0.0,
    duration_s: float | None = None,
    wait_s: float = 0.0,
    source_id: str = "imulog-replay",
) -> None:
    """``imulog replay`` (and ``imulog simulate --lsl``): TRIAL's raw channels as outlets until sent or Ctrl-C."""
    from imulog.archive.errors import ArchiveError
    from imulog.live.lsl import LslError
    from imulog.live.replay import load_plans
    from imulog.live.replay import replay as run_replay

    try:
        plans = load_plans(trial, start_s, duration_s)
    except (ArchiveError, LslError) as exc:
        raise click.ClickException(str(exc)) from None
    stop = threading.Event()
    _stop_on_signals(stop)

    def ready(outlets) -> None:
        for p in plans:
            rate = f"{p.srate:g} Hz" if p.srate else "irregular"
            click.echo(f"outlet {p.name} (type {p.type}, {len(p.labels)} channels, {rate}, {len(p.log_ns)} samples)")

    try:
        sent = run_replay(plans, speed=speed, source_id=source_id, wait_consumers_s=wait_s, stop=stop, on_ready=ready)
    except LslError as exc:
        raise click.ClickException(str(exc)) from None
    click.echo("sent " + ", ".join(f"{name} {n}" for name, n in sent.items()))
