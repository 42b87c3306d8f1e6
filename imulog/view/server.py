"""Serve recordings to Rerun's web viewer bundled in rerun-sdk (no internet needed), bound to one address.

The Python SDK's ``rr.serve_web_viewer`` (rerun-sdk 0.41) always listens on every interface, which exposes a
trial to the whole network. imulog instead runs the ``rerun`` executable that ships inside rerun-sdk
(``rerun_cli``) with ``--serve-web --bind HOST``: it hosts both the web viewer (HTTP) and the gRPC proxy the
recordings are sent to, on ``127.0.0.1`` unless the user asks for another address.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path

LOCALHOST = "127.0.0.1"


class PortInUseError(OSError):
    """A port the web viewer needs is taken by another program."""


@dataclass
class WebServer:
    """Where the viewer is: ``url`` opens the bundled web viewer connected to ``grpc_uri``."""

    url: str
    grpc_uri: str
    web_port: int
    grpc_port: int
    host: str = LOCALHOST
    process: subprocess.Popen | None = field(default=None, repr=False)

    def stop(self, timeout_s: float = 5.0) -> None:
        """End the server process (idempotent)."""
        if self.process is None or self.process.poll() is not None:
            return
        self.process.terminate()
        try:
            self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout_s)


def free_port(host: str = LOCALHOST) -> int:
    """A TCP port that was free a moment ago (for tests and ``--port 0``)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def check_port_free(port: int, host: str = LOCALHOST, what: str = "port") -> None:
    """Raise :class:`PortInUseError` with a one-line hint when ``host:port`` cannot be bound."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind((host, port))
        except OSError as exc:
            raise PortInUseError(
                f"{what} {host}:{port} is in use by another program ({exc.strerror}); "
                "choose another with --port/--grpc-port, or 0 for any free port"
            ) from exc


def _port_open(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.settimeout(0.2)
        return s.connect_ex((LOCALHOST if host in ("0.0.0.0", "::") else host, port)) == 0


def viewer_url(web_port: int, grpc_uri: str, host: str = LOCALHOST) -> str:
    """URL of the bundled web viewer on ``web_port`` that connects to the gRPC server ``grpc_uri``."""
    return f"http://{host}:{web_port}/?url={urllib.parse.quote(grpc_uri, safe='')}"


def grpc_uri(grpc_port: int, host: str = LOCALHOST) -> str:
    """Rerun proxy URI of a gRPC server on ``host:grpc_port``."""
    return f"rerun+http://{host}:{grpc_port}/proxy"


def _die_with_parent() -> None:
    """In the server's child process (Linux): be sent SIGTERM when imulog exits, even when it is killed, so a
    killed ``imulog view --web`` never leaves a server running."""
    import contextlib
    import ctypes
    import signal

    with contextlib.suppress(OSError):
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG


def rerun_executable() -> Path:
    """The ``rerun`` binary shipped inside the rerun-sdk wheel (``RERUN_CLI_PATH`` overrides)."""
    if "RERUN_CLI_PATH" in os.environ:
        return Path(os.environ["RERUN_CLI_PATH"])
    import rerun_cli

    exe = Path(rerun_cli.__file__).parent / ("rerun.exe" if sys.platform.startswith("win") else "rerun")
    if not exe.exists():
        raise FileNotFoundError(f"the rerun viewer binary is missing from rerun-sdk ({exe})")
    return exe


def start_web_server(
    *,
    web_port: int = 9090,
    grpc_port: int = 9876,
    host: str = LOCALHOST,
    memory_limit: str = "25%",
    timeout_s: float = 20.0,
) -> WebServer:
    """Start Rerun's web viewer and gRPC proxy on ``host`` (one process), wait until both listen.

    Ports of 0 pick free ones. Raises :class:`PortInUseError` when a port is taken, ``RuntimeError`` when the
    server does not come up within ``timeout_s``.
    """
    web_port = free_port(host) if web_port == 0 else web_port
    grpc_port = free_port(host) if grpc_port == 0 else grpc_port
    if web_port == grpc_port:
        raise PortInUseError(f"the web port and the gRPC port must differ (both {web_port})")
    check_port_free(web_port, host, "web viewer port")
    check_port_free(grpc_port, host, "gRPC port")
    cmd = [
        str(rerun_executable()),
        "--serve-web",
        "--bind",
        host,
        "--web-viewer-port",
        str(web_port),
        "--port",
        str(grpc_port),
        "--server-memory-limit",
        memory_limit,
        "--hide-welcome-screen",
    ]
    env = {**os.environ, "RERUN_ANALYTICS": "0"}
    log = tempfile.TemporaryFile()  # noqa: SIM115 - lives as long as the server; a pipe could fill and block it
    process = subprocess.Popen(
        cmd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=log,
        env=env,
        preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None,
    )
    deadline = time.monotonic() + timeout_s
    while not (_port_open(host, web_port) and _port_open(host, grpc_port)):
        if process.poll() is not None:
            log.seek(0)
            err = log.read().decode(errors="replace").strip().splitlines()
            raise RuntimeError(f"the Rerun web server exited: {err[-1] if err else 'no message'}")
        if time.monotonic() > deadline:
            process.kill()
            raise RuntimeError(f"the Rerun web server did not start within {timeout_s:.0f} s")
        time.sleep(0.05)
    url_host = LOCALHOST if host in ("0.0.0.0", "::") else host
    uri = grpc_uri(grpc_port, url_host)
    return WebServer(
        url=viewer_url(web_port, uri, url_host),
        grpc_uri=uri,
        web_port=web_port,
        grpc_port=grpc_port,
        host=host,
        process=process,
    )
