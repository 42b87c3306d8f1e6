"""A simulated arm trial written as a lab would have it (raw exports) and its ground truth saved and loaded (.npz + .json)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from imulog.process.kinematics.dh import JOINT_NAMES
from imulog.simulate import writers
from imulog.simulate.arm_params import ArmTrial, ArmTruth

TRUTH_FORMAT = "imulog.arm_truth/1"


_TRUTH_ARRAYS = ("t_ns", "q_rad", "r_upper_arm", "r_forearm", "elbow_m", "wrist_m", "q_world_trunk")


_TRUTH_DICTS = ("q_segment_to_sensor", "q_world_sensor", "imu_position_m")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def save_arm_truth(truth: ArmTruth, stem: Path | str) -> tuple[Path, Path]:
    """Write ``<stem>_truth.npz`` (arrays; per-IMU ones as ``<field>/<imu>``) and ``<stem>_truth.json``.

    Same file pair as :func:`imulog.simulate.truth.save_truth`, format ``imulog.arm_truth/1``:
    ``t_ns`` (common IMU/Vicon clock), ``q_rad`` (N, 5) true joint angles in
    ``joint_names`` order (rad), segment-to-trunk rotation matrices, elbow/wrist centres (m, trunk
    frame), trunk-to-world and per-IMU sensor-to-world quaternions (w,x,y,z), IMU positions (m)."""
    stem = Path(stem)
    npz = stem.with_name(stem.name + "_truth.npz")
    js = stem.with_name(stem.name + "_truth.json")
    arrays = {name: getattr(truth, name) for name in _TRUTH_ARRAYS}
    for name in _TRUTH_DICTS:
        for imu, value in getattr(truth, name).items():
            arrays[f"{name}/{imu}"] = np.asarray(value)
    np.savez_compressed(npz, **arrays)
    doc = {
        "format": TRUTH_FORMAT,
        "protocol": "arm",
        "arrays": npz.name,
        "joint_names": list(JOINT_NAMES),
        "units": {"t_ns": "ns", "q_rad": "rad", "elbow_m": "m", "wrist_m": "m", "imu_position_m": "m"},
        "info": truth.info,
    }
    js.write_text(json.dumps(doc, indent=1, default=_json_default) + "\n")
    return npz, js


def load_arm_truth(path: Path | str) -> ArmTruth:
    """Read :func:`save_arm_truth` files from ``<stem>_truth.json``, ``<stem>_truth.npz`` or the stem."""
    path = Path(path)
    for suffix in ("_truth.json", "_truth.npz"):
        if path.name.endswith(suffix):
            path = path.with_name(path.name[: -len(suffix)])
            break
    js = path.with_name(path.name + "_truth.json")
    if not js.is_file():
        raise FileNotFoundError(f"{js}: no ground-truth file")
    doc = json.loads(js.read_text())
    if doc.get("format") != TRUTH_FORMAT:
        raise ValueError(f"{js}: not an arm truth file (format {doc.get('format')!r}, expected {TRUTH_FORMAT!r})")
    with np.load(js.with_name(doc["arrays"])) as z:
        data: dict[str, Any] = {name: z[name] for name in _TRUTH_ARRAYS}
        for name in _TRUTH_DICTS:
            data[name] = {k.split("/", 1)[1]: z[k] for k in z.files if k.startswith(name + "/")}
    return ArmTruth(info=doc.get("info", {}), **data)


def write_arm_files(sim: ArmTrial, out_dir: Path | str, stem: str | None = None) -> dict[str, Path]:
    """Write the trial as raw exports + truth (module docstring); returns the paths by kind
    (``imu``, ``mapping``, ``vicon``, ``meta``, ``truth_npz``, ``truth``); sets ``recording.sources``.

    ``imulog convert`` of the folder (or of ``imu``, ``vicon`` with ``--meta-file meta``) gives
    back ``sim.recording``'s streams exactly (same samples, values and time stamps)."""
    if sim.raw is None:
        raise ValueError("this ArmTrial has no raw file values (simulate it with simulate_arm)")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = stem or sim.stem
    info = sim.truth.info.get("imu_params", {})
    device = {
        "name": "station",
        "model": "LSM9DS1 (simulated), cable-synchronised station",
        "rate_hz": sim.params.rate_hz,
        "acc_range_g": info.get("acc_range_g"),
        "gyr_range_dps": info.get("gyr_range_dps"),
    }
    paths: dict[str, Path] = {}
    paths["imu"], paths["mapping"] = writers.write_multi_imu_text(
        out / f"{stem}_imu.csv",
        sim.raw["t_ns"],
        sim.raw["channels"],
        {k: v for k, v in device.items() if v is not None},
    )
    vicon = sim.recording.markers[0]
    paths["vicon"] = writers.write_nexus_csv(
        out / f"{stem}_vicon.csv",
        vicon.pos,
        list(vicon.labels),
        float(vicon.meta["rate_hz"]),
        "",
        sim.raw["vicon_decimals"],
    )
    records = ("imulog.trial", "imulog.anthropometrics", "imulog.kinematics")
    meta = out / f"{stem}_meta.json"
    meta.write_text(json.dumps({k: sim.recording.metadata[k] for k in records}, indent=1) + "\n")
    paths["meta"] = meta
    paths["truth_npz"], paths["truth"] = save_arm_truth(sim.truth, out / stem)
    sim.recording.sources = [str(paths[k]) for k in ("imu", "mapping", "vicon")]
    return paths
