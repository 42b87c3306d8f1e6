"""Xsens MVN .mvnx (XML version 4): no redistributable sample exists, so the file is written here in the published
MVNX 4 layout (element and attribute names as Xsens' own load_mvnx reads them) and the stored values compared."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, ConvertOptions, convert_file, detect

from imulog.archive import TrialReader, check_file
from imulog.cli import cli

SEGMENTS = ["Pelvis", "T8", "RightUpperArm", "RightForeArm", "RightHand"]
SENSORS = ["Pelvis", "RightForeArm"]
JOINTS = ["jT9T8", "jRightShoulder", "jRightElbow", "jRightWrist"]


def fmt(a: np.ndarray) -> str:
    return " ".join(f"{v:.6f}" for v in a.ravel())


def write_mvnx(path: Path, n: int = 30, rate: int = 60) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(11)
    q = rng.normal(0, 1, (n, len(SEGMENTS), 4))
    q /= np.linalg.norm(q, axis=2, keepdims=True)
    pos = rng.normal(0, 1, (n, len(SEGMENTS), 3))
    sq = rng.normal(0, 1, (n, len(SENSORS), 4))
    sq /= np.linalg.norm(sq, axis=2, keepdims=True)
    free = rng.normal(0, 2, (n, len(SENSORS), 3))
    mag = rng.normal(0, 1, (n, len(SENSORS), 3))
    ja = rng.normal(0, 40, (n, len(JOINTS), 3))
    t_ms = np.round(np.arange(n) * 1000 / rate).astype(int)
    out = [
        '<?xml version="1.0" encoding="UTF-8" standalone="no"?>',
        '<mvnx version="4" xmlns="http://www.xsens.com/mvn/mvnx">',
        '<mvn version="2021.0.1" build="1"/>',
        "<comment></comment>",
        f'<subject label="Subject 1" torsoColor="#ea6852" frameRate="{rate}" segmentCount="{len(SEGMENTS)}" '
        'recDate="Tue Mar 03 14:08:49.271 2020" recDateMSecsSinceEpoch="1583240929271" '
        'originalFilename="C:/Users/someone/reach.mvn" configuration="FullBody" userScenario="noLevel" '
        'processingQuality="HD">',
        "<segments>",
    ]
    for i, s in enumerate(SEGMENTS, 1):
        out.append(
            f'<segment label="{s}" id="{i}"><points><point label="p{s}"><pos_b>0 0 0</pos_b></point></points></segment>'
        )
    out += ["</segments>", "<sensors>", *(f'<sensor label="{s}"/>' for s in SENSORS), "</sensors>", "<joints>"]
    out += [f'<joint label="{j}"><connector1>a/{j}</connector1><connector2>b/{j}</connector2></joint>' for j in JOINTS]
    out += ["</joints>", f'<frames segmentCount="{len(SEGMENTS)}" sensorCount="{len(SENSORS)}" jointCount="4">']
    for kind in ("identity", "tpose", "tpose-isb"):  # calibration poses, not samples
        out.append(
            f'<frame time="0" tc="" ms="" type="{kind}"><orientation>{fmt(q[0])}</orientation>'
            f"<position>{fmt(pos[0] * 0)}</position></frame>"
        )
    for i in range(n):
        out.append(
            f'<frame time="{t_ms[i]}" index="{i}" tc="00:00:00:{i:02d}" ms="{1583240929271 + t_ms[i]}" type="normal">'
            f"<orientation>{fmt(q[i])}</orientation><position>{fmt(pos[i])}</position>"
            f"<velocity>{fmt(pos[i])}</velocity>"
            f"<sensorFreeAcceleration>{fmt(free[i])}</sensorFreeAcceleration>"
            f"<sensorMagneticField>{fmt(mag[i])}</sensorMagneticField>"
            f"<sensorOrientation>{fmt(sq[i])}</sensorOrientation>"
            f"<jointAngle>{fmt(ja[i])}</jointAngle><jointAngleXZY>{fmt(ja[i][:, ::-1])}</jointAngleXZY>"
            "<centerOfMass>0 0 1 0 0 0 0 0 0</centerOfMass></frame>"
        )
    out += ["</frames>", "</subject>", '<securityCode code="abc"/>', "</mvnx>"]
    path.write_text("\n".join(out) + "\n")
    r = lambda a: np.round(a, 6)  # noqa: E731 - as printed
    return {"t_ms": t_ms, "q": r(q), "pos": r(pos), "sq": r(sq), "free": r(free), "mag": r(mag), "ja": r(ja)}


def test_mvnx_streams_match_the_written_file(tmp_path):
    path = tmp_path / "reach-001.mvnx"
    truth = write_mvnx(path)
    assert detect(path).name == "mvnx"
    rec = convert_file(path, options=ConvertOptions(extra={"names": {"RIGHTFOREARM": "right_forearm"}}))
    assert not rec.imus  # MVNX has no raw accelerometer or gyroscope samples
    poses = {p.topic: p for p in rec.poses}
    assert list(poses) == [f"/poses/mvn_{s.lower()}" for s in SEGMENTS]
    fore = poses["/poses/mvn_rightforearm"]
    np.testing.assert_array_equal(fore.position, truth["pos"][:, 3])
    np.testing.assert_array_equal(fore.orientation, truth["q"][:, 3])  # q0 = w first
    np.testing.assert_array_equal(fore.t_ns, truth["t_ms"] * 1_000_000)  # frame time in ms; calibration frames out
    signals = {s.topic: s for s in rec.signals}
    np.testing.assert_array_equal(signals["/orientation/right_forearm"].values, truth["sq"][:, 1])
    sensor = signals["/signals/right_forearm"]
    assert sensor.columns[:3] == ["free_acc_x", "free_acc_y", "free_acc_z"] and sensor.units[0] == "m/s^2"
    np.testing.assert_array_equal(sensor.values[:, :3], truth["free"][:, 1])
    np.testing.assert_array_equal(sensor.values[:, 3:], truth["mag"][:, 1])
    angles = signals["/signals/mvn_joint_angles"]
    assert angles.columns[3:6] == ["jRightShoulder_x", "jRightShoulder_y", "jRightShoulder_z"]
    assert set(angles.units) == {"deg"}
    np.testing.assert_array_equal(angles.values.reshape(-1, 4, 3), truth["ja"])
    assert "/signals/mvn_joint_angles_xzy" in signals
    # 1583240929271 ms = 2020-03-03T13:08:49.271Z; recDate says 14:08:49.271 local: +01:00
    trial = rec.metadata["imulog.trial"]
    assert trial["start_time"] == "2020-03-03T14:08:49.271000+01:00" and trial["time_zone"] == "+01:00"
    meta = rec.metadata["imulog.device.mvn"]
    assert meta["segments"] == SEGMENTS and meta["rate_hz"] == 60.0 and meta["mvnx_version"] == "4"
    assert "originalFilename" not in meta["subject"]  # it names the operator's PC folder

    out = tmp_path / "reach.mcap"
    result = CliRunner().invoke(cli, ["convert", str(path), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert check_file(out).ok
    with TrialReader(out) as t:
        np.testing.assert_array_equal(t.read("/poses/mvn_pelvis").position, truth["pos"][:, 0])


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda s: s[: len(s) * 2 // 3], r"line \d+: XML error: no element found"),
        (
            lambda s: s.replace("<jointAngle>", "<jointAngle>1 ", 1),
            r"frame 0 .*<jointAngle> has 13 values, expected 12",
        ),
        (lambda s: s.replace('time="50"', 'time="oops"'), r"frame 3 \(time 'oops'\): time attribute is not a number"),
        (lambda s: s.replace('time="50"', 'time="16"'), r"frame 3: time 16.0 ms does not increase"),
    ],
)
def test_damaged_mvnx(tmp_path, damage, message):
    good = tmp_path / "good.mvnx"
    write_mvnx(good)
    bad = tmp_path / "bad.mvnx"
    bad.write_text(damage(good.read_text()))
    with pytest.raises(ConversionError, match=message):
        convert_file(bad)
