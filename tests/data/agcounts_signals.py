"""Closed-form test accelerations (numpy only) whose agcounts output is kept in agcounts_10s.csv.

Independent of every recording and of imulog's simulator: a slowly turning gravity vector, gait-like 1.9/3.8 Hz
bursts, steady 7.3, 11.7 and 17.9 Hz components (what ActiLife's resampler aliases), a chirp and heel-strike-like
impacts. ``synthetic_acc(rate_hz)`` is (N, 3) g for ``SECONDS`` s, the same at every rate up to sampling.
"""

from __future__ import annotations

import numpy as np

SECONDS = 300
#: rates (Hz) kept in the fixture: ActiLife's resampled rates and, as a control, its decimated ones
RATES_HZ = (30, 40, 50, 60, 70, 80, 90, 100)


def synthetic_acc(rate_hz: int, seconds: int = SECONDS) -> np.ndarray:
    """(seconds x rate_hz, 3) acceleration in g sampled at ``rate_hz`` from t = 0."""
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    theta = 0.6 * np.sin(2 * np.pi * t / 97.0)
    phi = 0.4 * np.sin(2 * np.pi * t / 61.0) + 0.3
    grav = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    envelope = np.clip(np.sin(2 * np.pi * t / 80.0), 0.0, None) ** 2  # walking bouts, still in between
    gait = envelope * (np.sin(2 * np.pi * 1.9 * t) + 0.5 * np.sin(2 * np.pi * 3.8 * t + 0.3))
    f_chirp = 0.2 + (17.0 - 0.2) * t / seconds
    chirp = 0.15 * np.sin(2 * np.pi * np.cumsum(f_chirp) / rate_hz)
    impacts = envelope * 0.6 * np.exp(-(((t % (1 / 1.9)) / 0.015) ** 2))
    hf = np.column_stack(
        [0.08 * np.sin(2 * np.pi * 7.3 * t), 0.05 * np.sin(2 * np.pi * 11.7 * t), 0.04 * np.sin(2 * np.pi * 17.9 * t)]
    )
    motion = np.column_stack([0.35 * gait + impacts, 0.2 * gait + chirp, 0.5 * gait - 0.5 * impacts])
    return grav + motion + hf
