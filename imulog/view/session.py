"""Open Rerun recordings for trials, log them, attach the default blueprint, and route them to a sink.

Sinks: an ``.rrd`` file (``save``), a native viewer process (``spawn``) or the bundled web viewer (``web``).
One recording per trial, or one recording holding every trial under ``/{label}`` (``overlay``).
"""

from __future__ import annotations

import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import rerun as rr

from imulog.view import layout as L
from imulog.view.blueprint import build_blueprint
from imulog.view.server import WebServer, serve
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


def show(
    trials: Sequence[TrialData],
    *,
    sink: str,
    save_paths: Sequence[Path] = (),
    overlay: bool = False,
    web_port: int = 9090,
    grpc_port: int = 9876,
    on_trial: Callable[[TrialData], None] | None = None,
) -> ViewResult:
    """Log ``trials`` to ``sink`` (``save``/``spawn``/``web``); ``save_paths``: one per recording for ``save``."""
    groups = [list(trials)] if overlay else [[t] for t in trials]
    names = ["+".join(t.label for t in g) for g in groups]
    result = ViewResult(recordings=[new_recording(n) for n in names])
    if sink == "save":
        if len(save_paths) != len(groups):
            raise ValueError(f"{len(groups)} recording(s) but {len(save_paths)} output path(s)")
        for rec, path in zip(result.recordings, save_paths, strict=True):
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            rec.save(path)
            result.saved.append(Path(path))
    elif sink == "spawn":
        for rec in result.recordings:
            rec.spawn(memory_limit="50%")
    elif sink == "web":
        result.server = serve(result.recordings, web_port=web_port, grpc_port=grpc_port)
    else:
        raise ValueError(f"unknown sink {sink!r}")
    for rec, group in zip(result.recordings, groups, strict=True):
        result.logged.append(log_trials(rec, group, overlay=overlay))
        if on_trial is not None:
            for t in group:
                on_trial(t)
        rec.flush()
    if sink == "save":
        for rec in result.recordings:
            rec.disconnect()
    return result
