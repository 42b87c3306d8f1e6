"""OpenSim marker files (``.trc``, PathFileType 4): one marker channel, positions in mm, one row per frame.

Layout (as OpenSim and Motion Analysis write it; ``../shared/data/devices/opensim_trc/markers.trc`` is one)::

    PathFileType<TAB>4<TAB>(X/Y/Z)<TAB>NAME.trc
    DataRate<TAB>CameraRate<TAB>NumFrames<TAB>NumMarkers<TAB>Units<TAB>OrigDataRate<TAB>OrigDataStartFrame<TAB>OrigNumFrames
    100<TAB>100<TAB>652<TAB>51<TAB>mm<TAB>100<TAB>1<TAB>652
    Frame#<TAB>Time<TAB>M1<TAB><TAB><TAB>M2 ...
    <TAB><TAB>X1<TAB>Y1<TAB>Z1<TAB>X2 ...
    (a blank line)
    1<TAB>0.000000<TAB>...

Occluded samples are empty cells (OpenSim reads them as NaN). The markers keep the trial's labels (a ``Subject:``
prefix included), so they match the optical system's own names in an OpenSim marker set. Times are seconds from
the trial's origin on the export clock: by default the markers' own (``reference``); ``device`` maps them onto an
IMU's clock through its alignment. Positions in the optical system's world frame (z up for a Vicon); OpenSim's
y-up ground needs its usual rotation.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from imulog.archive.trial_clock import seconds_from, trial_clock
from imulog.export._atomic import ExportError, atomic_file
from imulog.export.table import ExportResult

if TYPE_CHECKING:
    from imulog.archive.reader import TrialReader

MM_PER_M = 1000.0


def format_trc(name: str, time_s: np.ndarray, labels: Sequence[str], pos_mm: np.ndarray, rate_hz: float) -> str:
    """The text of a ``.trc`` file: ``time_s`` (N,), ``pos_mm`` (N, M, 3) in mm (NaN: occluded, an empty cell)."""
    pos = np.asarray(pos_mm, dtype=np.float64)
    n, m = len(time_s), len(labels)
    if pos.shape != (n, m, 3):
        raise ValueError(f"positions of shape {pos.shape}, expected {(n, m, 3)}")
    bad = [label for label in labels if "\t" in label or "\n" in label]
    if bad:
        raise ValueError(f"marker name {bad[0]!r} holds a tab or a line break")
    rate = f"{rate_hz:.6f}"
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t{n}\t{m}\tmm\t{rate}\t1\t{n}",
        "\t".join(["Frame#", "Time", *(f"{label}\t\t" for label in labels)]).rstrip("\t"),
        "\t".join(["", "", *(f"X{j}\tY{j}\tZ{j}" for j in range(1, m + 1))]),
        "",
    ]
    cells = np.char.mod("%.6f", pos.reshape(n, m * 3))  # 1 nm: a source's own decimals survive
    cells[~np.isfinite(pos.reshape(n, m * 3))] = ""
    times = np.char.mod("%.6f", np.asarray(time_s, dtype=np.float64))
    for i in range(n):
        lines.append("\t".join([str(i + 1), times[i], *cells[i]]))
    return "\n".join(lines) + "\n"


def marker_topic(trial, topic: str | None) -> str:
    """The marker channel to export: ``topic`` (a ``/markers/*`` channel), else the trial's only one, else
    ``/markers/vicon``; a one-line error naming the channels to choose from otherwise."""
    topics = [t for t in trial.topics() if t.startswith("/markers/")]
    if topic is not None:
        if topic not in topics:
            raise ExportError(f"{trial.path}: trc takes a marker channel, not {topic} (markers: {', '.join(topics)})")
        return topic
    if len(topics) == 1:
        return topics[0]
    if "/markers/vicon" in topics:
        return "/markers/vicon"
    if not topics:
        raise ExportError(f"{trial.path}: no /markers/* channel to write to a .trc file")
    raise ExportError(f"{trial.path}: several marker channels: choose one with --topic ({', '.join(topics)})")


def export_trc(
    trial: TrialReader, out: str | Path, *, topic: str | None = None, clock: str = "reference", imu: str | None = None
) -> ExportResult:
    """Write one marker channel of the trial as an OpenSim ``.trc`` file (see the module docstring)."""
    chosen = marker_topic(trial, topic)
    info = trial.channel(chosen)
    mk = trial.read(chosen)
    if len(mk.t_ns) < 2 or not info.rate_hz:
        raise ExportError(f"{trial.path}: {chosen} has fewer than two frames or no rate")
    tc = trial_clock(trial, clock, imu)
    t = np.asarray(tc.times(chosen, mk.t_ns), dtype=np.int64)
    rate = float(info.rate_hz) * (int(mk.t_ns[-1]) - int(mk.t_ns[0])) / max(int(t[-1]) - int(t[0]), 1)
    pos = np.where(mk.valid[:, :, None], mk.pos, np.nan) * MM_PER_M
    try:
        text = format_trc(Path(out).name, seconds_from(t, tc.origin_ns), list(mk.labels), pos, rate)
    except ValueError as exc:
        raise ExportError(f"{trial.path}: {chosen}: {exc}") from None
    with atomic_file(out) as tmp:
        tmp.write_text(text)
    return ExportResult(
        path=str(out),
        format="trc",
        clock=clock,
        rows=len(t),
        columns=["Frame#", "Time", *mk.labels],
        topics=[chosen],
        files=[str(out)],
        notes=tc.export_notes(),
    )
