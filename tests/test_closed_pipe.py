"""A reader that closes the pipe early (``imulog evaluate walk.mcap | head -1``): every command ends as ``ls`` and
``git`` do, silently and killed by SIGPIPE (141 in a shell; before, click's exit status 1), instead of printing
``Error: ...: [Errno 32] Broken pipe`` (a command's ``except OSError`` around its output caught the closed pipe;
imulog.cli.LazyGroup.invoke, imulog.console.broken_pipe and exit_closed_pipe). Run on the real gaitmap walking trial
of ../shared/data, whose strides table is the output the audit saw break."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import click
import pytest
from click.testing import CliRunner

from imulog.cli import cli
from imulog.console import broken_pipe


def run_into_closed_pipe(*args) -> tuple[int, str]:
    """``python -m imulog ARGS`` with its stdout a pipe whose reader is already gone; (exit code, stderr)."""
    r, w = os.pipe()
    os.close(r)
    try:
        done = subprocess.run(
            [sys.executable, "-m", "imulog", *map(str, args)], stdout=w, stderr=subprocess.PIPE, text=True, check=False
        )
    finally:
        os.close(w)
    return done.returncode, done.stderr


@pytest.fixture(scope="module")
def walk(shared_data, tmp_path_factory):
    root = shared_data / "gaitmap_foot"
    path = tmp_path_factory.mktemp("pipe") / "walk.mcap"
    runner = CliRunner()
    assert (
        runner.invoke(
            cli, ["convert", str(root / "imu_sample.csv"), str(root / "mocap_sample.csv"), "-o", str(path)]
        ).exit_code
        == 0
    )
    assert runner.invoke(cli, ["process", "align", str(path), "--no-resample"]).exit_code == 0
    return path


@pytest.mark.parametrize("extra", [[], ["--json"]])
def test_the_strides_output_into_a_closed_pipe_is_quiet(walk, extra):
    code, err = run_into_closed_pipe("evaluate", walk, *extra)
    assert err == ""
    assert code == -signal.SIGPIPE  # as `ls | head`: 141 in a shell; the evaluation itself was done and recorded
    result = CliRunner().invoke(cli, ["evaluate", str(walk)])
    assert result.exit_code == 0 and "per stride" in result.output, result.output


def test_other_commands_into_a_closed_pipe_are_quiet(walk):
    for args in (["info", walk], ["info", walk, "--json"], ["process", "align", walk, "--no-resample"]):
        code, err = run_into_closed_pipe(*args)
        assert code == -signal.SIGPIPE and err == "", (args, code, err)


def test_a_closed_pipe_in_a_shell_is_status_141(walk):
    """What a shell script sees (``${PIPESTATUS[0]}`` of ``imulog info | ...`` whose reader has gone): 141, the
    status of ``ls`` and ``git`` there (before: 1), and nothing on stderr."""
    # the reader (`true`) is gone a second before imulog starts writing
    script = 'exec 3>&1; { sleep 1; "$0" -m imulog info "$1" 2>&3; echo "status $?" >&3; } | true'
    done = subprocess.run(["bash", "-c", script, sys.executable, str(walk)], capture_output=True, text=True)
    assert done.stdout == "status 141\n" and done.stderr == "", (done.stdout, done.stderr)


def test_a_real_file_error_is_still_reported():
    """Only a closed pipe is hidden: an OSError of a file stays the command's one-line error."""
    try:
        try:
            raise FileNotFoundError(2, "No such file or directory", "x.mcap")
        except OSError as exc:
            raise click.ClickException(f"x.mcap: {exc}") from None
    except click.ClickException as exc:
        assert broken_pipe(exc) is None
    try:
        try:
            raise BrokenPipeError(32, "Broken pipe")
        except OSError as exc:
            raise click.ClickException(f"x.mcap: {exc}") from None
    except click.ClickException as exc:
        assert isinstance(broken_pipe(exc), BrokenPipeError)
