"""``imulog view``: show trials in Rerun (file, native viewer or bundled web viewer)."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import click

from imulog.commands.outputs import overwrite_option, refuse_existing


def has_display() -> bool:
    """True when a native viewer window can open (X11/Wayland, macOS, Windows)."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _save_paths(files: list[Path], save: Path | None, overlay: bool, n_groups: int) -> list[Path]:
    if save is None:  # next to the inputs
        if overlay or not files:
            base = files[0] if files else Path("sample.mcap")
            return [base.with_name(base.stem + ("_overlay" if len(files) > 1 else "") + ".rrd")]
        return [f.with_suffix(".rrd") for f in files]
    if n_groups == 1 and save.suffix == ".rrd":
        return [save]
    if save.suffix == ".rrd":
        raise click.ClickException(
            f"--save {save}: {n_groups} trials make {n_groups} recordings; give a directory or use --overlay"
        )
    return [save / (f.stem + ".rrd") for f in files]


@click.command("view")
@click.argument("files", nargs=-1, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--save", "save", type=click.Path(path_type=Path), help="Write .rrd file(s) (a directory for several trials)."
)
@click.option("--spawn", is_flag=True, help="Open the native Rerun viewer (needs a display); combines with --save.")
@click.option(
    "--web", is_flag=True, help="Serve Rerun's bundled web viewer on localhost, print its URL; combines with --save."
)
@click.option("--port", default=9090, show_default=True, help="Web viewer HTTP port for --web (0 = any free port).")
@click.option("--grpc-port", default=9876, show_default=True, help="Data (gRPC) port for --web (0 = any free port).")
@click.option(
    "--bind",
    default="127.0.0.1",
    show_default=True,
    help="Address the --web servers listen on; 0.0.0.0 shares the trial with your whole network.",
)
@click.option("--overlay", is_flag=True, help="Put all FILES in one recording, each under /<trial name>.")
@click.option(
    "--sample",
    "sample_s",
    type=float,
    default=None,
    metavar="SECONDS",
    help="View a built-in analytic sample trial of this length instead of (or besides) FILES.",
)
@click.option(
    "--start",
    "start_s",
    type=float,
    default=None,
    metavar="SECONDS",
    help="Full resolution from here (seconds from the trial's start on the viewer's timeline); the rest as an overview.",
)
@click.option("--end", "end_s", type=float, default=None, metavar="SECONDS", help="End of the full-resolution window.")
@click.option(
    "--full-resolution/--overview",
    "full_resolution",
    default=None,
    help="Force every sample (memory grows with length) or the min/max overview. Default: overview for trials "
    "longer than 2 h or when --start/--end is given.",
)
@click.option(
    "--serve-seconds",
    type=float,
    default=None,
    metavar="S",
    help="With --web: stop serving after S seconds (default: until Ctrl-C).",
)
@overwrite_option("Replace existing .rrd file(s) (without it, an existing .rrd is refused).")
@click.option("--json", "as_json", is_flag=True, help="Print what was made (saved files, web URL, warnings) as JSON.")
def view(
    files: tuple[Path, ...],
    save: Path | None,
    spawn: bool,
    web: bool,
    port: int,
    grpc_port: int,
    bind: str,
    overlay: bool,
    sample_s: float | None,
    start_s: float | None,
    end_s: float | None,
    full_resolution: bool | None,
    serve_seconds: float | None,
    overwrite: bool = False,
    as_json: bool = False,
) -> None:
    """Show trials in Rerun: IMU, Vicon and every derived channel on one reference-clock timeline.

    Each channel is logged columnarly on the `reference_time` timeline (IMU clocks mapped with the trial's
    `imulog.alignment`), with a default layout: |ω| of the IMU gyroscope over the Vicon angular velocity,
    acceleration, orientation, a state timeline of phases and static intervals, a 3D view of markers,
    cluster frame and trajectories with a cursor at the current time, and the evaluation errors.

    \b
    Examples:
      imulog view trial.mcap                      # native viewer, or trial.rrd when there is no display
      imulog view trial.mcap --save trial.rrd     # then: rerun trial.rrd (--overwrite to replace it)
      imulog view trial.mcap --web --port 9090    # open the printed URL in a browser (works offline)
      imulog view trial.mcap --save t.rrd --spawn # keep a file and look at it now
      imulog view a.mcap b.mcap --save out/       # one recording per trial: out/a.rrd, out/b.rrd
      imulog view zupt.mcap ekf.mcap --overlay    # compare two processings of one trial in the same views
      imulog view --sample 60 --web               # a built-in analytic trial, no file needed
      imulog view week.mcap --save week.rrd       # > 2 h: min/max overview, small .rrd, bounded memory
      imulog view week.mcap --start 3600 --end 4200 --save hour2.rrd   # full resolution in that window
    """
    from imulog.view.overview import OverviewParams, read_trial_overview
    from imulog.view.session import show
    from imulog.view.source import TrialData, from_recording, open_trial

    if start_s is not None and end_s is not None and end_s <= start_s:
        raise click.UsageError(f"--end ({end_s:g} s) must be after --start ({start_s:g} s)")
    overview = OverviewParams(
        start_s=start_s,
        end_s=end_s,
        full_resolution_max_s=0.0 if full_resolution is False else OverviewParams.full_resolution_max_s,
    )

    if spawn and web:
        raise click.UsageError("choose one of --spawn and --web (each may be combined with --save)")
    if not files and sample_s is None:
        raise click.UsageError("give at least one FILE (or --sample SECONDS)")
    sinks = [name for name, on in (("save", save is not None), ("spawn", spawn), ("web", web)) if on]
    if not sinks:
        sinks = ["spawn"] if has_display() else ["save"]
    if "spawn" in sinks and not has_display():
        raise click.ClickException("--spawn needs a display ($DISPLAY is not set); use --web or --save")

    # the outputs are checked before any trial is read (a week's overview takes a while): docs/cli.md
    n_groups = 1 if overlay else len(files) + (sample_s is not None)
    paths: list[Path] = []
    if "save" in sinks:
        paths = _save_paths(list(files), save, overlay, n_groups)
        if len(paths) < n_groups:  # --sample besides files
            paths.append((paths[0].parent if paths else Path(".")) / "sample.rrd")
        refuse_existing(paths, overwrite=overwrite)
        if save is None:
            click.echo(
                "no display found and no --save/--web given: saving "
                + ", ".join(str(p) for p in paths)
                + " (open with `rerun FILE.rrd`, or use --web)",
                err=True,
            )

    trials: list[TrialData] = []
    with click.progressbar(list(files), label="reading trials", file=sys.stderr, hidden=not files) as bar:
        for f in bar:
            try:
                # each channel is read when the viewer reaches it, so Rerun encodes one while the next is read
                if full_resolution:
                    trials.append(open_trial(f))
                else:
                    data, reduced = read_trial_overview(f, overview, lazy=True)
                    if reduced:
                        click.echo(
                            f"{f}: long recording shown as a min/max overview ({overview.buckets} buckets per channel)"
                            + (
                                f", full resolution from {start_s or 0:g} s to {'the end' if end_s is None else f'{end_s:g} s'}"
                                if overview.has_window
                                else "; use --start/--end for full resolution in a window"
                            ),
                            err=True,
                        )
                    trials.append(data)
            except ImportError as exc:
                raise click.ClickException(f"{f}: cannot read archives ({exc})") from exc
            except Exception as exc:
                message = str(exc)
                raise click.ClickException(message if message.startswith(str(f)) else f"{f}: {message}") from exc
    if sample_s is not None:
        from imulog.view.sample import SampleTrialParams, sample_recording

        trials.append(from_recording(sample_recording(SampleTrialParams(duration_s=sample_s)), "sample"))

    from imulog.archive.errors import ArchiveError
    from imulog.view.server import PortInUseError

    try:
        result = show(
            trials, sink=sinks, save_paths=paths, overlay=overlay, web_port=port, grpc_port=grpc_port, bind=bind
        )
    except PortInUseError as exc:
        raise click.ClickException(str(exc)) from exc
    except ArchiveError as exc:  # a channel read while logging was damaged: show() removed the partial .rrd files
        raise click.ClickException(str(exc)) from exc  # the reader's messages start with the file's path
    except (OSError, RuntimeError, ValueError) as exc:
        raise click.ClickException(f"cannot open the Rerun sink(s) {', '.join(sinks)}: {exc}") from exc
    warnings = []
    for logged in result.logged:
        for trial in logged:
            markers = any(e.topic.startswith("/markers/") for e in trial.entities)
            if trial.unaligned_imus and markers:  # IMU-only trials have nothing to align with: no warning
                warnings.append(
                    f"{trial.label}: no imulog.alignment for IMU(s) {', '.join(trial.unaligned_imus)}; "
                    "shown on their device clock (run `imulog process align` first)"
                )
                click.echo(f"warning: {warnings[-1]}", err=True)
    if as_json:
        import json

        url = result.server.url if "web" in sinks and result.server is not None else None
        report = {"sinks": sinks, "saved": [str(p) for p in result.saved], "url": url, "warnings": warnings}
        click.echo(json.dumps(report, indent=2))
        sys.stdout.flush()
    for p in [] if as_json else result.saved:
        click.echo(f"saved {p}")
    if "spawn" in sinks and not as_json:
        click.echo("sent to the Rerun viewer")
    if "web" in sinks:
        assert result.server is not None
        if not as_json:
            click.echo(f"Rerun web viewer: {result.server.url}", err=False)
        click.echo("serving; press Ctrl-C to stop", err=True)
        sys.stdout.flush()
        deadline = None if serve_seconds is None else time.monotonic() + serve_seconds
        try:
            while deadline is None or time.monotonic() < deadline:
                time.sleep(0.2)
        except KeyboardInterrupt:
            pass
        finally:
            for rec in result.recordings:
                rec.disconnect()
            result.server.stop()
