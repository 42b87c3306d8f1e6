"""Whole setups (issue 27), the steps after orientation: one line on the heading frame after orienting several
IMUs and in ``info``, kinematics' clock from the IMU's own alignment record, trajectories and evaluation per IMU,
and the batch's per-IMU steps.

Real files: the APDM Opal CSV with four sensors (Static, Upper, Middle, Lower), the gaitmap sample's two feet
with their markers; and the simulated setup (:mod:`imulog.simulate.setup`)."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.cli import cli


def run(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    return result.exit_code, result.stdout, result.stderr


@pytest.fixture
def opals(shared_data, tmp_path):
    path = tmp_path / "opals.mcap"
    code, _, stderr = run("convert", shared_data / "devices" / "apdm_csv" / "imuData01.csv", "-o", path)
    assert code == 0, stderr
    return path


def _heading_line(stdout: str) -> str:
    lines = [line for line in stdout.splitlines() if line.startswith("heading:")]
    assert len(lines) == 1, stdout
    return lines[0]


def test_orientation_says_whether_the_imus_share_one_heading_frame(opals):
    code, stdout, stderr = run("process", "orientation", opals)
    assert code == 0, stderr
    line = _heading_line(stdout)
    assert "not one frame yet for 4 IMUs" in line and "arbitrary heading" in line
    assert f"imulog process heading {opals}" in line
    code, stdout, _ = run("info", opals)  # no record yet: info says the headings do not relate
    assert code == 0 and "heading: not related between" in stdout and "run `imulog process heading`" in stdout
    # the magnetometers disagree on this file (one wanders by about 10 deg): the step finds no frame, and the
    # orientation command then says so and what would give one
    code, stdout, _ = run("process", "heading", opals)
    assert code == 0 and "no common heading" in stdout
    code, stdout, _ = run("process", "orientation", opals)
    line = _heading_line(stdout)
    assert stdout.count("unchanged") == 4 and "not shared by static, upper, middle, lower" in line
    assert "--static-pose START,END" in line
    # a declared pose relates them: the same command now reports one frame
    code, stdout, stderr = run("process", "heading", opals, "--static-pose", "0.2,1.0")
    assert code == 0, stderr
    code, stdout, _ = run("process", "orientation", opals)
    assert _heading_line(stdout).startswith("heading: one frame for static, upper, middle, lower: static pose")
    # re-orienting one IMU makes the record stale: the line no longer claims one frame
    code, stdout, _ = run("process", "orientation", opals, "--imu", "upper", "--imu", "lower", "--backend", "madgwick")
    assert code == 0 and "not one frame yet for 2 IMUs" in _heading_line(stdout)
    code, stdout, _ = run("process", "orientation", opals, "--imu", "upper")  # one IMU: no heading line
    assert code == 0 and "heading:" not in stdout


def test_kinematics_reads_the_arm_imus_own_alignment_record():
    """In a setup aligned as a whole, ``imulog.alignment`` is the first IMU's; the upper arm's clock is its own."""
    from imulog.steps.common import alignment_for, alignment_record
    from imulog.steps.kinematics import _reference_times

    first = {"imu": "/imu/forearm", "offset_ns": 5_000_000, "drift_ppm": 0.0}
    own = {"imu": "/imu/upper_arm", "offset_ns": -20_000_000, "drift_ppm": 0.0}

    class Trial:
        metadata = {"imulog.alignment": first, "imulog.alignment.upper_arm": own}

    t = np.arange(0, 10**9, 10**7, dtype=np.int64)
    assert alignment_record(Trial.metadata, "/imu/upper_arm") == "imulog.alignment.upper_arm"
    assert alignment_record(Trial.metadata, "/imu/forearm") == "imulog.alignment"
    assert alignment_for(Trial.metadata, "/imu/upper_arm")["offset_ns"] == -20_000_000
    shifted = _reference_times(Trial, "/imu/upper_arm", t)
    expected = _reference_times(type("T", (), {"metadata": {"imulog.alignment": own}}), "/imu/upper_arm", t)
    assert np.array_equal(shifted, expected) and not np.array_equal(shifted, t)
    assert np.array_equal(_reference_times(Trial, "/imu/trunk", t), t)  # no record for it: device clock
