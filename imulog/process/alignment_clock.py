"""The alignment's clock model: device time to reference time and back (docs/architecture.md,
``imulog.alignment``)::

    t_ref_ns = t_dev_ns + offset_ns + drift_ppm * 1e-6 * (t_dev_ns - t0_ns)

Times in int64 ns. Pure functions; split from :mod:`imulog.process.alignment` (issue 24).
"""

from __future__ import annotations

import numpy as np

NS = 1_000_000_000


# --------------------------------------------------------------------------------------------
# clock model


def _int_ns(value) -> int:
    """An int64-ns field that may come back from metadata as int, float or string."""
    if value is None or value == "":
        return 0
    if isinstance(value, str):
        try:
            return int(value)
        except ValueError:
            return int(round(float(value)))
    return int(round(value)) if isinstance(value, float) else int(value)


def _clock(alignment: dict) -> tuple[int, float, int]:
    drift = alignment.get("drift_ppm", 0.0)
    return _int_ns(alignment.get("offset_ns", 0)), float(drift or 0.0), _int_ns(alignment.get("t0_ns", 0))


def device_to_reference(t_dev_ns: np.ndarray | int, alignment: dict) -> np.ndarray:
    """Map IMU device time to the reference clock: ``t_dev + offset + drift_ppm*1e-6*(t_dev - t0)``.

    ``alignment`` is an ``imulog.alignment`` record (keys ``offset_ns``, ``drift_ppm``, ``t0_ns``;
    missing drift or t0 mean 0). Returns int64 ns (rounded to the nearest ns).
    """
    t = np.asarray(t_dev_ns, dtype=np.int64)
    offset, drift, t0 = _clock(alignment)
    out = t + offset
    if drift != 0.0:
        out = out + np.round(drift * 1e-6 * (t - t0).astype(np.float64)).astype(np.int64)
    return out


def reference_to_device(t_ref_ns: np.ndarray | int, alignment: dict) -> np.ndarray:
    """Inverse of :func:`device_to_reference` (int64 ns)."""
    t = np.asarray(t_ref_ns, dtype=np.int64)
    offset, drift, t0 = _clock(alignment)
    k = drift * 1e-6
    # t_ref - t0 - offset = (t_dev - t0) * (1 + k)
    rel = (t - t0 - offset).astype(np.float64) / (1.0 + k)
    return t0 + np.round(rel).astype(np.int64)


# --------------------------------------------------------------------------------------------
