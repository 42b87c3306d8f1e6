"""The ``imulog`` command line: a thin layer of click commands over the Python API.

Commands live in :mod:`imulog.commands` (one module per area) and are imported lazily, so that
``imulog info`` does not pay for importing Rerun or numba.
"""

from __future__ import annotations

import importlib
import sys

import click

from imulog import __version__
from imulog.params import ParamError

# command name -> ("module:attribute" of a click.Command, one-line help shown by --help without importing it)
TOP_LEVEL_COMMANDS: dict[str, tuple[str, str]] = {
    "convert": ("imulog.commands.convert:convert", "Convert device exports (IMU text, Vicon CSV, C3D...) to a trial."),
    "info": ("imulog.commands.info:info", "Show a trial's channels, rates, gaps, metadata and derived runs."),
    "doctor": ("imulog.commands.archive:doctor", "Check a trial's integrity: CRCs, summary, decoding, raw hash."),
    "export": (
        "imulog.commands.archive:export",
        "Export to Parquet/CSV, OpenSim .sto/.trc, BIDS-motion or C3D.",
    ),
    "salvage": ("imulog.commands.archive:salvage", "Recover the intact channels of a damaged or truncated trial."),
    "record": ("imulog.commands.record:record", "Record Lab Streaming Layer streams into a crash-safe trial."),
    "replay": ("imulog.commands.record:replay", "Publish a trial's raw channels as live LSL outlets."),
    "simulate": ("imulog.commands.simulate:simulate", "Simulate trials with ground truth in raw export formats."),
    "calibrate": ("imulog.commands.calibrate:calibrate", "Estimate an IMU calibration from static recordings."),
    "evaluate": (
        "imulog.commands.trajectory:evaluate",
        "Compare IMU trajectories (or orientation) with the optical reference.",
    ),
    "view": ("imulog.commands.view:view", "Show trials in Rerun on one synchronized timeline."),
    "demo": ("imulog.commands.demo:demo", "Simulate, convert, process and view a trial in one command."),
    "batch": ("imulog.commands.batch:batch", "Run reprocessing steps over many trials (local or Dask)."),
    "catalog": ("imulog.commands.batch:catalog", "A Parquet catalog, one row per trial: devices, runs, metrics."),
    "report": ("imulog.commands.batch:report", "Accuracy tables and plots (Markdown, CSV, PNG) from a catalog."),
}

PROCESS_COMMANDS: dict[str, tuple[str, str]] = {
    "calibrate": ("imulog.commands.calibrate:process_calibrate", "Apply a calibration file: calibrated IMU channels."),
    "orientation": (
        "imulog.commands.orientation:process_orientation",
        "Sensor orientation and gravity-free acceleration.",
    ),
    "align": ("imulog.commands.align:process_align", "IMU-to-optical (markers or poses) time lag, drift and rotation."),
    "heading": ("imulog.commands.heading:process_heading", "One heading frame for the IMUs of a trial."),
    "phases": ("imulog.commands.phases:process_phases", "Movements, phases, repetitions and static intervals."),
    "trajectory": ("imulog.commands.trajectory:process_trajectory", "Wrist trajectories by integration methods."),
    "metrics": ("imulog.commands.metrics:process_metrics", "Clinical metrics: arm usage, activity, smoothness."),
    "epochs": ("imulog.commands.epochs:process_epochs", "ENMO, MAD, ActiGraph counts, wear per epoch; daily totals."),
    "kinematics": (
        "imulog.commands.kinematics:process_kinematics",
        "Shoulder and elbow angles from two IMUs (DH model).",
    ),
}


#: click's words for a command given several trials or a folder where it takes one trial file
_MANY_TRIALS = ("unexpected extra argument", "is a directory")


class LazyGroup(click.Group):
    """A click group whose subcommands are imported only when used (or listed in --help)."""

    def __init__(self, *args, lazy_commands: dict[str, tuple[str, str]] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy_commands = lazy_commands or {}

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.lazy_commands})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self.lazy_commands:
            module_name, attribute = self.lazy_commands[cmd_name][0].split(":")
            return getattr(importlib.import_module(module_name), attribute)
        return super().get_command(ctx, cmd_name)

    def invoke(self, ctx: click.Context):
        """Run the subcommand; a closed output pipe (raised, or reported by a command as its own error) ends the
        process silently by SIGPIPE, status 141 in a shell, as ``ls`` and ``git`` do (one rule for every command's
        output: ``imulog.console.broken_pipe``, ``imulog.console.exit_closed_pipe``; click alone exits 1)."""
        try:
            return super().invoke(ctx)
        except click.UsageError as exc:  # `process STEP a.mcap b.mcap` or a folder: say which command takes many
            step = exc.ctx.info_name if exc.ctx is not None and exc.ctx.parent is ctx else None
            if self.name == "process" and step and any(k in exc.message for k in _MANY_TRIALS):
                exc.message = exc.message.rstrip(".") + (
                    f"; process {step} runs on one trial: for several trials or a folder, "
                    f"imulog batch PATHS... --steps {step} (docs/batch.md)"
                )
            raise
        except ParamError as exc:  # a parameter object refused a value: the Python API's line, naming the option
            from imulog.commands.option_fields import option_line

            name = ctx.invoked_subcommand
            command = self.get_command(ctx, name) if name else None
            raise click.ClickException(option_line(exc, command)) from None
        except (click.ClickException, OSError) as exc:
            from imulog.console import broken_pipe, exit_closed_pipe

            if broken_pipe(exc) is not None:
                exit_closed_pipe()
            raise

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, self.lazy_commands[name][1]) for name in sorted(self.lazy_commands)]
        rows += [
            (name, command.get_short_help_str(limit=80))
            for name, command in sorted(self.commands.items())
            if name not in self.lazy_commands and not command.hidden
        ]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(sorted(rows))


@click.group(cls=LazyGroup, lazy_commands=TOP_LEVEL_COMMANDS, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="imulog")
def cli() -> None:
    """imulog: wearable-IMU trials as self-describing MCAP archives.

    Reports take --json; NO_COLOR=1 turns colour off; progress bars appear only on a terminal
    (plain lines in logs). Commands that write a file or folder refuse an existing one unless
    --overwrite. Shell completion: eval "$(_IMULOG_COMPLETE=bash_source imulog)"
    (zsh_source, fish_source for those shells; docs/cli.md).

    \b
    Typical session:
      imulog demo                                   # simulate, convert, process, view
      imulog convert wrist.csv vicon.csv -o trial.mcap --meta subject=S01
      imulog info trial.mcap
      imulog process orientation trial.mcap
      imulog view trial.mcap --save trial.rrd
    """


@cli.group(cls=LazyGroup, lazy_commands=PROCESS_COMMANDS)
def process() -> None:
    """Reprocessing steps: append derived channels (with provenance) to a trial.

    Each step reads its inputs from the trial, writes under /derived/..., and records its
    algorithm, parameters and input hashes. Running a step twice with the same inputs and
    parameters changes nothing; other parameters replace the step's own derived channels.
    """


def main() -> None:
    """The ``imulog`` script and ``python -m imulog``; honours ``NO_COLOR`` (no ANSI colour at all)."""
    from imulog.console import no_color

    try:
        cli.main(prog_name="imulog", standalone_mode=True, color=False if no_color() else None)
    except KeyboardInterrupt:  # pragma: no cover - interactive only
        click.echo("interrupted", err=True)
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()
