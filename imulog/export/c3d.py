"""C3D export (ezc3d): markers as points, IMU and analog channels as analogs, phases and events as events.

One C3D file has one frame clock, with ``ANALOG:RATE`` a whole multiple of ``POINT:RATE``
(:mod:`imulog.export.c3d_grid`). The fastest analog channel (``/analog/*`` or ``/imu/*``) is written
sample for sample: when its rate is a whole multiple of the marker rate the points keep their rate and
samples; otherwise the frames follow the analog channel and the points are interpolated linearly onto
them (a note says so; NaN across gaps). Other analog channels at the same rate are copied sample for
sample, slower ones interpolated (noted). IMU columns: ``{imu}_acc_x`` m/s^2, ``{imu}_gyr_x`` rad/s,
``{imu}_mag_x`` uT. All channels are first put on the chosen clock (default ``reference``).

Points are in mm (``POINT:UNITS = mm``, float storage, ``POINT:SCALE = -1``); a missing or invalid point
has residual -1, the C3D standard's "invalid" that Nexus, Visual3D, Mokka and btk test. Valid points have
residual 0, or the source's residual and camera mask when the markers came from a C3D file attached to
the trial and were not resampled. Analogs are floats with ``ANALOG:SCALE = 1``, ``OFFSET = 0``,
``GEN_SCALE = 1`` per channel, so every reader's ``(value - offset) * scale * gen_scale`` gives the
sample. Events: every phase and raw event interval gives ``<label>`` at its start and ``<label>_end`` at
its end (context ``General``, description ``repetition <task_index>``), in seconds from the first frame.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from imulog.archive.trial_clock import trial_clock
from imulog.export._atomic import ExportError, atomic_file
from imulog.export.c3d_grid import Grid, interp_gapped, place_on_grid, placed, plan_grid, whole_multiple
from imulog.export.table import ExportResult

if TYPE_CHECKING:
    from imulog.archive.reader import TrialReader

MM_PER_M = 1000.0
C3D_EXTRA = "C3D export needs ezc3d: pip install 'imulog[c3d]'"
__all__ = ["C3dContent", "build_c3d", "export_c3d", "interp_gapped", "place_on_grid", "trial_c3d"]


@dataclass
class C3dContent:
    """Everything a C3D file holds, as arrays (units as written: points in mm)."""

    point_rate_hz: float
    point_labels: list[str]
    points_mm: np.ndarray  # (F, M, 3), NaN = invalid
    residuals: np.ndarray | None = None  # (F, M): -1 invalid (None: -1 where NaN, else 0)
    camera_masks: np.ndarray | None = None  # (7, M, F) bool, as ezc3d holds them
    analog_rate_hz: float = 0.0
    analog_labels: list[str] = field(default_factory=list)
    analog_units: list[str] = field(default_factory=list)
    analog_descriptions: list[str] = field(default_factory=list)  # the source channel of each: "/imu/NAME acc_x"
    analogs: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (F * k, A)
    events: list[tuple[float, str, str]] = field(default_factory=list)  # (time s from frame 1, label, description)


def unique_labels(labels: list[str], descriptions: list[str]) -> list[str]:
    """Analog labels a reader can tell apart: a label several sensors share (two Delsys sensors' ``EMG``) gets its
    source's name in front (``mini_sensor_10_EMG``, from the description ``/analog/mini_sensor_10 EMG``); unique
    labels stay as the source named them."""
    counts: dict[str, int] = {}
    for label in labels:
        counts[label] = counts.get(label, 0) + 1
    return [
        f"{d.split(' ', 1)[0].rsplit('/', 1)[-1]}_{label}" if counts[label] > 1 else label
        for label, d in zip(labels, descriptions, strict=True)
    ]


def _ezc3d():
    try:
        import ezc3d
    except ImportError:  # pragma: no cover - ezc3d is in the c3d extra
        raise ExportError(C3D_EXTRA) from None
    return ezc3d


def build_c3d(content: C3dContent):
    """An ``ezc3d.c3d`` object of ``content`` (not written)."""
    c = _ezc3d().c3d()
    f, m = content.points_mm.shape[:2]
    point = c["parameters"]["POINT"]
    point["RATE"]["value"] = [content.point_rate_hz]
    point["LABELS"]["value"] = list(content.point_labels)
    point["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, m, f))
    pts[:3] = np.transpose(content.points_mm, (2, 1, 0))
    c["data"]["points"] = pts
    invalid = ~np.isfinite(content.points_mm).all(axis=2)  # (F, M)
    res = np.zeros((f, m)) if content.residuals is None else np.asarray(content.residuals, np.float64).copy()
    res[invalid] = -1.0
    res[~invalid & (res < 0)] = 0.0
    masks = np.zeros((7, m, f), bool) if content.camera_masks is None else np.asarray(content.camera_masks, bool)
    masks = masks & ~invalid.T[None]
    c["data"]["meta_points"] = {"residuals": res.T[None], "camera_masks": masks}
    if content.analog_labels:
        a = len(content.analog_labels)
        analog = c["parameters"]["ANALOG"]
        analog["RATE"]["value"] = [content.analog_rate_hz]
        analog["LABELS"]["value"] = list(content.analog_labels)
        analog["UNITS"]["value"] = list(content.analog_units)
        if content.analog_descriptions:
            analog["DESCRIPTIONS"]["value"] = list(content.analog_descriptions)
        analog["SCALE"]["value"] = [1.0] * a
        analog["OFFSET"]["value"] = [0] * a
        analog["GEN_SCALE"]["value"] = [1.0]
        analog["FORMAT"]["value"] = ["SIGNED"]
        analog["BITS"]["value"] = [16]
        c["data"]["analogs"] = content.analogs.T[None, :, :].astype(np.float64)
    for time_s, label, description in content.events:
        minutes = int(time_s // 60)
        c.add_event([minutes, float(time_s - 60 * minutes)], context="General", label=label, description=description)
    return c


def _clock_rate(tc, topic: str, t_ns: np.ndarray, rate_hz: float) -> tuple[float, np.ndarray]:
    """The channel's times on the export clock and its rate there (the clock map's drift applied)."""
    t = np.asarray(tc.times(topic, t_ns), np.int64)
    if len(t_ns) > 1 and int(t_ns[-1]) > int(t_ns[0]):
        rate_hz *= (int(t_ns[-1]) - int(t_ns[0])) / max(int(t[-1]) - int(t[0]), 1)
    return rate_hz, t


def source_meta_points(trial, topic: str, labels: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Residuals (F, M), camera masks (7, M, F) and frame times of the C3D file ``topic`` came from.

    Only when the channel's ``source`` is a ``.c3d`` attachment of the trial and every label is in it.
    """
    source = str(trial.channel(topic).metadata.get("source", ""))
    if not source.lower().endswith(".c3d") or not any(a["name"] == source for a in trial.attachment_infos()):
        return None
    ezc3d = _ezc3d()
    data = next(a.data for a in trial.iter_attachments() if a.name == source)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "source.c3d"
        path.write_bytes(data)
        c = ezc3d.c3d(str(path), extract_forceplat_data=False)
    meta = c["data"].get("meta_points") or {}
    if "residuals" not in meta:
        return None
    src_labels = [str(x).strip() for x in c["parameters"]["POINT"]["LABELS"]["value"]]
    pos = {lab: i for i, lab in reversed(list(enumerate(src_labels)))}
    if any(lab not in pos for lab in labels):
        return None
    cols = [pos[lab] for lab in labels]
    rate = float(c["parameters"]["POINT"]["RATE"]["value"][0])
    first = int(c["header"]["points"]["first_frame"])
    n = c["data"]["points"].shape[2]
    t = np.round((first + np.arange(n)) * (1e9 / rate)).astype(np.int64)
    masks = meta.get("camera_masks")
    masks = np.zeros((7, len(cols), n), bool) if masks is None or masks.shape[1:] != (len(src_labels), n) else masks
    return meta["residuals"][0][cols].T, masks[:, cols, :], t


def _points(trial, tc, topic: str, grid: Grid, notes: list[str]) -> tuple[list[str], np.ndarray, tuple | None]:
    """Marker labels, (F, M, 3) mm on the grid, and the source's residuals/masks placed on it (or None)."""
    mk = trial.read(topic)
    t = np.asarray(tc.times(topic, mk.t_ns), np.int64)
    pos = np.where(mk.valid[:, :, None], mk.pos, np.nan) * MM_PER_M
    m = len(mk.labels)
    if grid.points_resampled:
        src_rate = float(trial.channel(topic).rate_hz or 0.0)
        flat = interp_gapped(t, pos.reshape(len(t), m * 3), grid.point_times(), 1e9 / src_rate)
        notes.append(
            f"points of {topic} interpolated from {src_rate:g} Hz to {grid.point_rate_hz:.6g} Hz "
            f"(C3D needs the analog rate to be a whole multiple of the point rate; analogs kept at their own rate)"
        )
        return list(mk.labels), flat.reshape(grid.frames, m, 3), None
    idx, ok = place_on_grid(t, grid.g0_ns, grid.period_ns, grid.frames)
    points = np.full((grid.frames, m, 3), np.nan)
    points[idx[ok]] = pos[ok]
    meta = None
    src = source_meta_points(trial, topic, list(mk.labels))
    if src is not None:
        res_src, masks_src, t_src = src
        if np.array_equal(np.asarray(tc.times(topic, t_src), np.int64), t):  # every frame of the source, as is
            res = np.zeros((grid.frames, m))
            masks = np.zeros((7, m, grid.frames), bool)
            res[idx[ok]] = res_src[ok]
            masks[:, :, idx[ok]] = masks_src[:, :, ok]
            meta = (res, masks)
    return list(mk.labels), points, meta


def trial_c3d(trial, *, clock: str = "reference", imu: str | None = None, include_imu: bool = True):
    """The :class:`C3dContent` of a trial, and the notes of its clock mapping."""
    tc = trial_clock(trial, clock, imu)
    infos = {c.topic: c for c in trial.channels}
    marker_topics = [t for t in infos if t.startswith("/markers/")]
    imu_topics = [t for t in infos if t.startswith("/imu/") and t.count("/") == 2] if include_imu else []
    analog_topics = [t for t in infos if t.startswith("/analog/")]
    notes: list[str] = []
    if not marker_topics and not imu_topics and not analog_topics:
        raise ExportError(f"{trial.path}: no markers, analogs or IMU channel to put in a C3D file")
    # every analog source on the export clock: (topic, stream, times, rate there)
    sources = []
    for topic in analog_topics + imu_topics:
        stream = trial.read(topic)
        rate = float(infos[topic].rate_hz or 0.0)
        if rate <= 0 or len(stream.t_ns) == 0:
            notes.append(f"{topic} left out: no samples or no rate")
            continue
        rate, t = _clock_rate(tc, topic, stream.t_ns, rate)
        sources.append((topic, stream, t, rate))
    spans = [(int(s[2][0]), int(s[2][-1])) for s in sources]
    marker = None
    if marker_topics:
        base = marker_topics[0]
        if len(marker_topics) > 1:
            notes.append(f"points from {base} only (C3D has one point rate); left out {', '.join(marker_topics[1:])}")
        info = infos[base]
        if not (info.rate_hz and info.sample_count and info.start_ns is not None and info.end_ns is not None):
            raise ExportError(f"{trial.path}: {base} has no samples or no rate")
        t_mk = np.asarray(tc.times(base, np.array([info.start_ns, info.end_ns], np.int64)), np.int64)
        marker = (float(info.rate_hz) * (info.end_ns - info.start_ns) / max(int(t_mk[1] - t_mk[0]), 1), int(t_mk[0]))
        if info.end_ns == info.start_ns:
            marker = (float(info.rate_hz), int(t_mk[0]))
        spans.append((int(t_mk[0]), int(t_mk[1])))
    fastest = max(sources, key=lambda s: s[3]) if sources else None
    span = (min(s[0] for s in spans), max(s[1] for s in spans))
    grid = plan_grid(span, marker, (fastest[3], int(fastest[2][0])) if fastest else None)
    labels: list[str] = []
    points = np.full((grid.frames, 0, 3), np.nan)
    meta = None
    if marker_topics:
        labels, points, meta = _points(trial, tc, marker_topics[0], grid, notes)
    content = C3dContent(point_rate_hz=grid.point_rate_hz, point_labels=labels, points_mm=points)
    if meta is not None:
        content.residuals, content.camera_masks = meta
    n_an = grid.frames * grid.ratio
    span_s = (span[1] - span[0]) / 1e9
    columns: list[np.ndarray] = []
    for topic, stream, t, rate in sources:
        name = topic.rsplit("/", 1)[1]
        as_is = whole_multiple(rate, grid.analog_rate_hz, span_s) == 1
        if not as_is:
            notes.append(
                f"{topic} interpolated from {rate:.6g} Hz to the analog rate {grid.analog_rate_hz:.6g} Hz "
                "(C3D has one analog rate)"
            )

        def take(v, t=t, rate=rate, as_is=as_is):
            if as_is:
                return placed(t, v, grid.g0_ns, grid.analog_period_ns, n_an)
            return interp_gapped(t, v, grid.analog_times(), 1e9 / rate)

        if topic.startswith("/analog/"):
            units = stream.units
            units = list(units) if isinstance(units, list | tuple) else [str(units)] * len(stream.channel_names)
            content.analog_labels += list(stream.channel_names)
            content.analog_descriptions += [f"{topic} {c}" for c in stream.channel_names]
            content.analog_units += units
            columns.append(take(stream.values))
            continue
        for group, unit in (("acc", "m/s^2"), ("gyr", "rad/s"), ("mag", "uT")):
            arr = getattr(stream, group)
            if arr is None:
                continue
            columns.append(take(arr))
            content.analog_labels += [f"{name}_{group}_{a}" for a in "xyz"]
            content.analog_descriptions += [f"{topic} {group}_{a}" for a in "xyz"]
            content.analog_units += [unit] * 3
    content.analog_labels = unique_labels(content.analog_labels, content.analog_descriptions)
    if columns:
        content.analogs = np.concatenate(columns, axis=1)
        content.analog_rate_hz = grid.analog_rate_hz
    for topic in [t for t in infos if t.startswith("/derived/phases/") or t.startswith("/events/")]:
        iv = trial.read(topic)
        for a, b, label, task in zip(
            tc.times(topic, iv.start_ns), tc.times(topic, iv.end_ns), iv.labels, iv.task_index, strict=True
        ):
            desc = f"repetition {int(task)}" if int(task) > 0 else topic
            content.events.append(((int(a) - grid.g0_ns) / 1e9, str(label), desc))
            content.events.append(((int(b) - grid.g0_ns) / 1e9, f"{label}_end", desc))
    return content, notes + tc.export_notes()


def export_c3d(
    trial: TrialReader, out: str | Path, *, clock: str = "reference", imu: str | None = None, include_imu: bool = True
) -> ExportResult:
    """Write the trial as a C3D file (atomically)."""
    content, notes = trial_c3d(trial, clock=clock, imu=imu, include_imu=include_imu)
    c = build_c3d(content)
    with atomic_file(out) as tmp:
        c.write(str(tmp.with_suffix(".c3d")))
        tmp.with_suffix(".c3d").replace(tmp)
    return ExportResult(
        path=str(out),
        format="c3d",
        clock=clock,
        rows=content.points_mm.shape[0],
        columns=content.point_labels + content.analog_labels,
        topics=[],
        files=[str(out)],
        notes=notes,
    )
