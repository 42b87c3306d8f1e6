"""OpenSim/OpenSense orientation files (``.sto``, Storage version 3, ``DataType=Quaternion``).

Layout (as OpenSim 4.x writes it, e.g. ``../shared/data/devices/opensense_sto/``)::

    DataRate=100.000000
    DataType=Quaternion
    version=3
    OpenSimVersion=4.5
    endheader
    time<TAB>pelvis_imu<TAB>...
    0<TAB>w,x,y,z<TAB>...

One column per IMU (OpenSense matches them to model frames by name, e.g. ``radius_r_imu``); each
cell holds the sensor-to-global quaternion ``w,x,y,z`` of ``/derived/orientation/{imu}``, or of the device's own
estimate ``/orientation/{imu}`` (Xsens, APDM, MVN, OpenSense ``.sto``) for an IMU imulog has not oriented. Rows are on a
uniform grid (``DataRate``): several IMUs are slerped onto the first one's grid on the chosen clock;
samples across a time gap longer than 1.5 periods are ``nan,nan,nan,nan``. The global frame is imulog's
(z up); OpenSense's IMU placer turns it to OpenSim's y-up ground with ``sensor_to_opensim_rotations``
(-90 deg about x).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from imulog.archive.trial_clock import seconds_from, trial_clock
from imulog.export._atomic import ExportError, atomic_file
from imulog.export.table import ExportResult
from imulog.process import quaternion as quat

if TYPE_CHECKING:
    from imulog.archive.reader import TrialReader

ORIENTATION_PREFIX = "/derived/orientation/"


def format_sto(
    time_s: np.ndarray,
    names: Sequence[str],
    quats_wxyz: Sequence[np.ndarray],
    rate_hz: float,
    *,
    opensim_version: str = "4.5",
) -> str:
    """The text of a quaternion ``.sto`` file: ``time_s`` (N,), one (N, 4) w,x,y,z array per name."""
    if len(names) != len(quats_wxyz):
        raise ValueError("one quaternion array per name")
    header = f"DataRate={rate_hz:.6f}\nDataType=Quaternion\nversion=3\nOpenSimVersion={opensim_version}\nendheader\n"
    lines = [header + "\t".join(["time", *names])]
    cells = [np.char.mod("%.17g", np.asarray(q, np.float64)) for q in quats_wxyz]
    times = np.char.mod("%.17g", np.asarray(time_s, np.float64))
    for i in range(len(times)):
        lines.append("\t".join([times[i], *(",".join(c[i]) for c in cells)]))
    return "\n".join(lines) + "\n"


def resample_orientation(t_ns: np.ndarray, q: np.ndarray, grid_ns: np.ndarray, period_ns: float) -> np.ndarray:
    """Slerp unit quaternions (N, 4) from ``t_ns`` onto ``grid_ns``; NaN outside the data and in gaps
    longer than 1.5 ``period_ns``."""
    t = np.asarray(t_ns, np.int64)
    q = quat.normalize(np.asarray(q, np.float64))
    out = np.full((len(grid_ns), 4), np.nan)
    if len(t) == 0:
        return out
    # hemisphere-continuous so slerp takes the short way
    dots = np.einsum("ij,ij->i", q[1:], q[:-1])
    flips = np.concatenate([[1.0], np.cumprod(np.where(dots < 0, -1.0, 1.0))])
    q = q * flips[:, None]
    k = np.searchsorted(t, grid_ns, side="right") - 1
    inside = (k >= 0) & (grid_ns <= t[-1])
    k = np.clip(k, 0, max(len(t) - 2, 0))
    if len(t) == 1:
        out[inside] = q[0]
        return out
    t0, t1 = t[k], t[k + 1]
    ok = inside & ((t1 - t0) <= 1.5 * period_ns)
    frac = np.clip((grid_ns - t0) / np.maximum(t1 - t0, 1), 0.0, 1.0)
    res = quat.slerp(q[k], q[k + 1], frac)
    out[ok] = res[ok]
    j = np.clip(np.searchsorted(t, grid_ns), 0, len(t) - 1)
    exact = t[j] == grid_ns  # a grid point on a sample takes it as it is, also beside a gap
    out[exact] = q[j[exact]]
    return out


def default_name(imu: str) -> str:
    """OpenSense column name of an IMU: ``wrist`` -> ``wrist_imu`` (kept if it already ends in ``_imu``)."""
    return imu if imu.endswith("_imu") else f"{imu}_imu"


DEVICE_PREFIX = "/orientation/"
SOURCES = ("auto", "derived", "device")


def orientation_topics(trial, source: str = "auto") -> dict[str, str]:
    """IMU name -> the orientation channel exported for it: ``/derived/orientation/IMU`` (imulog's) or
    ``/orientation/IMU`` (the device's own estimate: Xsens, APDM, MVN, OpenSense ``.sto``).

    ``source``: ``auto`` takes imulog's where there is one and the device's otherwise; ``derived`` or ``device``
    take only that kind. Every IMU of the trial with an orientation of the kind chosen is listed, in trial order.
    """
    if source not in SOURCES:
        raise ExportError(f"{trial.path}: orientation source must be one of {', '.join(SOURCES)}, not {source!r}")
    topics = trial.topics()
    derived = {t[len(ORIENTATION_PREFIX) :]: t for t in topics if t.startswith(ORIENTATION_PREFIX)}
    device = {t[len(DEVICE_PREFIX) :]: t for t in topics if t.startswith(DEVICE_PREFIX)}
    order = [t.rsplit("/", 1)[-1] for t in topics if t.startswith((ORIENTATION_PREFIX, DEVICE_PREFIX, "/imu/"))]
    out: dict[str, str] = {}
    for name in dict.fromkeys(order):
        if source in ("auto", "derived") and name in derived:
            out[name] = derived[name]
        elif source in ("auto", "device") and name in device:
            out[name] = device[name]
    return out


def heading_frame(trial, topic: str) -> tuple[str, bool]:
    """(the global frame of an orientation channel, whether other IMUs can share it).

    imulog's: its ``global_frame`` (ENU with the magnetometer fused, shareable; 6D: z-up with an arbitrary
    heading of its own, never shared). The device's: the device's global frame as its export declares it
    (``Coordinate system`` of an Xsens header), which the sensors of one export share."""
    import json

    meta = trial.channel(topic).metadata
    if topic.startswith(ORIENTATION_PREFIX):
        params = meta.get("params") or "{}"
        frame = str((json.loads(params) if isinstance(params, str) else params).get("global_frame") or "unknown")
        return frame, "arbitrary heading" not in frame
    name = topic[len(DEVICE_PREFIX) :]
    device = trial.metadata.get(f"imulog.device.{name}") or {}
    header = device.get("header") or {}
    system = header.get("Coordinate system") or device.get("coordinate_system")
    fmt = device.get("format") or device.get("model") or "device"
    return (f"the {fmt} export's own" + (f" ({system})" if system else "")), True


def resolve_names(trial, imus: Sequence[str], names: Mapping[str, str]) -> dict[str, str]:
    """``--name KEY=COLUMN`` -> IMU -> column: KEY is an IMU's name, or its device serial or label
    (``imulog.device.IMU``), case-insensitive. A KEY that matches no exported IMU is an error."""
    keys: dict[str, str] = {}
    for imu in imus:
        device = trial.metadata.get(f"imulog.device.{imu}") or {}
        for key in (imu, device.get("serial"), device.get("label")):
            if key:
                keys.setdefault(str(key).lower(), imu)
    out: dict[str, str] = {}
    for key, column in names.items():
        imu = keys.get(str(key).lower())
        if imu is None:
            raise ExportError(
                f"{trial.path}: --name {key}={column}: no IMU {key!r} with an orientation "
                f"(IMUs: {', '.join(imus) or 'none'})"
            )
        out[imu] = column
    return out


def export_sto(
    trial: TrialReader,
    out: str | Path,
    *,
    clock: str = "device",
    imu: str | None = None,
    imus: Sequence[str] | None = None,
    names: Mapping[str, str] | None = None,
    rate_hz: float | None = None,
    source: str = "auto",
) -> ExportResult:
    """Write the orientation of every IMU of the trial as one OpenSense ``.sto`` file.

    Per IMU, imulog's ``/derived/orientation/IMU`` or the device's own ``/orientation/IMU`` (``source``, see
    :func:`orientation_topics`); each source is named in the result's notes and ``topics``. ``imus``: which IMUs
    (default: all); ``names``: IMU (or serial, or label) -> column name (default ``{imu}_imu``), refused when it
    matches no IMU; ``rate_hz``: the grid's rate (default: the first IMU's). When the IMUs' orientations do not
    share one heading frame (6D orientations each have their own heading), a note says so.
    """
    available = orientation_topics(trial, source)
    chosen = list(imus) if imus else list(available)
    if not chosen:
        hint = "" if source == "derived" else " or /orientation/*"
        raise ExportError(
            f"{trial.path}: no /derived/orientation/*{hint} channel: run `imulog process orientation {trial.path}` first"
        )
    missing = [i for i in chosen if i not in available]
    if missing:
        raise ExportError(
            f"{trial.path}: no orientation of IMU {missing[0]!r} (orientations: {', '.join(available) or 'none'})"
        )
    rename = resolve_names(trial, chosen, names or {})
    tc = trial_clock(trial, clock, imu)
    raw_imus = set(trial.topics())
    streams = []
    for name in chosen:
        topic = available[name]
        s = trial.read(topic)
        clock_topic = f"/imu/{name}" if f"/imu/{name}" in raw_imus else topic  # device estimates: the IMU's clock
        streams.append((name, tc.times(clock_topic, s.t_ns), s.values))
    first_info = trial.channel(available[chosen[0]])
    rate = float(rate_hz or first_info.rate_hz or 0.0)
    if rate <= 0:
        raise ExportError(f"{trial.path}: cannot tell the orientation rate; give --rate")
    t_first = streams[0][1]
    period = 1e9 / rate
    n = int(np.floor((t_first[-1] - t_first[0]) / period + 1e-9)) + 1 if len(t_first) else 0
    grid = t_first[0] + np.round(np.arange(n) * period).astype(np.int64) if n else np.zeros(0, np.int64)
    columns = [rename.get(name, default_name(name)) for name in chosen]
    if len(set(columns)) != len(columns):
        raise ExportError(f"{out}: two IMUs get the same column name ({', '.join(columns)})")
    frames = {name: heading_frame(trial, available[name]) for name in chosen}
    shared = {frame for frame, ok in frames.values()}
    related = len(chosen) < 2 or (len(shared) == 1 and all(ok for _, ok in frames.values()))
    heading_note = ""
    if not related and all(available[n].startswith(ORIENTATION_PREFIX) for n in chosen):
        # imulog's orientations of several IMUs: into the trial's common heading frame when the heading step
        # found one (issue 27: from the magnetometers, the optical clusters or a declared static pose)
        from imulog.steps.heading import common_heading

        corrections, heading_note = common_heading(trial.metadata, chosen)
        if corrections is not None:
            streams = [(n, t, quat.multiply(np.asarray(corrections[n], float), q)) for n, t, q in streams]
            rec = trial.metadata.get("imulog.heading") or {}
            heading_note = f"every IMU in the trial's common heading frame ({rec.get('source')}: {rec.get('frame')})"
            related = True
    quats = [resample_orientation(t, q, grid, period) for _, t, q in streams]
    text = format_sto(seconds_from(grid, tc.origin_ns), columns, quats, rate)
    with atomic_file(out) as tmp:
        tmp.write_text(text)
    notes = tc.export_notes()
    for name, column in zip(chosen, columns, strict=True):
        kind = "imulog's" if available[name].startswith(ORIENTATION_PREFIX) else "the device's"
        notes.append(f"{column}: {available[name]} ({kind}; global frame {frames[name][0]})")
    if related and heading_note:
        notes.append(heading_note)
    elif not related:
        notes.append(
            f"the {len(chosen)} IMUs' orientations do not share one heading frame ("
            + "; ".join(f"{n}: {f}" for n, (f, _) in frames.items())
            + "): segment headings in this file do not relate"
            + (f" ({heading_note})" if heading_note else "")
        )
    return ExportResult(
        path=str(out),
        format="sto",
        clock=clock,
        rows=n,
        columns=["time", *columns],
        topics=[available[c] for c in chosen],
        files=[str(out)],
        notes=notes,
    )
