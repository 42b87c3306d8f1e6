"""C3D export (ezc3d): markers as points, IMU and analog channels as analogs, phases and events as events.

One C3D file has one frame clock. Points are the trial's first marker channel, placed on a uniform
grid at its rate (``POINT:UNITS`` = mm, missing samples invalid); analogs run at an integer multiple of
that rate: ``/analog/*`` channels at such a rate are copied sample for sample, IMU channels
(``/imu/*``: ``{imu}_acc_x`` m/s^2, ``{imu}_gyr_x`` rad/s, ``{imu}_mag_x`` uT) are interpolated
linearly onto the analog grid (NaN across gaps longer than 1.5 IMU periods). All channels are first
put on the chosen clock (default ``reference``: the markers' clock, IMU through ``imulog.alignment``).
Without markers the frames are the first IMU's samples at its rate. Events: every phase and raw event
interval gives ``<label>`` at its start and ``<label>_end`` at its end (context ``General``,
description ``repetition <task_index>``), in seconds from the first frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imulog.export._atomic import ExportError, atomic_file
from imulog.export.clock import trial_clock
from imulog.export.table import ExportResult

MM_PER_M = 1000.0


@dataclass
class C3dContent:
    """Everything a C3D file holds, as arrays (units as written: points in mm)."""

    point_rate_hz: float
    point_labels: list[str]
    points_mm: np.ndarray  # (F, M, 3), NaN = invalid
    analog_rate_hz: float = 0.0
    analog_labels: list[str] = field(default_factory=list)
    analog_units: list[str] = field(default_factory=list)
    analogs: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (F * k, A)
    events: list[tuple[float, str, str]] = field(default_factory=list)  # (time s from frame 1, label, description)


def place_on_grid(t_ns: np.ndarray, g0_ns: int, period_ns: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Grid index of each sample (nearest) and which samples fall on the grid [0, n)."""
    idx = np.round((np.asarray(t_ns, np.int64) - g0_ns) / period_ns).astype(np.int64)
    ok = (idx >= 0) & (idx < n)
    return idx, ok


def interp_gapped(t_src_ns: np.ndarray, values: np.ndarray, t_dst_ns: np.ndarray, period_ns: float) -> np.ndarray:
    """Linear interpolation of (N, C) values onto ``t_dst_ns``; NaN outside and across gaps > 1.5 periods."""
    t = np.asarray(t_src_ns, np.int64)
    v = np.asarray(values, np.float64).reshape(len(t), -1)
    out = np.full((len(t_dst_ns), v.shape[1]), np.nan)
    if len(t) < 2:
        return out
    k = np.clip(np.searchsorted(t, t_dst_ns, side="right") - 1, 0, len(t) - 2)
    inside = (t_dst_ns >= t[0]) & (t_dst_ns <= t[-1])
    gap_ok = (t[k + 1] - t[k]) <= 1.5 * period_ns
    frac = ((t_dst_ns - t[k]) / np.maximum(t[k + 1] - t[k], 1))[:, None]
    res = v[k] * (1.0 - frac) + v[k + 1] * frac
    ok = inside & gap_ok
    out[ok] = res[ok]
    j = np.clip(np.searchsorted(t, t_dst_ns), 0, len(t) - 1)
    exact = t[j] == t_dst_ns  # on a sample: its value, also beside a gap
    out[exact] = v[j[exact]]
    return out


def build_c3d(content: C3dContent):
    """An ``ezc3d.c3d`` object of ``content`` (not written)."""
    try:
        import ezc3d
    except ImportError:  # pragma: no cover - ezc3d is in the c3d extra
        raise ExportError("C3D export needs ezc3d: pip install 'imulog[c3d]'") from None
    c = ezc3d.c3d()
    f, m = content.points_mm.shape[:2]
    c["parameters"]["POINT"]["RATE"]["value"] = [content.point_rate_hz]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(content.point_labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, m, f))
    pts[:3] = np.transpose(content.points_mm, (2, 1, 0))
    c["data"]["points"] = pts
    if content.analog_labels:
        c["parameters"]["ANALOG"]["RATE"]["value"] = [content.analog_rate_hz]
        c["parameters"]["ANALOG"]["LABELS"]["value"] = list(content.analog_labels)
        c["parameters"]["ANALOG"]["UNITS"]["value"] = list(content.analog_units)
        c["data"]["analogs"] = content.analogs.T[None, :, :].astype(np.float64)
    for time_s, label, description in content.events:
        minutes = int(time_s // 60)
        c.add_event([minutes, float(time_s - 60 * minutes)], context="General", label=label, description=description)
    return c


def trial_c3d(trial, *, clock: str = "reference", imu: str | None = None, include_imu: bool = True):
    """The :class:`C3dContent` of a trial, and the notes of its clock mapping."""
    tc = trial_clock(trial, clock, imu)
    infos = {c.topic: c for c in trial.channels}
    marker_topics = [t for t in infos if t.startswith("/markers/")]
    imu_topics = [t for t in infos if t.startswith("/imu/") and t.count("/") == 2] if include_imu else []
    analog_topics = [t for t in infos if t.startswith("/analog/")]
    notes: list[str] = []
    if marker_topics:
        base = marker_topics[0]
        if len(marker_topics) > 1:
            notes.append(f"points from {base} only (C3D has one point rate); left out {', '.join(marker_topics[1:])}")
        mk = trial.read(base)
        rate = float(infos[base].rate_hz or 0.0)
        t_pts = tc.times(base, mk.t_ns)
    elif imu_topics:
        base = imu_topics[0]
        mk = None
        rate = float(infos[base].rate_hz or 0.0)
        t_pts = tc.times(base, trial.read(base).t_ns)
    else:
        raise ExportError(f"{trial.path}: no markers and no IMU channel to put in a C3D file")
    if rate <= 0 or len(t_pts) == 0:
        raise ExportError(f"{trial.path}: {base} has no samples or no rate")
    period = 1e9 / rate
    g0 = int(t_pts[0])
    n = int(round((int(t_pts[-1]) - g0) / period)) + 1
    labels: list[str] = []
    points = np.full((n, 0, 3), np.nan)
    if mk is not None:
        idx, ok = place_on_grid(t_pts, g0, period, n)
        pos = np.where(mk.valid[:, :, None], mk.pos, np.nan) * MM_PER_M
        points = np.full((n, len(mk.labels), 3), np.nan)
        points[idx[ok]] = pos[ok]
        labels = list(mk.labels)
    content = C3dContent(point_rate_hz=rate, point_labels=labels, points_mm=points)
    # analog grid: the highest integer multiple of the point rate among /analog/ channels (1 otherwise)
    ratio = 1
    usable = []
    for topic in analog_topics:
        r = float(infos[topic].rate_hz or 0.0) / rate
        if r >= 1 and abs(r - round(r)) < 1e-6:
            usable.append(topic)
            ratio = max(ratio, int(round(r)))
        else:
            notes.append(f"{topic} left out: its rate is not a whole multiple of the point rate {rate:g} Hz")
    a_period = period / ratio
    t_an = g0 + np.round(np.arange(n * ratio) * a_period).astype(np.int64)
    columns: list[np.ndarray] = []
    for topic in usable:
        an = trial.read(topic)
        t = tc.times(topic, an.t_ns)
        if round(float(infos[topic].rate_hz) / rate) == ratio:
            idx, ok = place_on_grid(t, g0, a_period, len(t_an))
            vals = np.full((len(t_an), an.values.shape[1]), np.nan)
            vals[idx[ok]] = an.values[ok]
        else:
            vals = interp_gapped(t, an.values, t_an, 1e9 / float(infos[topic].rate_hz))
        units = list(an.units) if isinstance(an.units, list | tuple) else [str(an.units)] * len(an.channel_names)
        content.analog_labels += list(an.channel_names)
        content.analog_units += units
        columns.append(vals)
    for topic in imu_topics:
        s = trial.read(topic)
        name = topic.rsplit("/", 1)[1]
        t = tc.times(topic, s.t_ns)
        imu_period = 1e9 / float(infos[topic].rate_hz or rate)
        for group, unit in (("acc", "m/s^2"), ("gyr", "rad/s"), ("mag", "uT")):
            arr = getattr(s, group)
            if arr is None:
                continue
            columns.append(interp_gapped(t, arr, t_an, imu_period))
            content.analog_labels += [f"{name}_{group}_{a}" for a in "xyz"]
            content.analog_units += [unit] * 3
    if columns:
        content.analogs = np.concatenate(columns, axis=1)
        content.analog_rate_hz = rate * ratio
    for topic in [t for t in infos if t.startswith("/derived/phases/") or t.startswith("/events/")]:
        iv = trial.read(topic)
        for a, b, label, task in zip(
            tc.times(topic, iv.start_ns), tc.times(topic, iv.end_ns), iv.labels, iv.task_index, strict=True
        ):
            desc = f"repetition {int(task)}" if int(task) > 0 else topic
            content.events.append(((int(a) - g0) / 1e9, str(label), desc))
            content.events.append(((int(b) - g0) / 1e9, f"{label}_end", desc))
    return content, notes + tc.notes


def export_c3d(
    trial, out: str | Path, *, clock: str = "reference", imu: str | None = None, include_imu: bool = True
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
