"""The ``imulog`` command line: a thin layer of click commands over the Python API.

Commands live in :mod:`imulog.commands` (one module per area) and are imported lazily, so that
``imulog info`` does not pay for importing Rerun or numba.
"""

from __future__ import annotations

import importlib
import sys

import click

from imulog import __version__

# command name -> "module:attribute" of a click.Command
TOP_LEVEL_COMMANDS: dict[str, str] = {
    "convert": "imulog.commands.convert:convert",
    "info": "imulog.commands.archive:info",
    "doctor": "imulog.commands.archive:doctor",
    "export": "imulog.commands.archive:export",
    "simulate": "imulog.commands.simulate:simulate",
    "calibrate": "imulog.commands.calibrate:calibrate",
    "evaluate": "imulog.commands.trajectory:evaluate",
    "view": "imulog.commands.view:view",
    "demo": "imulog.commands.demo:demo",
}

PROCESS_COMMANDS: dict[str, str] = {
    "calibrate": "imulog.commands.calibrate:process_calibrate",
    "orientation": "imulog.commands.orientation:process_orientation",
    "align": "imulog.commands.align:process_align",
    "phases": "imulog.commands.phases:process_phases",
    "trajectory": "imulog.commands.trajectory:process_trajectory",
    "metrics": "imulog.commands.metrics:process_metrics",
}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported only when used (or listed in --help)."""

    def __init__(self, *args, lazy_commands: dict[str, str] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy_commands = lazy_commands or {}

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.lazy_commands})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self.lazy_commands:
            module_name, attribute = self.lazy_commands[cmd_name].split(":")
            return getattr(importlib.import_module(module_name), attribute)
        return super().get_command(ctx, cmd_name)


@click.group(cls=LazyGroup, lazy_commands=TOP_LEVEL_COMMANDS, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="imulog")
def cli() -> None:
    """imulog: wearable-IMU trials as self-describing MCAP archives.

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
    try:
        cli(standalone_mode=True)
    except KeyboardInterrupt:  # pragma: no cover - interactive only
        click.echo("interrupted", err=True)
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()
