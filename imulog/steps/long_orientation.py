"""Orientation of long recordings in bounded memory: overlapping windows, each smoothed offline, headings joined.

A week of wrist data is 60 M samples: the offline VQF smoother (the default backend) cannot hold it. Above
:data:`LONG_SAMPLES` the orientation step reads the IMU chunk by chunk and runs the very same computation
(:func:`imulog.steps.orientation.orientation_with_gaps`: gaps, backend, gravity-free acceleration) on windows of
``window_s`` that overlap by ``overlap_s`` on both sides; each window keeps its core and hands the rest to its
neighbours. Inclination is absolute in every window (gravity); without a magnetometer the heading of each window
is arbitrary, so each window is turned about the global vertical to continue the previous one at their join (as
the step does across long gaps). With the magnetometer fused the heading is absolute and nothing is turned.

Memory: one window plus its overlaps, whatever the recording's length.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from imulog.model import SignalStream
from imulog.steps.sample_window import SampleWindow

#: recordings with more IMU samples than this (about 8 h at 100 Hz) get their orientation window by window
LONG_SAMPLES = 3_000_000


@dataclass(frozen=True)
class WindowParams:
    """Window length and overlap on each side, seconds (the smoother's context at each window's edges)."""

    window_s: float = 1800.0
    overlap_s: float = 60.0

    def to_dict(self) -> dict[str, float]:
        return {"window_s": self.window_s, "overlap_s": self.overlap_s}


def windowed_pieces(
    path: str | Path,
    topic: str,
    imu: str,
    params: Any,
    gaps: Any,
    window: WindowParams,
    total: int,
) -> Iterator[SignalStream]:
    """The orientation step's three streams of ``topic`` (``total`` samples), window by window."""
    from imulog.archive import TrialReader
    from imulog.heap import bound_heap
    from imulog.process import quaternion as qmath
    from imulog.steps.common import mean_rate_hz
    from imulog.steps.orientation import imu_arrays, orientation_with_gaps

    core_start = 0
    join_quat: np.ndarray | None = None  # the previous window's orientation at this window's first core sample
    bound_heap()  # the same temporaries core after core: keep them out of the heap (imulog.heap)
    with TrialReader(path) as trial:
        blocks = trial.iter_blocks(topic)
        first = next(blocks)
        buf = SampleWindow(itertools.chain([imu_arrays(first, topic)], (imu_arrays(b, topic) for b in blocks)), total)
        rate = mean_rate_hz(first.t_ns)
        core = max(1, int(round(window.window_s * rate)))
        overlap = int(round(window.overlap_s * rate))
        while core_start < total:
            core_end = min(total, core_start + core)
            hi = min(total, core_end + overlap)
            lo = max(0, core_start - overlap)
            t, acc, gyr, mag = buf.take(lo, hi)
            streams, _ = orientation_with_gaps(t, acc, gyr, mag, imu, params, gaps)
            quat, lin, static = (s.values for s in streams)
            k0, k1 = core_start - lo, core_end - lo
            if join_quat is not None and not params.use_mag and np.isfinite(quat[k0]).all():
                turn = qmath.heading_offset(quat[k0 : k0 + 1], join_quat)
                quat = qmath.multiply(np.tile(turn, (len(quat), 1)), quat)
                lin = qmath.rotate(np.tile(turn, (len(lin), 1)), lin)
            join_quat = quat[k1 : k1 + 1].copy() if k1 < len(quat) else None
            for stream, values in zip(streams, (quat, lin, static), strict=True):
                yield SignalStream(
                    stream.topic, t[k0:k1], stream.columns, stream.units, values[k0:k1], frame_id=stream.frame_id
                )
            core_start = core_end
