"""A device file and its vendor's export side by side are one recording: ``imulog convert FOLDER`` makes one trial
of the device file and skips the export with one line naming it (docs/converters.md, "One trial per recording").
On the real folders of ../shared/data/devices: NilsPod (the ``.bin`` and NilsPodLib's ``_data.csv`` decode of it;
two trials before) and ActiGraph (``example.gt3x`` and ActiLife's ``exampleRAW.csv``, ``example-IMU.csv``; three
before); Axivity: no real ``.cwa`` and OMGUI CSV of one recording is in the shared data, so the pair is built the way
OMGUI names it (``X.csv`` beside ``X.cwa``) from the reference decode of the real AX6 file (two trials before). Converting an export by name still works (a cross-check of the two decodes), and an export without its
device file beside it is converted as before."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from imulog.converters.registry import group_directory

from imulog.archive import TrialReader
from imulog.cli import cli

NILSPOD = "devices/nilspod"
STEM = "NilsPodX-6F13_20210109_162824"


def run(*args: str | Path) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


@pytest.mark.parametrize(
    ("folder", "device_file", "exports"),
    [
        (NILSPOD, f"{STEM}.bin", [f"{STEM}_data.csv"]),
        ("devices/actigraph_gt3x", "example.gt3x", ["example-IMU.csv", "exampleRAW.csv"]),
    ],
)
def test_a_folder_with_a_device_file_and_its_export_is_one_trial(shared_data, tmp_path, folder, device_file, exports):
    out = tmp_path / "out"
    code, text, err = run("convert", shared_data / folder, "-o", out)
    assert code == 0, err
    assert text.strip() == "wrote 1 trial(s) to " + str(out)
    (trial,) = sorted(out.glob("*.mcap"))
    assert trial.name == Path(device_file).stem + ".mcap"
    with TrialReader(trial) as reader:
        assert reader.metadata["imulog.conversion"]["inputs"] == [device_file]
    skipped = [line for line in err.splitlines() if line.startswith("skipped ")]
    assert len(skipped) == len(exports), err
    for line, name in zip(skipped, exports, strict=True):
        assert line.startswith(f"skipped {shared_data / folder / name}: an export of {device_file} beside it")
        assert f"convert {name} by name" in line
    code, text, _ = run("convert", shared_data / folder, "-o", tmp_path / "json", "--json")
    doc = json.loads(text)
    assert code == 0 and len(doc["trials"]) == 1
    assert sorted(Path(s["path"]).name for s in doc["skipped"]) == sorted(exports)


def test_the_export_by_name_and_alone_still_converts(shared_data, tmp_path):
    csv = shared_data / NILSPOD / f"{STEM}_data.csv"
    code, _, err = run("convert", csv, "-o", tmp_path / "csv.mcap")
    assert code == 0, err
    alone = tmp_path / "alone"
    alone.mkdir()
    for suffix in ("_data.csv", "_header.json"):
        shutil.copy(shared_data / NILSPOD / f"{STEM}{suffix}", alone)
    groups = group_directory(alone)
    assert [[p.name for p in files] for _, files in groups] == [[f"{STEM}_data.csv"]]
    with TrialReader(tmp_path / "csv.mcap") as by_name:
        assert by_name.metadata["imulog.conversion"]["inputs"][0] == f"{STEM}_data.csv"


def omgui_csv(npz: Path, out: Path) -> None:
    """The CSV OMGUI's "Export raw CSV" writes (formatted device-clock stamps, acc g, gyro deg/s; no header), from
    the reference decode of the .cwa (scikit-digital-health's, beside the file)."""
    import datetime as dt

    import numpy as np

    ref = np.load(npz)
    with out.open("w") as f:
        for t, acc, gyr in zip(ref["time"], ref["accel"], ref["gyro"], strict=True):
            stamp = dt.datetime.fromtimestamp(float(t), dt.UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3]
            f.write(stamp + "," + ",".join(f"{v:.6f}" for v in (*acc, *gyr)) + "\n")


def test_an_omgui_csv_beside_its_cwa_is_one_trial(shared_data, tmp_path):
    """``ax6_sample.cwa`` and OMGUI's export of it, ``ax6_sample.csv``: before, two trials (the CSV a second
    recording); now one, from the .cwa, and the export skipped with the one line; by name the CSV still converts and
    decodes to the same samples (times within the CSV's 1 ms) and start time (the cross-check the line
    offers)."""
    folder = tmp_path / "ax6"
    folder.mkdir()
    shutil.copy(shared_data / "devices/axivity_cwa/ax6_sample.cwa", folder)
    omgui_csv(shared_data / "devices/axivity_cwa/ax6_data.npz", folder / "ax6_sample.csv")
    out = tmp_path / "out"
    code, text, err = run("convert", folder, "-o", out)
    assert code == 0, err
    assert text.strip() == f"wrote 1 trial(s) to {out}"
    assert sorted(p.name for p in out.iterdir()) == ["ax6_sample.mcap"]
    skipped = [line for line in err.splitlines() if line.startswith("skipped ")]
    assert skipped == [
        f"skipped {folder / 'ax6_sample.csv'}: an export of ax6_sample.cwa beside it (Axivity AX3/AX6 CSV export): "
        "one recording, converted from ax6_sample.cwa; convert ax6_sample.csv by name to compare the two decodes"
    ], err
    code, _, err = run("convert", folder / "ax6_sample.csv", "-o", tmp_path / "csv.mcap")
    assert code == 0, err
    with TrialReader(out / "ax6_sample.mcap") as cwa, TrialReader(tmp_path / "csv.mcap") as csv:
        a, b = cwa.read("/imu/ax6_6011802"), csv.read("/imu/axivity")
        assert cwa.metadata["imulog.trial"]["start_time"] == csv.metadata["imulog.trial"]["start_time"]
    assert (
        abs(a.t_ns - b.t_ns).max() < 1_000_000 and abs(a.acc - b.acc).max() < 1e-5 and abs(a.gyr - b.gyr).max() < 1e-5
    )


def test_axivity_csvs_that_are_not_a_cwas_export_still_convert(shared_data, tmp_path):
    """The rule is OMGUI's name: the real AX3 CSV (GGIR's test file, another recording than ``ax3_sample.cwa``:
    2019 at 100 Hz against 2020 at 200 Hz) beside the .cwa under its own name is a trial of its own; the device's
    upper-case ``CWA-DATA.CWA`` beside ``CWA-DATA.csv`` is a pair."""
    folder = tmp_path / "ax3"
    folder.mkdir()
    shutil.copy(shared_data / "devices/axivity_cwa/ax3_sample.cwa", folder)
    shutil.copy(shared_data / "devices/axivity_csv/ax3_testfile_unix_timestamps.csv", folder)
    skipped: list = []
    groups = group_directory(folder, skipped)
    assert sorted(p.name for _, files in groups for p in files) == [
        "ax3_sample.cwa",
        "ax3_testfile_unix_timestamps.csv",
    ]
    assert skipped == []
    (folder / "ax3_sample.cwa").rename(folder / "CWA-DATA.CWA")
    (folder / "ax3_testfile_unix_timestamps.csv").rename(folder / "CWA-DATA.csv")
    groups = group_directory(folder, skipped)
    assert [[p.name for p in files] for _, files in groups] == [["CWA-DATA.CWA"]]
    assert [p.name for p, _ in skipped] == ["CWA-DATA.csv"]


def test_convert_and_inspect_name_a_skipped_file_with_the_same_line(shared_data, tmp_path):
    """``convert FOLDER`` printed ``skipped X: reason`` on stderr and ``convert --inspect FOLDER`` ``X: skipped:
    reason`` on stdout; both now print the one line (``convert_common.echo_skipped``), on stderr beside the
    warnings, and their ``--json`` the same records (real NilsPod folder)."""
    folder = shared_data / NILSPOD
    code, _, converted = run("convert", folder, "-o", tmp_path / "out")
    assert code == 0, converted
    code, report, inspected = run("convert", "--inspect", folder)
    assert code == 0, inspected
    line = f"skipped {folder / (STEM + '_data.csv')}: an export of {STEM}.bin beside it (NilsPod"
    for err in (converted, inspected):
        assert [x for x in err.splitlines() if "skipped" in x][0].startswith(line), err
    assert "skipped" not in report  # the report on stdout describes what converts
    as_json = [
        json.loads(run("convert", *args, folder, "--json")[1])["skipped"]
        for args in (["-o", tmp_path / "json"], ["--inspect"])
    ]
    assert as_json[0] == as_json[1] and len(as_json[0]) == 1
