"""Write a simulated gait session (:mod:`imulog.simulate.gait`) as a lab has it: one Xsens MT Manager text file
per sensor (``MT_<master>_<trial>-000_<DeviceId>.txt``, the 2022 layout: a ``// Device information`` header with
the DeviceId, tab-separated PacketCounter, SampleTimeFine, Acc, Gyr, Mag, Quat), the Vicon ``.c3d`` of the
session (points in mm; ezc3d, the ``c3d`` extra) and the truth (``<stem>_truth.json``: clock, sensors, markers
per segment, stances; ``<stem>_truth.npz``: every IMU's true position and orientation on the marker frames).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from imulog.process import quaternion as quat
from imulog.simulate.gait import MARKERS, MASTER, SEGMENTS, SERIALS, GaitParams, GaitSession, imu_lever, simulate_gait

_HEADER = """// General information:
//  MT Manager version: 2022.2.0
//  XDA version: 2022.2.0 build 7381 rev 124627 built on 2023-07-19
// Device information:
//  DeviceId: {serial}
//  ProductCode: MTW2-3A7G6
//  Firmware Version: 4.4.0
//  Hardware Version: 1.1.0
// Device settings:
//  Filter Profile: human(46.1)
//  Option Flags: Orientation Smoother Disabled, Position/Velocity Smoother Disabled, Continuous Zero Rotation Update Disabled, AHS Disabled, ICC Disabled
// Coordinate system: ENU
"""  # noqa: E501
_COLUMNS = ["PacketCounter", "SampleTimeFine"] + [f"{q}_{a}" for q in ("Acc", "Gyr", "Mag") for a in "XYZ"]
_COLUMNS += [f"Quat_q{i}" for i in range(4)]


def write_xsens(session: GaitSession, out_dir: Path, trial: str = "003") -> list[Path]:
    """One MT Manager text file per IMU; the station's PacketCounter and SampleTimeFine are shared."""
    paths = []
    for seg in SEGMENTS:
        d = session.imu[seg]
        ticks = np.round(d["t_dev_s"] * 10_000).astype(np.int64)
        counter = (1234 + np.arange(len(ticks))) % 65536
        body = np.column_stack([d["acc"], d["gyr"], d["mag"], d["quat"]])
        lines = [_HEADER.format(serial=SERIALS[seg]).rstrip("\n"), "\t".join(_COLUMNS)]
        for c, tk, row in zip(counter, ticks, body, strict=True):
            lines.append(f"{c:05d}\t{tk}\t" + "\t".join(f"{v:.6f}" for v in row))
        path = out_dir / f"MT_{MASTER}_{trial}-000_{SERIALS[seg]}.txt"
        path.write_text("\n".join(lines) + "\n")
        paths.append(path)
    return paths


def write_c3d(session: GaitSession, path: Path) -> Path:
    """The markers as a Vicon C3D (mm, ``POINT:RATE`` the marker rate, gaps as residual -1)."""
    import ezc3d

    c = ezc3d.c3d()
    rate = session.params.marker_rate_hz
    pos_mm = session.marker_pos * 1000.0  # (F, M, 3)
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(session.marker_labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    pts = np.ones((4, pos_mm.shape[1], pos_mm.shape[0]))
    pts[:3] = np.transpose(pos_mm, (2, 1, 0))
    c["data"]["points"] = pts
    invalid = ~np.isfinite(pos_mm).all(axis=2)
    res = np.where(invalid, -1.0, 0.8)
    c["data"]["meta_points"] = {"residuals": res.T[None], "camera_masks": np.zeros((7, *res.T.shape), bool)}
    c.write(str(path))
    return path


def imu_truth_on_markers(session: GaitSession) -> dict[str, np.ndarray]:
    """Per IMU its true position (m) and orientation (IMU to world) at the marker frames' reference times."""
    out = {}
    t = session.t_s
    for seg in SEGMENTS:
        p = session.p_seg[seg] + quat.rotate(session.q_seg[seg], imu_lever(seg))
        q = quat.multiply(session.q_seg[seg], session.q_mount[seg])
        out[f"{seg}_pos"] = np.column_stack([np.interp(session.marker_t_s, t, p[:, j]) for j in range(3)])
        out[f"{seg}_quat"] = quat.normalize(
            np.column_stack([np.interp(session.marker_t_s, t, q[:, j]) for j in range(4)])
        )
    return out


def write_gait_session(
    out_dir: Path | str, *, seed: int = 0, params: GaitParams | None = None, stem: str = "walk03"
) -> dict[str, Path | list[Path]]:
    """Simulate and write the session into ``out_dir`` (created): the 11 Xsens files, ``<stem>.c3d`` and the
    truth files. Returns their paths (``xsens``, ``c3d``, ``truth_json``, ``truth_npz``)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s = simulate_gait(params, seed=seed)
    xs = write_xsens(s, out)
    c3d = write_c3d(s, out / f"{stem}.c3d")
    truth = {
        "clock": s.clock,
        "imu_rate_hz": s.params.imu_rate_hz,
        "marker_rate_hz": s.params.marker_rate_hz,
        "sensors": {
            seg: {
                "serial": SERIALS[seg],
                "stream": f"mt_{SERIALS[seg].lower()}",
                "markers": list(MARKERS[seg]),
                "rotation_imu_to_segment": s.q_mount[seg].tolist(),
                "lever_arm_m": imu_lever(seg).tolist(),
            }
            for seg in SEGMENTS
        },
        "stances": s.stances,
        "lab_yaw_deg": s.params.lab_yaw_deg,
        "note": "IMU times: SampleTimeFine / 10 kHz on the station clock; markers on the C3D's clock",
    }
    tj = out / f"{stem}_truth.json"
    tj.write_text(json.dumps(truth, indent=1))
    tn = out / f"{stem}_truth.npz"
    np.savez_compressed(tn, marker_t_s=s.marker_t_s, **imu_truth_on_markers(s))
    return {"xsens": xs, "c3d": c3d, "truth_json": tj, "truth_npz": tn}
