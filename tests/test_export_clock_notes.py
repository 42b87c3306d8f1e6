"""Every export words an unaligned IMU's time stamps the same way (:func:`imulog.archive.trial_clock.not_aligned_note`,
through ``TrialClock.export_notes``). Before, the ``.sto`` export said "the 3 IMUs share the clock of one recording
(...): exported as recorded" while the C3D export of the same trial said, per channel, "/imu/forearm: IMU 'forearm'
is not aligned; its time stamps are exported as recorded", and never whether the IMUs share a clock. Trial: the
simulated station (:func:`imulog.simulate.setup.simulate_setup`: upper arm, forearm and trunk IMUs of one source
file, markers), not aligned, exported on the upper arm's device clock."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from imulog.archive import write_trial
from imulog.cli import cli
from imulog.simulate.setup import simulate_setup


def notes(*args) -> list[str]:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return [line.removeprefix("note: ") for line in result.stderr.splitlines() if line.startswith("note: ")]


@pytest.fixture(scope="module", params=["one recording", "trunk of its own"])
def trial(request, tmp_path_factory):
    sim = simulate_setup(seed=0, duration_s=10.0)
    if request.param == "trunk of its own":
        trunk = next(s for s in sim.recording.imus if s.name == "trunk")
        sim.recording.metadata["imulog.device.trunk"]["source"] = trunk.meta["source"] = "trunk_imu.csv"
    path = write_trial(tmp_path_factory.mktemp("notes") / "t.mcap", sim.recording, attach_sources=False)
    assert CliRunner().invoke(cli, ["process", "orientation", str(path)]).exit_code == 0
    return request.param, path


def test_c3d_sto_and_tables_say_the_same_of_unaligned_imus(trial, tmp_path):
    kind, path = trial
    source = "arm_s00_t00_imu.csv"
    common = ["--clock", "device", "--imu", "upper_arm"]
    c3d = notes("export", path, "-o", tmp_path / "t.c3d", *common)
    sto = notes("export", path, "-o", tmp_path / "t.sto", *common)
    csv = notes("export", path, "-t", "/imu/trunk", "-o", tmp_path / "t.csv", *common)
    if kind == "one recording":
        line = f"IMUs 'forearm', 'trunk' are not aligned: exported as recorded, on the clock of recording {source!r}, "
        expected = [line + "'upper_arm''s too"]
        trunk = [
            f"IMU 'trunk' is not aligned: exported as recorded, on the clock of recording {source!r}, "
            + ("'upper_arm''s too")
        ]
    else:
        expected = [
            f"IMU 'forearm' is not aligned: exported as recorded, on the clock of recording {source!r}, 'upper_arm''s too",
            "IMU 'trunk' is not aligned: exported as recorded, on its own device clock, which may differ from "
            "'upper_arm''s (no shared recording in the device records)",
        ]
        trunk = expected[1:]
    unaligned = [n for n in c3d if "not aligned" in n]
    assert unaligned == expected, c3d
    assert [n for n in sto if "not aligned" in n] == expected, sto
    assert [n for n in csv if "not aligned" in n] == trunk, csv
