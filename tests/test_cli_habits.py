"""Command-line habits: python -m imulog, --json everywhere, NO_COLOR, plain progress in logs, lazy imports."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from imulog.cli import PROCESS_COMMANDS, TOP_LEVEL_COMMANDS, cli
from imulog.console import LineProgress, progress_bar

IMULOG = [sys.executable, "-m", "imulog"]


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NO_COLOR", "DISPLAY")}
    env.update(extra)
    return env


def test_python_dash_m_imulog_is_the_command_line():
    proc = subprocess.run([*IMULOG, "--help"], capture_output=True, text=True, env=_env())
    assert proc.returncode == 0 and proc.stdout.startswith("Usage: imulog ")
    assert "export" in proc.stdout and "doctor" in proc.stdout


_IMPORTS = """
import sys
sys.argv = ["imulog", *sys.argv[1:]]
try:
    from imulog.cli import main
    main()
except SystemExit as exc:
    code = exc.code
MODULES = ("scipy.signal", "pandas", "rerun", "numba", "numpy", "google.protobuf")
print("\\nMODULES", *[m for m in MODULES if m in sys.modules], file=sys.stderr)
"""


@pytest.mark.parametrize("args", [["--help"], ["info", "{trial}"], ["view", "--help"], ["convert", "--help"]])
def test_help_info_and_view_import_only_what_they_use(args, processed_r2g):
    """The processed trial has an imulog.alignment, so `info` prints its summary: still no scipy.signal."""
    argv = [a.format(trial=processed_r2g) for a in args]
    proc = subprocess.run([sys.executable, "-c", _IMPORTS, *argv], capture_output=True, text=True, env=_env())
    assert proc.returncode == 0, proc.stderr
    line = [ln for ln in proc.stderr.splitlines() if ln.startswith("MODULES")][-1]
    loaded = line.split()[1:]
    assert "scipy.signal" not in loaded and "pandas" not in loaded, (args, loaded)
    if args[0] in ("--help", "info", "view"):
        assert "rerun" not in loaded and "numba" not in loaded, (args, loaded)
    if args[0] in ("--help", "info"):  # info reads the summary and metadata records only (imulog._lazy)
        assert "numpy" not in loaded and "google.protobuf" not in loaded, (args, loaded)
    if args[0] == "info":
        assert "alignment" in proc.stdout  # the summary was printed, from the lazily imported step


def test_every_reporting_command_takes_json():
    for name in ("info", "doctor", "export", "convert", "view", "catalog", "evaluate"):
        command = cli.get_command(click.Context(cli), name)
        assert any(p.name == "as_json" or "--json" in getattr(p, "opts", []) for p in command.params), name
    metrics = cli.get_command(click.Context(cli), "process").get_command(click.Context(cli), "metrics")
    assert any("--json" in getattr(p, "opts", []) for p in metrics.params)
    assert {"info", "doctor", "export", "convert", "view", "catalog"} <= set(TOP_LEVEL_COMMANDS)
    assert "metrics" in PROCESS_COMMANDS


def test_json_outputs_parse(processed_r2g, tmp_path):
    runner = CliRunner()
    docs = {}
    for name, args in {
        "info": ["info", str(processed_r2g), "--json"],
        "doctor": ["doctor", str(processed_r2g), "--json"],
        "export": ["export", str(processed_r2g), "-t", "/imu/wrist", "-o", str(tmp_path / "w.parquet"), "--json"],
        "catalog": ["catalog", str(processed_r2g), "-o", str(tmp_path / "c.parquet"), "--json"],
        "convert": ["convert", "recordings/sim/r2g_s00_t00_imu.csv", "-o", str(tmp_path / "c.mcap"), "--json"],
    }.items():
        result = runner.invoke(cli, args)
        assert result.exit_code == 0, (name, result.output)
        docs[name] = json.loads(result.stdout)
    assert docs["doctor"]["ok"] is True and docs["doctor"]["checks"]
    assert docs["export"]["rows"] > 9000 and docs["export"]["clock"] == "device"
    assert docs["catalog"]["rows"] == 1
    assert docs["convert"]["trials"][0]["channels"]["/imu/wrist"] > 9000
    assert any(c["topic"] == "/imu/wrist" for c in docs["info"]["channels"])


def test_view_json_reports_the_saved_file(tmp_path):
    proc = subprocess.run(
        [*IMULOG, "view", "--sample", "5", "--save", str(tmp_path / "s.rrd"), "--json"],
        capture_output=True,
        text=True,
        env=_env(),
    )
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["saved"] == [str(tmp_path / "s.rrd")] and (tmp_path / "s.rrd").stat().st_size > 0


def test_doctor_json_on_a_damaged_file_exits_1(processed_r2g, tmp_path):
    bad = tmp_path / "bad.mcap"
    data = bytearray(processed_r2g.read_bytes())
    data[len(data) // 2] ^= 0xFF
    bad.write_bytes(bytes(data))
    result = CliRunner().invoke(cli, ["doctor", str(bad), "--json"])
    assert result.exit_code == 1
    report = json.loads(result.stdout)
    assert report["ok"] is False and report["problems"]


_COLOR = """
import click
from imulog import cli
cli.cli.add_command(click.Command("paint", callback=lambda: click.secho("red", fg="red")))
cli.main()
"""


@pytest.mark.skipif(sys.platform != "linux", reason="uses a pseudo-terminal")
def test_no_color_is_honoured_on_a_terminal():
    import pty

    def run(env):
        out = b""
        pid, fd = pty.fork()
        if pid == 0:  # child: stdout is the terminal
            os.execve(sys.executable, [sys.executable, "-c", _COLOR, "paint"], env)
        while True:
            try:
                chunk = os.read(fd, 1024)
            except OSError:
                break
            if not chunk:
                break
            out += chunk
        os.waitpid(pid, 0)
        return out

    assert b"\x1b[31m" in run(_env())  # colour on a terminal ...
    assert b"\x1b[" not in run(_env(NO_COLOR="1"))  # ... and none with NO_COLOR


def test_progress_in_a_log_is_plain_lines():
    log = io.StringIO()
    bar = progress_bar(20, "batch", unit="file", file=log)
    assert isinstance(bar, LineProgress)  # a StringIO is not a terminal
    for _ in range(20):
        bar.update(1)
        bar.set_postfix(failed=0)
    bar.close()
    text = log.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert lines[-1] == "batch: 20/20 file (100 %) failed=0" and 9 <= len(lines) <= 11


def test_progress_of_a_few_items_prints_each_count_once():
    """8 files (the study walk's archive): 4 of 8 passes both 40 % and 50 %; `batch: 4/8 file (50 %)` was printed
    twice, in imulog batch and imulog catalog alike."""
    log = io.StringIO()
    bar = progress_bar(8, "batch", unit="file", file=log)
    for _ in range(8):
        bar.update(1)
    bar.close()
    lines = log.getvalue().splitlines()
    assert len(lines) == len(set(lines)) == 8, lines
    assert lines[3] == "batch: 4/8 file (50 %)" and lines[-1] == "batch: 8/8 file (100 %)"


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_long_recordings_step_shows_its_windows_on_a_terminal(tmp_path, monkeypatch):
    """A recording of several windows (an hour each by default; here 60 s) shows a bar per step on a terminal,
    one tick per window; in a log nothing is added (the step's own summary is its output)."""
    import numpy as np

    from imulog.archive import write_trial
    from imulog.model import ImuStream, Recording
    from imulog.steps.orientation import run_orientation
    from imulog.steps.windows import WindowParams

    t = np.arange(9000, dtype=np.int64) * 20_000_000  # 3 minutes at 50 Hz
    rng = np.random.default_rng(0)
    imu = ImuStream(
        "wrist",
        t,
        acc=np.tile([0.0, 0.0, 9.81], (len(t), 1)) + rng.normal(0, 0.05, (len(t), 3)),
        gyr=rng.normal(0, 0.01, (len(t), 3)),
    )
    path = write_trial(tmp_path / "long.mcap", Recording(imus=[imu]))
    windows = WindowParams(core_s=60.0, margin_s=5.0)
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    run_orientation(path, windows=windows)
    assert log.getvalue() == ""
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    run_orientation(path, windows=windows, force=True)
    assert "orientation wrist" in terminal.getvalue() and "3/3" in terminal.getvalue()


def test_catalog_progress_goes_to_the_log_without_carriage_returns(processed_r2g, tmp_path):
    proc = subprocess.run(
        [*IMULOG, "catalog", str(processed_r2g), "-o", str(tmp_path / "c.parquet")],
        capture_output=True,
        text=True,
        env=_env(),
    )
    assert proc.returncode == 0, proc.stderr
    assert "\r" not in proc.stderr and "catalog: 1/1 file (100 %)" in proc.stderr


def test_shell_completion_script():
    proc = subprocess.run(
        [sys.executable, "-m", "imulog"], capture_output=True, text=True, env=_env(_IMULOG_COMPLETE="bash_source")
    )
    assert proc.returncode == 0 and "_imulog_completion" in proc.stdout and "complete " in proc.stdout
    docs = (Path(__file__).resolve().parents[1] / "docs" / "cli.md").read_text()
    assert "_IMULOG_COMPLETE=bash_source imulog" in docs
