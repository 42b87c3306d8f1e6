"""Model streams (IMU, signals, markers, poses, orientation) from the parsed columns of delimited text."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters._common import SI_UNIT
from imulog.converters._lab import orientation_stream
from imulog.converters.delimited_header import Column
from imulog.converters.delimited_plan import _Plan
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, MarkerStream, PoseStream, Recording, SignalStream


def _recording(
    plan: _Plan,
    values: np.ndarray,
    t_ns: np.ndarray,
    time_desc: dict[str, Any],
    rate_meta: float | None,
    warnings: list[str],
) -> Recording:
    """The IMU streams (SI units) and the other numeric columns of ``values``, device by device."""
    path, mapping, device_meta, fmt = plan.path, plan.mapping, plan.device_meta, plan.fmt
    devices: dict[str, list[Column]] = {}
    for c in plan.layout.columns:
        if c.quantity not in ("ignore", "index", "time"):
            devices.setdefault(c.device, []).append(c)
    rec = Recording(sources=[str(path)] + ([str(mapping.path)] if mapping else []), warnings=warnings)
    for dev, cols in devices.items():
        streams: dict[str, np.ndarray] = {}
        units: dict[str, str] = {}
        extra_cols: list[Column] = []
        chosen_variant: dict[str, str] = {}
        slots: dict[tuple[str, str | None], Column] = {}
        marks = [c for c in cols if c.quantity == "marker"]
        quat_cols = {c.axis: c for c in cols if c.quantity == "quat"}
        if marks and set(quat_cols) == set("wxyz") and {c.variant for c in marks} == {dev}:
            pos = _marker_stream(path, dev, marks, values, t_ns).pos[:, 0]
            q = np.column_stack([values[:, quat_cols[a].index] for a in "wxyz"])
            rec.poses.append(
                PoseStream(topic=f"/poses/{dev}", t_ns=t_ns, position=pos, orientation=q, frame_id="world")
            )
            rec.metadata[f"imulog.device.{dev}"] = {
                "format": fmt,
                "kind": "reference pose (position m, quaternion w, x, y, z as exported)",
                "columns": [c.name for c in marks] + [quat_cols[a].name for a in "wxyz"],
                "source": path.name,
            }
            continue
        if marks:
            rec.markers.append(_marker_stream(path, dev, marks, values, t_ns))
            rec.metadata.setdefault(
                f"imulog.device.{dev}", {"format": fmt, "kind": "markers (mapping file)", "source": path.name}
            )
        quat = {c.axis: c for c in cols if c.quantity == "quat"}
        if quat:
            if set(quat) != set("wxyz"):
                missing = ", ".join(a for a in "wxyz" if a not in quat)
                raise ConversionError(path, f"orientation group {dev!r}: no quaternion column {missing}")
            q = np.column_stack([values[:, quat[a].index] for a in "wxyz"])
            rec.signals.append(orientation_stream(dev, t_ns, q, frame_id="reference"))
            rec.metadata[f"imulog.device.{dev}"] = {
                "format": fmt,
                "kind": "reference orientation (quaternion w, x, y, z as exported)",
                "orientation": {"topic": f"/orientation/{dev}", "columns": [quat[a].name for a in "wxyz"]},
                "source": path.name,
            }
        for c in cols:
            if c.quantity in ("quat", "marker"):
                continue
            if c.quantity in ("acc", "gyr", "mag", "temperature"):
                v = chosen_variant.setdefault(c.quantity, c.variant)
                if c.variant != v:
                    extra_cols.append(c)
                    continue
                key = (c.quantity, c.axis)
                if key in slots:
                    raise ConversionError(
                        path, f"two columns give {c.quantity} {c.axis or ''}: {slots[key].name!r} and {c.name!r}"
                    )
                slots[key] = c
            else:
                extra_cols.append(c)
        resolution: dict[str, dict[str, list[float]]] = {}
        for q in ("acc", "gyr", "mag"):
            axes = {a: slots.get((q, a)) for a in "xyz"}
            present = [a for a, c in axes.items() if c is not None]
            if not present:
                continue
            if len(present) != 3:
                missing = ", ".join(f"{q} {a}" for a, c in axes.items() if c is None)
                raise ConversionError(path, f"device {dev!r}: missing column(s) for {missing}")
            vec = streams[q] = np.empty((len(values), 3))
            for k, a in enumerate("xyz"):  # scaled straight into the (N, 3) array: no temporary per axis
                np.multiply(values[:, axes[a].index], axes[a].factor, out=vec[:, k])
            units[q] = axes["x"].unit
            factors = [float(axes[a].factor) for a in "xyz"]
            if any(f != 1.0 for f in factors):  # text * unit factor: the archive stores the text's numbers
                resolution[q] = {"scale": factors}
        if ("temperature", None) in slots:
            c = slots[("temperature", None)]
            streams["temperature"] = values[:, c.index] * c.factor
            units["temperature"] = c.unit
        if not streams and not extra_cols:
            continue
        if streams:
            meta = {
                "format": fmt,
                "model": device_meta.get("model", "Shimmer" if dev.startswith("shimmer") else ""),
                "serial": device_meta.get("serial", dev.split("_", 1)[1].upper() if dev.startswith("shimmer_") else ""),
                "rate_hz": rate_meta,
                "units": units,
                "time": time_desc,
                "source": path.name,
            }
            for k, v in device_meta.items():
                if k not in ("name",) and k not in meta:
                    meta[k] = v
            imu_meta = {**meta, "resolution": resolution} if resolution else dict(meta)
            rec.imus.append(ImuStream(name=dev, t_ns=t_ns, meta=imu_meta, **streams))
            rec.metadata[f"imulog.device.{dev}"] = meta
        if extra_cols:
            cols_out = []
            units_out = []
            data = []
            for c in extra_cols:
                conv = c.quantity in ("acc", "gyr", "mag", "temperature")
                cols_out.append(c.name)
                units_out.append(SI_UNIT[c.quantity] if conv else c.unit)
                data.append(values[:, c.index] * (c.factor if conv else 1.0))
            rec.signals.append(
                SignalStream(
                    topic=f"/signals/{dev}", t_ns=t_ns, columns=cols_out, units=units_out, values=np.column_stack(data)
                )
            )
    if not rec.imus and not rec.signals and not rec.markers:
        raise ConversionError(path, "no IMU or numeric columns found")
    return rec


def _marker_stream(path: Path, dev: str, cols: list[Column], values: np.ndarray, t_ns: np.ndarray) -> MarkerStream:
    """Marker columns (one per marker axis, from a mapping file) as one marker set, in m."""
    labels: list[str] = []
    axes: dict[tuple[str, str], Column] = {}
    for c in cols:
        if c.variant not in labels:
            labels.append(c.variant)
        if (c.variant, str(c.axis)) in axes:
            raise ConversionError(
                path,
                f"marker {c.variant!r} axis {c.axis}: two columns ({axes[(c.variant, str(c.axis))].name!r}, {c.name!r})",
            )
        axes[(c.variant, str(c.axis))] = c
    pos = np.full((len(values), len(labels), 3), np.nan)
    for m, label in enumerate(labels):
        missing = [a for a in "xyz" if (label, a) not in axes]
        if missing:
            raise ConversionError(
                path, f"marker {label!r}: no column for axis {', '.join(missing)} in the mapping file"
            )
        for k, a in enumerate("xyz"):
            c = axes[(label, a)]
            pos[:, m, k] = values[:, c.index] * c.factor
    return MarkerStream(name=dev, t_ns=t_ns, labels=labels, pos=pos, meta={"source": path.name})
