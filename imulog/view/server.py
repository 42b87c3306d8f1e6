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


def grpc_uri(grpc_port: int, host: str = "127.0.0.1") -> str:
    """Rerun proxy URI of a gRPC server on ``host:grpc_port``."""
    return f"rerun+http://{host}:{grpc_port}/proxy"


def server_sinks(
    count: int, *, grpc_port: int = 9876, memory_limit: str = "25%"
) -> tuple[list[rr.GrpcServerSink | rr.GrpcSink], str, int]:
    """Sinks for ``count`` recordings sharing one gRPC server bound to 127.0.0.1 (the first hosts it).

    Returns (sinks, server URI, port). Pass the sinks to ``RecordingStream.set_sinks`` before logging.
    """
    if grpc_port == 0:
        grpc_port = free_port()
    uri = grpc_uri(grpc_port)
    host = rr.GrpcServerSink(bind_ip="127.0.0.1", port=grpc_port, server_memory_limit=memory_limit)
    return [host, *[rr.GrpcSink(uri) for _ in range(count - 1)]], uri, grpc_port


def serve_viewer(uri: str, grpc_port: int, web_port: int = 9090) -> WebServer:
    """Host the bundled web viewer (HTTP on 127.0.0.1-reachable ``web_port``) connected to ``uri``."""
    if web_port == 0:
        web_port = free_port()
    rr.serve_web_viewer(web_port=web_port, open_browser=False, connect_to=uri)
    return WebServer(url=viewer_url(web_port, uri), grpc_uri=uri, web_port=web_port, grpc_port=grpc_port)
