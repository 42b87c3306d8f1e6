"""liblsl's own log lines in ``imulog record``: its "Loaded default config" info line is not printed on every run,
while its errors and a user's own configuration (log level included) are kept (imulog.live.lsl.pylsl)."""

from __future__ import annotations

import os
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

pytest.importorskip("pylsl")

ROOT = Path(__file__).resolve().parents[1]
NOBODY = f"imulog-test-{uuid.uuid4().hex}"


def record_list(tmp_path: Path, **env: str) -> subprocess.CompletedProcess:
    """``imulog record --list`` of a stream name no one publishes, run in ``tmp_path`` with ``tmp_path`` as home
    (no configuration of the user's unless the test writes one there). The name is this run's own: without a
    configuration the command is in liblsl's default session, where another LSL program of the machine may have
    streams, which a plain ``--list`` would find."""
    base = {k: v for k, v in os.environ.items() if k != "LSLAPICFG"}
    base.update(HOME=str(tmp_path), PYTHONPATH=str(ROOT), NO_COLOR="1", **env)
    return subprocess.run(
        [sys.executable, "-m", "imulog", "record", "--list", "--wait", "0.2", "--stream", f"name={NOBODY}"],
        cwd=tmp_path,
        env=base,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.skipif(Path("/etc/lsl_api/lsl_api.cfg").exists(), reason="this machine has a system-wide LSL config")
def test_no_loaded_default_config_line(tmp_path):
    run = record_list(tmp_path)
    assert run.returncode == 1  # nothing to list
    assert f"no LSL stream matches name={NOBODY}" in run.stderr
    assert "Loaded default config" not in run.stderr
    assert "INFO|" not in run.stderr


def test_liblsl_errors_are_kept(tmp_path):
    run = record_list(tmp_path, LSLAPICFG=str(tmp_path / "missing.cfg"))
    assert "LSLAPICFG file" in run.stderr and "not found" in run.stderr  # liblsl's own error line


def test_a_users_config_and_log_level_are_kept(tmp_path):
    (tmp_path / "lsl_api.cfg").write_text("[multicast]\nResolveScope = machine\n[log]\nlevel = 0\n")
    run = record_list(tmp_path)
    assert "Configuration loaded from lsl_api.cfg" in run.stderr  # the user asked for info lines: they stay
