"""A trial's raw channels published as LSL outlets in real time (or faster / slower with ``speed``).

Each raw channel becomes one outlet named after the channel (``/imu/wrist`` -> ``wrist``) with a header that
``imulog record`` (and LabRecorder + ``imulog convert``) maps back to the same channel: IMU channels as type
``IMU`` with channels ``acc_x``.. in m/s^2, ``gyr_x``.. in rad/s, ``mag_x``.. in uT; markers as type ``MoCap``
with ``<marker>_X/_Y/_Z`` in m (NaN = occluded); signals and analog channels with their columns and units;
events as an irregular string stream. Values are sent as double64, so they arrive unchanged. Samples are
scheduled on the trial's time axis (the channels' MCAP log times), so the outlets keep the trial's relative
timing; each is stamped ``t0 + (log_time - first log time) / speed`` on this host's LSL clock.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from imulog.live.lsl import LslError, pylsl

REPLAYED = ("imu", "markers", "signals", "analog", "events")
IMU_PARTS = (("acc", "m/s^2"), ("gyr", "rad/s"), ("mag", "uT"))


@dataclass
class OutletPlan:
    """What one outlet sends: its header fields, samples (rows or strings) and their log times (ns)."""

    topic: str
    name: str
    type: str
    labels: list[str]
    units: list[str]
    srate: float
    rows: Any  # (N, C) float64 array, or a list of N strings
    log_ns: np.ndarray
    string: bool = False


def plan_channel(topic: str, stream: Any, log_ns: np.ndarray, rate_hz: float | None) -> OutletPlan | None:
    """The outlet of one raw channel (None for a channel kind that is not sent)."""
    family, _, name = topic.strip("/").partition("/")
    name = name.replace("/", "_")
    rate = float(rate_hz or 0.0)
    if family == "imu":
        labels, units, cols = [], [], []
        for q, unit in IMU_PARTS:
            values = getattr(stream, q, None)
            if values is not None:
                labels += [f"{q}_{a}" for a in "xyz"]
                units += [unit] * 3
                cols.append(values)
        if not cols:
            return None
        return OutletPlan(topic, name, "IMU", labels, units, rate, np.hstack(cols), log_ns)
    if family == "markers":
        labels = [f"{m}_{a}" for m in stream.labels for a in "XYZ"]
        rows = stream.pos.reshape(len(stream.t_ns), -1)
        return OutletPlan(topic, name, "MoCap", labels, ["m"] * len(labels), rate, rows, log_ns)
    if family in ("signals", "analog"):
        if name.endswith("_lsl_clock"):
            return None  # a recording's own clock record, not a device stream
        columns = list(getattr(stream, "columns", None) or getattr(stream, "labels", []))
        units = list(getattr(stream, "units", None) or [""] * len(columns))
        values = np.asarray(stream.values, dtype=np.float64)
        return OutletPlan(topic, name, "Signal", columns, units, rate, values, log_ns)
    if family == "events":
        return OutletPlan(topic, name, "Markers", ["label"], [""], 0.0, list(stream.labels), log_ns, string=True)
    return None


def load_plans(path: Path, start_s: float = 0.0, duration_s: float | None = None) -> list[OutletPlan]:
    """The outlets of a trial's raw channels, cut to ``[start_s, start_s + duration_s)`` of the trial's axis."""
    from imulog.archive import TrialReader
    from imulog.archive.timeline import TrialAxis

    plans = []
    with TrialReader(path) as trial:
        channels = [c for c in trial.channels if c.topic.strip("/").split("/")[0] in REPLAYED and c.sample_count]
        imus = {c.topic.split("/")[-1] for c in channels if c.topic.startswith("/imu/")}
        axis = TrialAxis(trial.metadata, imus)
        for ch in channels:
            stream = trial.read(ch.topic)
            t = getattr(stream, "t_ns", None)
            t = stream.start_ns if t is None else t
            log_ns = axis.map_for(ch.topic, ch.metadata)(t).astype(np.int64)
            plan = plan_channel(ch.topic, stream, log_ns, ch.rate_hz)
            if plan is not None:
                plans.append(plan)
    if not plans:
        raise LslError(f"{path}: no raw IMU, marker, signal or event channel to replay")
    origin = min(int(p.log_ns[0]) for p in plans if len(p.log_ns)) + int(start_s * 1e9)
    end = origin + int(duration_s * 1e9) if duration_s is not None else None
    for p in plans:
        keep = (p.log_ns >= origin) & (p.log_ns < end if end is not None else True)
        idx = np.flatnonzero(keep)
        p.rows = [p.rows[i] for i in idx] if p.string else p.rows[idx]
        p.log_ns = p.log_ns[idx] - origin
    return plans


def make_outlet(plan: OutletPlan, source_id: str) -> Any:
    """An LSL outlet with the channel labels and units in ``desc/channels`` (the XDF convention)."""
    lsl = pylsl()
    fmt = lsl.cf_string if plan.string else lsl.cf_double64
    info = lsl.StreamInfo(plan.name, plan.type, len(plan.labels), plan.srate, fmt, f"{source_id}:{plan.topic}")
    channels = info.desc().append_child("channels")
    for label, unit in zip(plan.labels, plan.units, strict=True):
        ch = channels.append_child("channel")
        ch.append_child_value("label", label)
        if unit:
            ch.append_child_value("unit", unit)
        ch.append_child_value("type", plan.type)
    info.desc().append_child_value("manufacturer", "imulog replay")
    return lsl.StreamOutlet(info, chunk_size=0, max_buffered=360)


def replay(
    plans: list[OutletPlan],
    *,
    speed: float = 1.0,
    source_id: str = "imulog-replay",
    wait_consumers_s: float = 0.0,
    stop: threading.Event | None = None,
    on_ready: Callable[[list[Any]], None] | None = None,
) -> dict[str, int]:
    """Send every plan's samples when due; return samples sent per outlet name.

    ``wait_consumers_s``: first wait (up to this long, per outlet) until a recorder has connected to each outlet.
    """
    lsl = pylsl()
    stop = stop or threading.Event()
    outlets = [make_outlet(p, source_id) for p in plans]
    if on_ready is not None:
        on_ready(outlets)
    if wait_consumers_s > 0:
        for plan, outlet in zip(plans, outlets, strict=True):
            if not outlet.wait_for_consumers(wait_consumers_s):
                raise LslError(f"no recorder connected to outlet {plan.name!r} within {wait_consumers_s:g} s")
    t0 = lsl.local_clock() + 0.05
    sent = [0] * len(plans)
    stamps = [t0 + p.log_ns / 1e9 / speed for p in plans]
    while not stop.is_set():
        now = lsl.local_clock()
        left = False
        for k, (plan, outlet) in enumerate(zip(plans, outlets, strict=True)):
            i = sent[k]
            j = int(np.searchsorted(stamps[k], now, side="right"))
            if j > i:
                rows = plan.rows[i:j]
                data = [[str(r)] for r in rows] if plan.string else np.ascontiguousarray(rows).tolist()
                outlet.push_chunk(data, list(stamps[k][i:j]))
                sent[k] = j
            left = left or sent[k] < len(stamps[k])
        if not left:
            break
        stop.wait(0.002)
    time.sleep(0.2)  # let the last chunk leave before the outlets close
    return {p.name: n for p, n in zip(plans, sent, strict=True)}
