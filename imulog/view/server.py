"""Serve recordings to Rerun's web viewer bundled in rerun-sdk (no internet needed)."""

from __future__ import annotations

import socket
import urllib.parse
from dataclasses import dataclass

import rerun as rr


@dataclass(frozen=True)
class WebServer:
    """Where the viewer is: ``url`` opens the bundled web viewer connected to ``grpc_uri``."""

    url: str
    grpc_uri: str
    web_port: int
    grpc_port: int


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago (for tests and ``--port 0``)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def viewer_url(web_port: int, grpc_uri: str, host: str = "127.0.0.1") -> str:
    """URL of the bundled web viewer on ``web_port`` that connects to the gRPC server ``grpc_uri``."""
    return f"http://{host}:{web_port}/?url={urllib.parse.quote(grpc_uri, safe='')}"


def serve(
    recordings: list[rr.RecordingStream],
    *,
    web_port: int = 9090,
    grpc_port: int = 9876,
    memory_limit: str = "25%",
) -> WebServer:
    """Host one gRPC server fed by all ``recordings`` plus the web viewer; returns immediately.

    Call before logging. The servers live as long as this process (and the recordings) do.
    """
    if web_port == 0:
        web_port = free_port()
    if grpc_port == 0:
        grpc_port = free_port()
    first, *others = recordings
    uri = first.serve_grpc(grpc_port=grpc_port, server_memory_limit=memory_limit)
    for rec in others:
        rec.connect_grpc(uri)
    rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=uri)
    return WebServer(url=viewer_url(web_port, uri), grpc_uri=uri, web_port=web_port, grpc_port=grpc_port)
