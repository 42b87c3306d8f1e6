"""Open Rerun recordings for trials, log them, attach the default blueprint, and route them to a sink.

Sinks: an ``.rrd`` file (``save``), a native viewer process (``spawn``) or the bundled web viewer (``web``).
One recording per trial, or one recording holding every trial under ``/{label}`` (``overlay``).
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import rerun as rr

from imulog.view import layout as L
from imulog.view.blueprint import build_blueprint
from imulog.view.server import LOCALHOST, WebServer, grpc_uri, start_web_server
from imulog.view.source import TrialData
from imulog.view.streams import LoggedTrial, log_streams

APP_ID = "imulog"


@dataclass
class ViewResult:
    """What was shown: per recording the logged trials, the files written, the web server."""

    recordings: list[rr.RecordingStream] = field(default_factory=list)
    logged: list[list[LoggedTrial]] = field(default_factory=list)
    saved: list[Path] = field(default_factory=list)
    server: WebServer | None = None


def new_recording(name: str) -> rr.RecordingStream:
    """A fresh recording of the ``imulog`` application named ``name``."""
    rec = rr.RecordingStream(APP_ID, recording_id=uuid.uuid4())
    rec.send_recording_name(name)
    return rec


def _unique_labels(trials: Sequence[TrialData]) -> list[str]:
    labels: list[str] = []
    for t in trials:
        label, k = L.slug(t.label), 2
        while label in labels:
            label, k = f"{L.slug(t.label)}_{k}", k + 1
        labels.append(label)
    return labels


def log_trials(rec: rr.RecordingStream, trials: Sequence[TrialData], *, overlay: bool) -> list[LoggedTrial]:
    """Log ``trials`` into ``rec`` (under ``/{label}`` each when ``overlay``) and send the blueprint."""
    logged: list[LoggedTrial] = []
    colours_used = 0
    for trial, label in zip(trials, _unique_labels(trials), strict=True):
        result = log_streams(
            trial.streams,
            trial.metadata,
            recording=rec,
            label=label if overlay else trial.label,
            prefix=f"/{label}" if overlay else "",
            channel_meta=trial.channel_meta,
            color_offset=colours_used,
        )
        colours_used += sum(1 for e in result.by_role("cursor") if e.topic != L.CLUSTER_POSE_TOPIC)
        logged.append(result)
    rec.send_blueprint(build_blueprint(logged), make_active=True, make_default=True)
    return logged


def _discard(result: ViewResult) -> None:
    """Close the recordings, remove the ``.rrd`` files they were writing and stop the web server."""
    for rec in result.recordings:
        rec.disconnect()
    for path in result.saved:
        path.unlink(missing_ok=True)
    if result.server is not None:
        result.server.stop()


def show(
    trials: Sequence[TrialData],
    *,
    sink: str | Sequence[str],
    save_paths: Sequence[Path] = (),
    overlay: bool = False,
    web_port: int = 9090,
    grpc_port: int = 9876,
    spawn_port: int = 9876,
    bind: str = LOCALHOST,
) -> ViewResult:
    """Log ``trials`` to one or several sinks: ``save`` (``save_paths``, one per recording), ``spawn``, ``web``.

    One recording per trial, or one for all when ``overlay``. ``web`` starts Rerun's web viewer and gRPC proxy
    bound to ``bind`` (127.0.0.1 unless asked); stop it with ``result.server.stop()``. Trials from
    :func:`imulog.view.source.open_trial` are read while they are logged; if reading fails, the error is raised
    after the server is stopped and the ``.rrd`` files being written are removed.
    """
    sinks = {sink} if isinstance(sink, str) else set(sink)
    unknown = sinks - {"save", "spawn", "web"}
    if unknown or not sinks:
        raise ValueError(f"unknown sink(s) {sorted(unknown)}; use save, spawn and/or web")
    if "spawn" in sinks and "web" in sinks and spawn_port == grpc_port:
        raise ValueError("--spawn and --web need different gRPC ports")
    groups = [list(trials)] if overlay else [[t] for t in trials]
    names = ["+".join(t.label for t in g) for g in groups]
    result = ViewResult(recordings=[new_recording(n) for n in names])
    per_rec: list[list] = [[] for _ in groups]
    if "save" in sinks:
        if len(save_paths) != len(groups):
            raise ValueError(f"{len(groups)} recording(s) but {len(save_paths)} output path(s)")
        for sinks_of, path in zip(per_rec, save_paths, strict=True):
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            sinks_of.append(rr.FileSink(Path(path)))
            result.saved.append(Path(path))
    if "web" in sinks:
        result.server = start_web_server(web_port=web_port, grpc_port=grpc_port, host=bind)
        for sinks_of in per_rec:
            sinks_of.append(rr.GrpcSink(result.server.grpc_uri))
    if "spawn" in sinks:
        rr.spawn(port=spawn_port, connect=False, memory_limit="50%")
        for sinks_of in per_rec:
            sinks_of.append(rr.GrpcSink(grpc_uri(spawn_port)))
    for rec, sinks_of in zip(result.recordings, per_rec, strict=True):
        rec.set_sinks(*sinks_of)
    try:
        for rec, group in zip(result.recordings, groups, strict=True):
            result.logged.append(log_trials(rec, group, overlay=overlay))
            rec.flush()
    except BaseException:  # e.g. a damaged chunk reached while reading (open_trial): no partial .rrd is left
        _discard(result)
        raise
    if sinks == {"save"}:
        for rec in result.recordings:
            rec.disconnect()
    return result
