"""imulog's own C3D export read back: the IMU channels it writes as analogs (``{imu}_acc_x`` m/s^2, ``{imu}_gyr_x``
rad/s, ``{imu}_mag_x`` uT) come back as ``/imu/{imu}`` (converters/c3d_imus.py). Before, ``imulog convert`` gave
them only as ``/analog/vicon`` columns. The same names with other units in ``ANALOG:UNITS`` (another tool's
deg/s) stay analogs, with one warning line. Trial: ``imulog simulate arm`` (upper-arm and forearm IMUs at 100 Hz,
markers), 20 s, converted, exported to C3D on the IMUs' clock, converted again."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli

ezc3d = pytest.importorskip("ezc3d")
IMUS = ("upper_arm", "forearm")


def run(*args) -> tuple[str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.stdout, result.stderr


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("c3d_imus")
    run("simulate", "arm", "-o", tmp / "sim", "--set", "duration_s=20")
    sim = tmp / "sim" / "arm_s00_t00"
    run("convert", f"{sim}_imu.csv", f"{sim}_vicon.csv", "--meta-file", f"{sim}_meta.json", "-o", tmp / "t.mcap")
    run("export", tmp / "t.mcap", "-o", tmp / "t.c3d", "--clock", "device")
    return tmp


def imu_channels(path) -> dict:
    with TrialReader(path) as t:
        return {n: t.read(f"/imu/{n}") for n in IMUS if f"/imu/{n}" in t.topics()} | {"topics": t.topics()}


def test_the_imus_come_back_from_imulogs_c3d(exported):
    run("convert", exported / "t.c3d", "-o", exported / "back.mcap")
    before, after = imu_channels(exported / "t.mcap"), imu_channels(exported / "back.mcap")
    assert "/analog/vicon" not in after["topics"]  # the C3D held the IMUs' analogs only
    for n in IMUS:
        a, b = before[n], after[n]
        assert len(b.t_ns) == len(a.t_ns)
        for group in ("acc", "gyr", "mag"):  # the C3D's analogs are float32
            np.testing.assert_allclose(getattr(b, group), getattr(a, group), rtol=2**-23, atol=0)
        # on the C3D's frame clock: the same sample intervals within a microsecond
        assert np.max(np.abs((b.t_ns - b.t_ns[0]) - (a.t_ns - a.t_ns[0]))) < 1000
    with TrialReader(exported / "back.mcap") as t:
        assert t.metadata["imulog.device.forearm"]["units"] == {"acc": "m/s^2", "gyr": "rad/s", "mag": "uT"}


def test_pieces_give_the_whole_files_imus(exported, monkeypatch):
    """Converted in pieces of a few frames (the first piece declares each IMU's span, read from the data)."""
    import imulog.converters.c3d as c3d_conv

    assert len(list(c3d_conv.iter_c3d(exported / "t.c3d", piece_bytes=4096))) > 10
    monkeypatch.setenv("IMULOG_STREAM_MIN_BYTES", "1")
    monkeypatch.setattr(c3d_conv, "PIECE_BYTES", 4096)
    run("convert", exported / "t.c3d", "-o", exported / "pieces.mcap")
    whole, pieces = imu_channels(exported / "t.mcap"), imu_channels(exported / "pieces.mcap")
    for n in IMUS:
        assert len(pieces[n].t_ns) == len(whole[n].t_ns)
        np.testing.assert_allclose(pieces[n].gyr, whole[n].gyr, rtol=2**-23, atol=0)


def test_imu_names_in_other_units_stay_analogs_with_a_warning(exported):
    c = ezc3d.c3d(str(exported / "t.c3d"))
    labels = [str(x) for x in c["parameters"]["ANALOG"]["LABELS"]["value"]]
    units = [
        "deg/s" if "_gyr_" in lab else u
        for lab, u in zip(labels, c["parameters"]["ANALOG"]["UNITS"]["value"], strict=True)
    ]
    c["parameters"]["ANALOG"]["UNITS"]["value"] = units
    c.write(str(exported / "other.c3d"))
    _, err = run("convert", exported / "other.c3d", "-o", exported / "other.mcap")
    warned = [line for line in err.splitlines() if "named like imulog's IMU channels" in line]
    assert len(warned) == 2 and "upper_arm_gyr_x..z in 'deg/s', not rad/s" in warned[0] + warned[1], err
    after = imu_channels(exported / "other.mcap")
    assert not any(f"/imu/{n}" in after["topics"] for n in IMUS) and "/analog/vicon" in after["topics"]
