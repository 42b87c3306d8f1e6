"""A study's workflow on real files of several devices in one folder (the third user audit's walk through README,
docs/batch.md and docs/epochs.md): convert the folder, process epochs, gather the study's epoch table. Real
recordings of ../shared/data/devices: the Axivity AX6 .cwa, two Xsens MTw of one recording, the ActiGraph .gt3x
beside ActiLife's RAW export of it."""

from __future__ import annotations

import shutil

import pandas as pd
import pytest
from click.testing import CliRunner

from imulog.cli import cli


def run(*args) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


@pytest.fixture(scope="module")
def study(shared_data, tmp_path_factory):
    """The folder converted (one trial per recording) and epochs computed on every IMU by imulog batch."""
    root = tmp_path_factory.mktemp("study")
    raw = root / "raw"
    raw.mkdir()
    devices = shared_data / "devices"
    for f in (
        devices / "axivity_cwa/ax6_sample.cwa",
        devices / "actigraph_gt3x/example.gt3x",
        devices / "actigraph_gt3x/exampleRAW.csv",
        *sorted((devices / "xsens_mtmanager").glob("MT_012005D6_031-000_*.txt")),
    ):
        shutil.copy(f, raw)
    code, text, err = run("convert", raw, "-o", root / "archive")
    assert code == 0, err
    assert text.strip() == f"wrote 3 trial(s) to {root / 'archive'}"  # the RAW export is the .gt3x's recording
    code, text, err = run("batch", root / "archive", "--steps", "epochs", "--no-ledger")
    assert code == 0, text + err
    return root


def test_the_epoch_table_says_which_device_each_row_comes_from(study):
    """A study of several devices compares their epochs; the table had path, subject, trial and imu only, and
    the model and serial had to be looked up trial by trial."""
    out = study / "study_epochs.csv"
    code, text, err = run("catalog", study / "archive", "-o", study / "catalog.parquet", "--epochs", out)
    assert code == 0, err
    table = pd.read_csv(out)
    assert list(table.columns[:6]) == ["path", "subject", "trial", "imu", "device", "serial"]
    devices = table.groupby("imu")[["device", "serial"]].first()
    assert devices.loc["ax6_6011802"].tolist() == ["Axivity AX6", "6011802"]
    assert devices.loc["mt_00b421af"].tolist() == ["Xsens MT", "00B421AF"]
    assert devices.loc["tas1e31150129"].tolist() == ["ActiGraph Link", "TAS1E31150129"]
    assert table["device"].notna().all()
