"""`imulog view --web`: the servers listen on localhost only unless asked, and a busy port is a clear error."""

from __future__ import annotations

import socket
import subprocess
import sys
import urllib.request

import pytest
from click.testing import CliRunner
from procs import start

from imulog.cli import cli
from imulog.view.server import PortInUseError, free_port, start_web_server


def _listening_addresses(port: int) -> set[str]:
    """Local addresses with a TCP listener on ``port`` (from the kernel's socket table)."""
    out = subprocess.run(["ss", "-ltnH", f"sport = :{port}"], capture_output=True, text=True, check=True).stdout
    return {line.split()[3].rsplit(":", 1)[0] for line in out.splitlines() if line.strip()}


@pytest.mark.skipif(sys.platform != "linux", reason="reads the Linux socket table with ss")
def test_web_server_binds_localhost_only():
    server = start_web_server(web_port=0, grpc_port=0)
    try:
        assert _listening_addresses(server.web_port) == {"127.0.0.1"}
        assert _listening_addresses(server.grpc_port) == {"127.0.0.1"}
        with urllib.request.urlopen(server.url, timeout=10) as response:  # the bundled viewer answers
            assert response.status == 200
    finally:
        server.stop()
    assert server.process is not None and server.process.poll() is not None


def test_busy_port_is_a_one_line_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        with pytest.raises(PortInUseError, match=f"127.0.0.1:{port} is in use"):
            start_web_server(web_port=port, grpc_port=free_port())
        result = CliRunner().invoke(cli, ["view", "--sample", "2", "--web", "--port", str(port), "--grpc-port", "0"])
    assert result.exit_code != 0
    message = result.output.strip().splitlines()
    assert message[-1].startswith("Error: web viewer port") and "--port" in message[-1], result.output
    assert "Traceback" not in result.output


@pytest.mark.skipif(sys.platform != "linux", reason="PR_SET_PDEATHSIG is Linux's")
def test_killed_viewer_leaves_no_server(tmp_path):
    """SIGKILL of `imulog view --web` (a timeout, a closed terminal) takes its Rerun server with it."""
    import os
    import signal
    import time

    web, grpc = free_port(), free_port()
    proc = start(
        [
            sys.executable,
            "-m",
            "imulog",
            "view",
            "--sample",
            "2",
            "--web",
            "--port",
            str(web),
            "--grpc-port",
            str(grpc),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        cwd=tmp_path,
    )
    try:
        line = proc.stdout.readline()
        assert line.startswith("Rerun web viewer:"), line
        assert _listening_addresses(web)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    deadline = time.monotonic() + 10
    while _listening_addresses(web) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _listening_addresses(web) and not _listening_addresses(grpc)
