"""One overwrite rule for every command that writes a file or folder: refused unless --overwrite, CLI wording."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from imulog.cli import cli

MESSAGE = "exists; add --overwrite to replace it"


def run(*args: str):
    return CliRunner().invoke(cli, [str(a) for a in args])


def refused(result, path) -> None:
    assert result.exit_code != 0, result.output
    assert f"{path} {MESSAGE}" in result.output, result.output
    assert "overwrite=True" not in result.output  # the Python API's wording stays out of the CLI


@pytest.mark.parametrize(
    ("name", "extra"),
    [
        ("wrist.parquet", ["--topic", "/imu/wrist"]),
        ("wrist.csv", ["--topic", "/imu/wrist"]),
        ("trial.sto", []),
        ("trial.c3d", []),
        ("bids", ["--to", "bids"]),
    ],
)
def test_every_export_refuses_an_existing_output(processed_r2g, tmp_path, name, extra):
    out = tmp_path / name
    if name == "bids":
        out.mkdir()
        (out / "keep.txt").write_text("mine")
    else:
        out.write_text("mine")
    refused(run("export", processed_r2g, "-o", out, *extra), out)
    assert (out / "keep.txt" if name == "bids" else out).read_text() == "mine"  # untouched
    result = run("export", processed_r2g, "-o", out, *extra, "--overwrite")
    assert result.exit_code == 0, result.output
    assert not (out / "keep.txt").exists() if name == "bids" else out.read_bytes() != b"mine"


def test_an_empty_folder_is_free_for_bids(processed_r2g, tmp_path):
    out = tmp_path / "bids"
    out.mkdir()
    assert run("export", processed_r2g, "--to", "bids", "-o", out).exit_code == 0


def test_view_save_convert_salvage_calibrate(processed_r2g, tmp_path, repo_root):
    rrd = tmp_path / "trial.rrd"
    rrd.write_text("mine")
    refused(run("view", processed_r2g, "--save", rrd), rrd)
    assert rrd.read_text() == "mine"
    assert run("view", processed_r2g, "--save", rrd, "--overwrite").exit_code == 0
    sim = repo_root / "recordings" / "sim"
    mcap = tmp_path / "t.mcap"
    mcap.write_text("mine")
    refused(run("convert", sim / "r2g_s00_t00_imu.csv", "-o", mcap), mcap)
    fixed = tmp_path / "fixed.mcap"
    fixed.write_text("mine")
    refused(run("salvage", processed_r2g, "-o", fixed), fixed)
    cal = tmp_path / "cal.json"
    cal.write_text("{}")
    refused(run("calibrate", sim / "r2g_s00_t00_imu.csv", "-o", cal), cal)


def test_convert_folder_mode_names_the_trial_in_cli_words(repo_root, tmp_path):
    out = tmp_path / "trials"
    out.mkdir()
    (out / "r2g_s00_t00.mcap").write_text("mine")
    result = run("convert", repo_root / "recordings" / "sim", "-o", out)
    assert result.exit_code != 0
    assert f"{out / 'r2g_s00_t00.mcap'} {MESSAGE}" in result.output and "overwrite=True" not in result.output


def test_simulate_refuses_only_the_files_it_would_write(tmp_path):
    out = tmp_path / "sim"
    out.mkdir()
    (out / "other_trial.csv").write_text("not ours")
    assert run("simulate", "slide", "-o", out, "--repetitions", "1", "--noise-free").exit_code == 0
    again = run("simulate", "slide", "-o", out, "--repetitions", "1", "--noise-free")
    assert again.exit_code != 0 and MESSAGE in again.output and "slide_s00_t00" in again.output
    assert run("simulate", "slide", "-o", out, "--repetitions", "1", "--trials", "2", "--overwrite").exit_code == 0
    assert (out / "other_trial.csv").read_text() == "not ours"


def test_demo_catalog_report(processed_r2g, tmp_path):
    demo = tmp_path / "demo"
    demo.mkdir()
    (demo / "notes.txt").write_text("mine")
    refused(run("demo", "-o", demo, "--no-view", "--no-open"), demo)
    result = run("demo", "-o", demo, "--no-view", "--no-open", "--overwrite")  # not an earlier demo: kept
    assert result.exit_code != 0 and "does not hold an earlier demo" in result.output
    assert (demo / "notes.txt").read_text() == "mine"
    # catalog: an existing catalog is updated (what the command is for); any other file is refused
    other = tmp_path / "table.parquet"
    other.write_text("not parquet")
    result = run("catalog", processed_r2g, "-o", other)
    assert result.exit_code != 0 and MESSAGE in result.output
    cat = tmp_path / "catalog.parquet"
    assert run("catalog", processed_r2g, "-o", cat, "-q").exit_code == 0
    again = run("catalog", processed_r2g, "-o", cat, "--json")
    assert again.exit_code == 0, again.output
    assert json.loads(again.output)["reused"] == 1  # updated: the row kept, the file not read again
    report = tmp_path / "report"
    report.mkdir()
    (report / "accuracy.md").write_text("mine")
    refused(run("report", cat, "-o", report, "--no-plots"), report)
    assert run("report", cat, "-o", report, "--no-plots", "--overwrite").exit_code == 0
