"""Shared test fixtures: the real recordings in ../shared/data and temporary trial folders."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("IMULOG_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Folder of real public recordings (see ../shared/data/README.md); CI has it beside the clone."""
    if not SHARED_DATA.is_dir():
        pytest.fail(f"real recordings not found at {SHARED_DATA}; set IMULOG_SHARED_DATA")
    return SHARED_DATA


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO_ROOT


@pytest.fixture(scope="session")
def processed_r2g(tmp_path_factory) -> Path:
    """recordings/sim's R2G trial converted and processed (orientation, align, phases); do not modify it.

    Tests that change a trial copy it first (``shutil.copy``).
    """
    from click.testing import CliRunner

    from imulog.cli import cli
    from imulog.steps.align import run_align
    from imulog.steps.orientation import run_orientation
    from imulog.steps.phases import run_phases

    sim = REPO_ROOT / "recordings" / "sim"
    out = tmp_path_factory.mktemp("processed_r2g") / "r2g.mcap"
    args = ["convert", str(sim / "r2g_s00_t00_imu.csv"), str(sim / "r2g_s00_t00_vicon.csv"),
            "--meta-file", str(sim / "r2g_s00_t00_meta.json"), "-o", str(out)]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    run_orientation(out)
    run_align(out)
    run_phases(out)
    return out
