"""Ground truth of a simulated trial and its files (``<stem>_truth.npz`` + ``<stem>_truth.json``)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from imulog.model import Intervals

ARRAYS = (
    "t_ns",
    "position",
    "velocity",
    "acceleration",
    "orientation",
    "angular_velocity",
    "static_mask",
    "imu_t_ref_ns",
    "imu_t_dev_ns",
    "imu_position",
    "imu_velocity",
    "imu_orientation",
    "imu_angular_velocity",
    "imu_static_mask",
    "imu_dropped_t_dev_ns",
)


@dataclass
class GroundTruth:
    """True state of a simulated trial, all on the reference (Vicon) clock and in the world frame.

    ``t_ns`` is the Vicon frame grid (frame k at ``(k-1)/rate``); ``position`` (N, 3) m of the
    IMU/cluster origin, ``velocity`` m/s, ``acceleration`` m/s^2 (world, gravity excluded),
    ``orientation`` (N, 4) w,x,y,z sensor-to-world, ``angular_velocity`` (N, 3) rad/s in the
    sensor frame, ``static_mask`` True where the wrist is exactly still. The ``imu_*`` arrays hold
    the same at every recorded IMU sample: ``imu_t_ref_ns`` its exact reference time (rounded
    to ns), ``imu_t_dev_ns`` its device time stamp. ``phases`` has the task phases (labels and
    ``task_index`` as in conventions.md), ``events`` the protocol's other intervals (opening
    static, wave...). ``alignment`` is the true ``imulog.alignment`` record.
    """

    protocol: str
    t_ns: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    orientation: np.ndarray
    angular_velocity: np.ndarray
    static_mask: np.ndarray
    phases: Intervals
    events: Intervals
    alignment: dict[str, Any]
    imu_t_ref_ns: np.ndarray
    imu_t_dev_ns: np.ndarray
    imu_position: np.ndarray
    imu_velocity: np.ndarray
    imu_orientation: np.ndarray
    imu_angular_velocity: np.ndarray
    imu_static_mask: np.ndarray
    imu_dropped_t_dev_ns: np.ndarray
    anthropometrics: dict[str, Any] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)  # parameters, device errors, magnetic field...

    def interpolate(self, t_ref_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position (m) and normalised-lerp orientation at reference times (ns) from the 100 Hz grid
        (position error below ~0.05 mm for the simulated movements)."""
        t = np.asarray(t_ref_ns, dtype=np.float64)
        base = self.t_ns.astype(np.float64)
        pos = np.column_stack([np.interp(t, base, self.position[:, k]) for k in range(3)])
        q = np.column_stack([np.interp(t, base, self.orientation[:, k]) for k in range(4)])
        return pos, q / np.linalg.norm(q, axis=1, keepdims=True)


def _hermite(t: np.ndarray, tk: np.ndarray, y: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolation of samples ``y`` with derivatives ``dy`` at ``tk`` (s)."""
    i = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, len(tk) - 2)
    h = (tk[i + 1] - tk[i])[:, None]
    u = ((t - tk[i])[:, None]) / h
    h00 = 2 * u**3 - 3 * u**2 + 1
    h10 = u**3 - 2 * u**2 + u
    h01 = -2 * u**3 + 3 * u**2
    h11 = u**3 - u**2
    return h00 * y[i] + h10 * h * dy[i] + h01 * y[i + 1] + h11 * h * dy[i + 1]


def _interpolate_imu_kinematics(data: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    tk = data["t_ns"].astype(np.float64) / 1e9
    t = data["imu_t_ref_ns"].astype(np.float64) / 1e9
    zero_acc = np.zeros_like(data["acceleration"])
    q = np.column_stack([np.interp(t, tk, data["orientation"][:, k]) for k in range(4)])
    return {
        "imu_position": _hermite(t, tk, data["position"], data["velocity"]),
        "imu_velocity": _hermite(t, tk, data["velocity"], data["acceleration"])
        if "acceleration" in data
        else _hermite(t, tk, data["velocity"], zero_acc),
        "imu_orientation": q / np.linalg.norm(q, axis=1, keepdims=True),
        "imu_angular_velocity": np.column_stack([np.interp(t, tk, data["angular_velocity"][:, k]) for k in range(3)]),
    }


def _intervals_to_json(iv: Intervals) -> list[dict[str, Any]]:
    return [
        {"label": lab, "start_ns": int(s), "end_ns": int(e), "task_index": int(k)}
        for lab, s, e, k in zip(iv.labels, iv.start_ns, iv.end_ns, iv.task_index, strict=True)
    ]


def _intervals_from_json(topic: str, rows: list[dict[str, Any]]) -> Intervals:
    return Intervals(
        topic=topic,
        start_ns=np.array([r["start_ns"] for r in rows], dtype=np.int64),
        end_ns=np.array([r["end_ns"] for r in rows], dtype=np.int64),
        labels=[r["label"] for r in rows],
        task_index=np.array([r["task_index"] for r in rows], dtype=np.int64),
    )


IMU_KINEMATICS = ("imu_position", "imu_velocity", "imu_orientation", "imu_angular_velocity")


def save_truth(truth: GroundTruth, stem: Path | str, *, compact: bool = False) -> tuple[Path, Path]:
    """Write ``<stem>_truth.npz`` (arrays) and ``<stem>_truth.json`` (intervals, alignment, info).

    ``compact`` leaves out the per-IMU-sample kinematics; :func:`load_truth` then rebuilds them from
    the 100 Hz arrays (cubic Hermite for position and velocity: error below 1 um for the simulated
    movements; normalised lerp for orientation) -- used for the small files in ``recordings/``."""
    stem = Path(stem)
    npz = stem.with_name(stem.name + "_truth.npz")
    js = stem.with_name(stem.name + "_truth.json")
    names = [n for n in ARRAYS if not (compact and n in IMU_KINEMATICS)]
    arrays = {name: getattr(truth, name) for name in names}
    if compact:  # derivatives and orientation in float32 (relative precision 6e-8); positions stay float64
        for name in ("velocity", "acceleration", "orientation", "angular_velocity"):
            arrays[name] = arrays[name].astype(np.float32)
    np.savez_compressed(npz, **arrays)
    doc = {
        "format": "imulog.truth/1",
        "protocol": truth.protocol,
        "arrays": npz.name,
        "imu_kinematics": "interpolated" if compact else "exact",
        "alignment": truth.alignment,
        "phases": _intervals_to_json(truth.phases),
        "events": _intervals_to_json(truth.events),
        "anthropometrics": truth.anthropometrics,
        "info": truth.info,
    }
    js.write_text(json.dumps(doc, indent=1, default=_json_default) + "\n")
    return npz, js


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def load_truth(path: Path | str) -> GroundTruth:
    """Read a ground truth from ``<stem>_truth.json``, ``<stem>_truth.npz`` or the stem itself."""
    path = Path(path)
    name = path.name
    for suffix in ("_truth.json", "_truth.npz"):
        if name.endswith(suffix):
            path = path.with_name(name[: -len(suffix)])
            break
    js = path.with_name(path.name + "_truth.json")
    if not js.is_file():
        raise FileNotFoundError(f"{js}: no ground-truth file")
    doc = json.loads(js.read_text())
    with np.load(js.with_name(doc["arrays"])) as arrays:
        data = {
            name: (arrays[name].astype(np.float64) if arrays[name].dtype == np.float32 else arrays[name])
            for name in ARRAYS
            if name in arrays.files
        }
    if any(name not in data for name in IMU_KINEMATICS):
        data.update(_interpolate_imu_kinematics(data))
    return GroundTruth(
        protocol=doc["protocol"],
        phases=_intervals_from_json("/truth/phases", doc["phases"]),
        events=_intervals_from_json("/truth/events", doc["events"]),
        alignment=doc["alignment"],
        anthropometrics=doc.get("anthropometrics", {}),
        info=doc.get("info", {}),
        **data,
    )
