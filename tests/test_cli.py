"""The command registry: every advertised command imports, is a click command, and has a teaching --help."""

from __future__ import annotations

import importlib

import click
import pytest
from click.testing import CliRunner

from imulog.cli import PROCESS_COMMANDS, TOP_LEVEL_COMMANDS, cli

ALL_COMMANDS = [(name, spec) for name, spec in TOP_LEVEL_COMMANDS.items()] + [
    (f"process {name}", spec) for name, spec in PROCESS_COMMANDS.items()
]


@pytest.mark.parametrize(("name", "spec"), ALL_COMMANDS, ids=[name for name, _ in ALL_COMMANDS])
def test_registered_command_resolves(name: str, spec: tuple[str, str]) -> None:
    module_name, attribute = spec[0].split(":")
    command = getattr(importlib.import_module(module_name), attribute)
    assert isinstance(command, click.Command), f"{spec[0]} is not a click command"


@pytest.mark.parametrize("name", [name for name, _ in ALL_COMMANDS])
def test_help_teaches(name: str) -> None:
    result = CliRunner().invoke(cli, [*name.split(), "--help"])
    assert result.exit_code == 0, result.output
    assert "Usage: " in result.output
    # --help shows at least one example invocation of the command itself
    assert f"imulog {name}" in result.output, f"'imulog {name} --help' shows no example"


def test_top_level_help_does_not_import_heavy_modules() -> None:
    import subprocess
    import sys

    code = "import sys; from imulog.cli import cli; cli.main(['--help'], standalone_mode=False); print(sorted(m for m in ('rerun', 'numba', 'scipy') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"
