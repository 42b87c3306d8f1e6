"""IMU channels among a C3D file's analogs, named as imulog's C3D export writes them (:mod:`imulog.export.c3d`).

imulog writes each IMU's channels as analogs ``{imu}_acc_x`` .. ``{imu}_acc_z`` (m/s^2), ``{imu}_gyr_*`` (rad/s)
and ``{imu}_mag_*`` (uT). A C3D read back gives them as ``/imu/{imu}`` again when an IMU has a whole accelerometer
or gyroscope triad and every triad of it carries those units in ``ANALOG:UNITS``; the same names with other units
(another tool's ``g`` or ``deg/s``, or none) stay analogs, with a one-line warning. Pure functions on the plan's
labels and units and on decoded analog values; times in int64 ns.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from imulog.model import ImuStream

#: the units imulog's C3D export writes per group, and their usual spellings
IMU_UNITS = {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT"}
UNIT_SPELLINGS = {"acc": {"m/s^2", "m/s2", "m/s²"}, "gyr": {"rad/s"}, "mag": {"uT", "µT", "μT"}}
_LABEL = re.compile(r"^(?P<imu>.+)_(?P<group>acc|gyr|mag)_(?P<axis>[xyz])$")


@dataclass(frozen=True)
class C3dImu:
    """One IMU found among the analogs: its ``name`` and, per group (``acc``, ``gyr``, ``mag``), the analog columns of
    its x, y and z axes."""

    name: str
    columns: dict[str, list[int]]

    def all_columns(self) -> list[int]:
        return [c for cols in self.columns.values() for c in cols]


def find_imus(source: str, labels: list[str], units: list[str]) -> tuple[list[C3dImu], list[int], list[str]]:
    """The IMUs imulog's naming gives among the analog ``labels`` (with ``units`` from ``ANALOG:UNITS``): (IMUs, the
    analog columns that stay analogs, warnings naming ``source`` for IMU-like names with other units)."""
    axes: dict[str, dict[str, dict[str, int]]] = {}
    for i, label in enumerate(labels):
        m = _LABEL.match(label.strip())
        if m:
            axes.setdefault(m["imu"], {}).setdefault(m["group"], {})[m["axis"]] = i
    imus: list[C3dImu] = []
    warnings: list[str] = []
    for name, groups in axes.items():
        full = {g: [by_axis[a] for a in "xyz"] for g, by_axis in groups.items() if set(by_axis) == set("xyz")}
        if not {"acc", "gyr"} & set(full):
            continue
        wrong = {
            g: sorted({units[c] for c in cols})
            for g, cols in full.items()
            if any(units[c] not in UNIT_SPELLINGS[g] for c in cols)
        }
        if wrong:
            said = "; ".join(
                f"{name}_{g}_x..z in {' '.join(map(repr, u))}, not {IMU_UNITS[g]}" for g, u in wrong.items()
            )
            warnings.append(
                f"{source}: analogs named like imulog's IMU channels ({said} in ANALOG:UNITS): kept as analogs, "
                f"not read as IMU {name!r}"
            )
            continue
        imus.append(C3dImu(name, {g: full[g] for g in IMU_UNITS if g in full}))
    taken = {c for imu in imus for c in imu.all_columns()}
    return imus, [i for i in range(len(labels)) if i not in taken], warnings


def sample_rows(imu: C3dImu, values: np.ndarray) -> np.ndarray:
    """The analog rows (bool) where the C3D holds a sample of ``imu``: any of its columns finite (the export leaves
    the analog frames before an IMU starts, and across its gaps, NaN)."""
    return np.isfinite(values[:, imu.all_columns()]).any(axis=1)


def imu_streams(imus: list[C3dImu], t_ns: np.ndarray, values: np.ndarray, meta: dict[str, Any]) -> list[ImuStream]:
    """The ``/imu/{name}`` streams of ``imus`` from analog samples ``values`` (A columns) at ``t_ns``, rows without a
    sample of the IMU left out; ``meta`` each stream's (rate, source)."""
    out = []
    for imu in imus:
        rows = sample_rows(imu, values)
        if not rows.any():
            continue
        cols = {g: values[rows][:, c].astype(np.float64) for g, c in imu.columns.items()}
        out.append(
            ImuStream(
                imu.name,
                np.asarray(t_ns)[rows],
                acc=cols.get("acc"),
                gyr=cols.get("gyr"),
                mag=cols.get("mag"),
                meta=imu_meta(imu, meta),
            )
        )
    return out


def imu_meta(imu: C3dImu, meta: dict[str, Any]) -> dict[str, Any]:
    """An IMU stream's meta (and device record): ``meta`` (rate, source) and the units it was read in."""
    return {**meta, "units": {g: IMU_UNITS[g] for g in imu.columns}, "c3d_analogs": True}
