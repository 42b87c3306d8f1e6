"""A device file and its vendor's export side by side are one recording: ``imulog convert FOLDER`` makes one trial
of the device file and skips the export with one line naming it (docs/converters.md, "One trial per recording").
On the real folders of ../shared/data/devices: NilsPod (the ``.bin`` and NilsPodLib's ``_data.csv`` decode of it;
two trials before) and ActiGraph (``example.gt3x`` and ActiLife's ``exampleRAW.csv``, ``example-IMU.csv``; three
before). Converting an export by name still works (a cross-check of the two decodes), and an export without its
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
