"""Hand a trial to other Python toolkits in their own unit and frame conventions.

* gaitmap (mad-lab-fau/gaitmap) expects one ``pandas.DataFrame`` per sensor with columns
  ``acc_x, acc_y, acc_z`` in m/s^2 and ``gyr_x, gyr_y, gyr_z`` in **deg/s**, in its own sensor frame
  (for foot sensors: x forward, z up from the sole). imulog stores rad/s, so passing an imulog table
  straight to gaitmap silently gives gyroscope values 57.3 times too small: :func:`to_gaitmap`
  converts, and applies ``rotation`` (3x3, imulog sensor frame -> gaitmap sensor frame) when given.
* kineticstoolkit works with ``ktk.TimeSeries`` (time in s, data arrays, units in ``data_info``):
  :func:`to_kineticstoolkit` gives one TimeSeries per channel, on the chosen clock.
"""

from __future__ import annotations

import numpy as np

from imulog.archive.trial_clock import seconds_from, trial_clock
from imulog.export._atomic import ExportError
from imulog.export.table import column_units

RAD_TO_DEG = 180.0 / np.pi
GAITMAP_COLUMNS = ("acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z")


def gaitmap_frame(acc_m_s2: np.ndarray, gyr_rad_s: np.ndarray, rotation: np.ndarray | None = None) -> np.ndarray:
    """(N, 6) ``acc`` m/s^2 and ``gyr`` deg/s, rotated by ``rotation`` (3x3) when given."""
    acc = np.asarray(acc_m_s2, np.float64)
    gyr = np.asarray(gyr_rad_s, np.float64) * RAD_TO_DEG
    if rotation is not None:
        r = np.asarray(rotation, np.float64)
        if r.shape != (3, 3):
            raise ValueError("rotation must be a 3x3 matrix")
        acc, gyr = acc @ r.T, gyr @ r.T
    return np.concatenate([acc, gyr], axis=1)


def to_gaitmap(trial, imu: str | None = None, *, clock: str = "device", rotation: np.ndarray | None = None):
    """One IMU as the DataFrame gaitmap expects (index ``t[s]``, acc m/s^2, gyr deg/s)."""
    import pandas as pd

    names = [t.rsplit("/", 1)[1] for t in trial.topics() if t.startswith("/imu/") and t.count("/") == 2]
    if imu is None:
        if len(names) != 1:
            raise ExportError(f"{trial.path}: name the IMU for gaitmap (IMUs: {', '.join(names) or 'none'})")
        imu = names[0]
    if imu not in names:
        raise ExportError(f"{trial.path}: no IMU {imu!r} (IMUs: {', '.join(names) or 'none'})")
    topic = f"/imu/{imu}"
    s = trial.read(topic)
    tc = trial_clock(trial, clock, imu)
    data = gaitmap_frame(s.acc, s.gyr, rotation)
    index = pd.Index(seconds_from(tc.times(topic, s.t_ns), tc.origin_ns), name="t[s]")
    df = pd.DataFrame(data, columns=list(GAITMAP_COLUMNS), index=index)
    df.attrs["units"] = {"acc": "m/s^2", "gyr": "deg/s"}
    df.attrs["sampling_rate_hz"] = trial.channel(topic).rate_hz
    return df


def to_kineticstoolkit(trial, topic: str, *, clock: str = "device", imu: str | None = None):
    """One channel as a ``kineticstoolkit.TimeSeries``: time in s from the trial's start, units in data_info.

    IMU channels give ``acc``/``gyr``/``mag`` (N, 3) arrays, markers one (N, 4) homogeneous array per
    marker in m (as ktk.read_c3d gives), other channels one array per column. Intervals become events.
    """
    try:
        import kineticstoolkit as ktk
    except ImportError:
        raise ExportError("kineticstoolkit is not installed (pip install kineticstoolkit)") from None
    from imulog.archive.tables import stream_columns
    from imulog.model import ImuStream, Intervals, MarkerStream

    tc = trial_clock(trial, clock, imu)
    s = trial.read(topic)
    meta = trial.channel(topic).metadata
    if isinstance(s, Intervals):
        ts = ktk.TimeSeries()
        for a, label in zip(seconds_from(tc.times(topic, s.start_ns), tc.origin_ns), s.labels, strict=True):
            ts = ts.add_event(float(a), str(label))
        return ts
    ts = ktk.TimeSeries(time=seconds_from(tc.times(topic, s.t_ns), tc.origin_ns))
    data: dict[str, tuple[np.ndarray, str]] = {}
    if isinstance(s, ImuStream):
        for group, unit in (("acc", "m/s^2"), ("gyr", "rad/s"), ("mag", "uT")):
            if getattr(s, group) is not None:
                data[group] = (np.asarray(getattr(s, group), np.float64), unit)
    elif isinstance(s, MarkerStream):
        for j, label in enumerate(s.labels):
            p = np.where(s.valid[:, j, None], s.pos[:, j], np.nan)
            data[label] = (np.column_stack([p, np.ones(len(p))]), "m")
    else:
        cols = stream_columns(s)
        cols.pop("t_ns")
        units = column_units(s, meta, list(cols))
        data = {k: (np.asarray(v, np.float64), units[k]) for k, v in cols.items()}
    for name, (values, unit) in data.items():
        ts = ts.add_data(name, values)
        ts = ts.add_info(name, "Unit", unit)
    return ts
