"""The two clocks of a simulated trial: the reference (Vicon) clock and the IMU's device clock.

The mapping is the project convention (conventions.md, ``imulog.process.alignment``)::

    t_ref_ns = t_dev_ns + offset_ns + drift_ppm * 1e-6 * (t_dev_ns - t0_ns)

``t0_ns`` is the IMU's first device time stamp. The IMU samples at ``rate_hz`` on its own clock;
its device time stamps are written with microsecond resolution (three decimals of ms), so they are
exact in the text file; each sample's true reference time follows from the mapping above.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ClockParams:
    """Clock parameters. Defaults and reasoning in docs/simulate.md."""

    imu_rate_hz: float = 114.9  # BlueBuddy nominal 115 Hz; the real crystal-derived rate is not exact
    imu_start_ref_s: float | None = None  # IMU start on the reference clock; None: random in [0.5, 2.5] s
    imu_stop_early_s: float | None = None  # IMU stops this long before the Vicon; None: random [0.5, 2.5] s
    device_t0_s: float | None = None  # first device time stamp (uptime); None: random [5, 3600] s
    drift_ppm: float | None = None  # None: N(0, 30) ppm, typical of consumer crystals (±20–50 ppm)
    vicon_rate_hz: float = 100.0  # the thesis's Vicon T20 capture rate
    timestamp_resolution_us: int = 1  # device stamps are written in ms with 3 decimals


@dataclass(frozen=True)
class ClockTruth:
    offset_ns: int
    drift_ppm: float
    t0_ns: int

    def device_to_reference(self, t_dev_ns: np.ndarray) -> np.ndarray:
        """Exact reference time (float ns) of device time stamps."""
        t = np.asarray(t_dev_ns, dtype=np.int64)
        return (t + self.offset_ns).astype(np.float64) + self.drift_ppm * 1e-6 * (t - self.t0_ns).astype(np.float64)

    def reference_to_device(self, t_ref_ns: np.ndarray) -> np.ndarray:
        """Inverse mapping (float ns)."""
        t = np.asarray(t_ref_ns, dtype=np.float64)
        k = 1.0 + self.drift_ppm * 1e-6
        return (t - self.offset_ns + self.drift_ppm * 1e-6 * self.t0_ns) / k


def vicon_times_ns(n_frames: int, rate_hz: float) -> np.ndarray:
    """Nexus frame times: ``round((frame - 1) / rate_hz * 1e9)`` for frames 1..n (Sub Frame 0)."""
    frames = np.arange(n_frames, dtype=np.float64)
    return np.round(frames / rate_hz * 1e9).astype(np.int64)


def imu_device_times_ns(params: ClockParams, truth: ClockTruth, ref_start_s: float, ref_stop_s: float) -> np.ndarray:
    """Device time stamps (int64 ns, microsecond-quantised) of samples taken in [ref_start, ref_stop]."""
    dev_stop = truth.reference_to_device(np.array([ref_stop_s * 1e9]))[0]
    period_ns = 1e9 / params.imu_rate_hz
    n = int(np.floor((dev_stop - truth.t0_ns) / period_ns)) + 1
    res = params.timestamp_resolution_us * 1000
    t = truth.t0_ns + np.round(np.arange(n) * period_ns / res).astype(np.int64) * res
    return t


def draw_clock(params: ClockParams, rng: np.random.Generator) -> tuple[ClockTruth, float, float]:
    """Random clock truth; returns (truth, imu_start_ref_s, imu_stop_early_s)."""
    start = params.imu_start_ref_s if params.imu_start_ref_s is not None else float(rng.uniform(0.5, 2.5))
    stop_early = params.imu_stop_early_s if params.imu_stop_early_s is not None else float(rng.uniform(0.5, 2.5))
    dev0_s = params.device_t0_s if params.device_t0_s is not None else float(rng.uniform(5.0, 3600.0))
    drift = params.drift_ppm if params.drift_ppm is not None else float(rng.normal(0.0, 30.0))
    res = params.timestamp_resolution_us * 1000
    t0_ns = int(round(dev0_s * 1e9 / res)) * res
    offset_ns = int(round(start * 1e9)) - t0_ns
    return ClockTruth(offset_ns=offset_ns, drift_ppm=drift, t0_ns=t0_ns), start, stop_early
