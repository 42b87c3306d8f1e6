"""Vicon Nexus CSV and the gaitmap mocap file in pieces (issue 24, point 4): every shared Nexus CSV and gaitmap file,
and Nexus files of several sections built from them, convert through ``imulog convert`` whole and in tiny pieces to
the same archive sample by sample; the sections are found the same whatever the block the scan reads; the pieces
join to the whole file's recording."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from imulog.converters._binary import concat_chunks
from imulog.converters.gaitmap import iter_mocap, read_mocap
from imulog.converters.vicon_csv import iter_vicon_csv, read_vicon_csv
from imulog.converters.vicon_csv_sections import find_sections
from test_convert_pieces import assert_same_recording
from test_convert_pieces_archive import TEXT, assert_same_trial, convert_twice

from imulog.model import Recording


def _plain(value: Any) -> Any:
    """``value`` with its arrays as lists (the markers' ``resolution`` scale is an array, as the reader gives it)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value.tolist() if isinstance(value, np.ndarray) else value


def assert_same_nexus(a: Recording, b: Recording) -> None:
    for rec in (a, b):
        for m in rec.markers:
            m.meta = _plain(m.meta)
    assert_same_recording(a, b)


@pytest.fixture
def sections_file(shared_data: Path, tmp_path: Path) -> Path:
    """A Nexus export of three sections one after the other, as Nexus writes them: Devices (the EMG of
    analogs.csv, 2 kHz), Trajectories (markers.csv, 100 Hz) and Model Outputs (the same columns named as outputs),
    separated by blank lines, with blank lines after the last."""
    analogs = (shared_data / "vicon_nexus/analogs.csv").read_bytes()
    markers = (shared_data / "vicon_nexus/markers.csv").read_bytes()
    outputs = markers.replace(b"Trajectories", b"Model Outputs", 1)
    path = tmp_path / "sections.csv"
    path.write_bytes(analogs + b"\r\n" + markers + b"\r\n" + outputs + b"\r\n\r\n")
    return path


def test_the_three_sections_are_read(sections_file):
    rec = read_vicon_csv(sections_file)
    assert [s.topic for s in rec.streams()] == ["/markers/vicon", "/analog/vicon", "/vicon/model_outputs"]
    assert len(rec.analogs[0]) == 20 * len(rec.markers[0]) == 20 * 580
    assert rec.analogs[0].t_ns[20] == rec.markers[0].t_ns[1]  # one clock: sub frames of the marker frames


@pytest.mark.parametrize("block", [97, 4096, 1 << 30])
def test_sections_found_whatever_the_scan_block(sections_file, block):
    assert find_sections(sections_file, block) == find_sections(sections_file, 1 << 30)
    assert [s.name for s in find_sections(sections_file, block)] == ["Devices", "Trajectories", "Model Outputs"]


@pytest.mark.parametrize("piece_bytes", [700, 5000, 1 << 20])
def test_nexus_pieces_join_to_the_whole(sections_file, shared_data, piece_bytes):
    for path in (sections_file, shared_data / "vicon_nexus/markers.csv", shared_data / "vicon_nexus/analogs.csv"):
        pieces = list(iter_vicon_csv(path, piece_bytes=piece_bytes))
        assert len(pieces) > (1 if piece_bytes < (1 << 20) else 0)
        assert_same_nexus(concat_chunks(pieces), read_vicon_csv(path))


def test_gaitmap_mocap_pieces_join_to_the_whole(shared_data):
    path = shared_data / "gaitmap_foot/mocap_sample.csv"
    pieces = list(iter_mocap(path, piece_bytes=4096))
    assert len(pieces) > 100
    assert_same_recording(concat_chunks(pieces), read_mocap(path))


CASES = [
    "vicon_nexus/markers.csv",
    "vicon_nexus/analogs.csv",
    "gaitmap_foot/imu_sample.csv",
    "gaitmap_foot/mocap_sample.csv",
]


def test_every_shared_nexus_csv_and_gaitmap_table_is_a_case(shared_data):
    found = {f"vicon_nexus/{p.name}" for p in (shared_data / "vicon_nexus").glob("*.csv")}
    found |= {f"gaitmap_foot/{p.name}" for p in (shared_data / "gaitmap_foot").glob("*_sample.csv")}
    assert found - set(CASES) == {"gaitmap_foot/stride_borders_sample.csv"}  # one row per stride: one piece


@pytest.mark.parametrize("rel", CASES, ids=[Path(r).name for r in CASES])
def test_pieces_write_the_whole_files_archive(rel, shared_data, tmp_path, monkeypatch):
    whole, pieces = convert_twice(shared_data / rel, tmp_path, (TEXT, 8192), monkeypatch)
    assert_same_trial(whole, pieces)


def test_sections_file_pieces_write_the_whole_files_archive(sections_file, tmp_path, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    whole, pieces = convert_twice(sections_file, out, (TEXT, 8192), monkeypatch)
    assert_same_trial(whole, pieces)


def _nexus(path: Path, frames: int) -> None:
    """A Nexus export of ``frames`` frames: Devices (one EMG channel, 10 sub frames) then Trajectories (2 markers)."""
    rng = np.random.default_rng(0)
    with open(path, "w") as f:
        f.write("Devices\n1000\n,,EMG Sensor 1\nFrame,Sub Frame,EMG1\n,,V\n")
        frame = np.repeat(np.arange(1, frames + 1), 10)
        sub = np.tile(np.arange(10), frames)
        np.savetxt(
            f, np.column_stack([frame, sub, rng.normal(0, 1e-4, 10 * frames)]), delimiter=",", fmt=["%d", "%d", "%.3e"]
        )
        f.write("\nTrajectories\n100\n,,s:a,,,s:b,,\nFrame,Sub Frame,X,Y,Z,X,Y,Z\n,,mm,mm,mm,mm,mm,mm\n")
        rows = np.column_stack([np.arange(1, frames + 1), np.zeros(frames), rng.normal(0, 500, (frames, 6))])
        np.savetxt(f, rows, delimiter=",", fmt=["%d", "%d"] + ["%.3f"] * 6)


_PEAK = """
import sys
from imulog.converters.vicon_csv import iter_vicon_csv
n = 0
for piece in iter_vicon_csv(sys.argv[1], piece_bytes=1 << 20):
    n += sum(len(m) for m in piece.markers)
hwm = [int(x.split()[1]) for x in open("/proc/self/status") if x.startswith("VmHWM:")]
print(n, hwm[0])
"""


def test_a_long_nexus_csv_reads_in_bounded_memory(tmp_path):
    """Reading a two-section Nexus export in 1 MiB pieces: 4x the frames (100 000 -> 400 000, 23 -> 95 MB of text)
    peaks within 15 MB (the child's own VmHWM); measured 112 -> 115 MB, where one piece a section
    (``piece_bytes=None``) peaks at 192 -> 471 MB."""
    import subprocess
    import sys

    peaks = {}
    for frames in (100_000, 400_000):
        path = tmp_path / f"nexus_{frames}.csv"
        _nexus(path, frames)
        out = subprocess.run([sys.executable, "-c", _PEAK, str(path)], capture_output=True, text=True, check=True)
        n, kib = (int(x) for x in out.stdout.split())
        assert n == frames
        peaks[frames] = kib / 1024
    assert peaks[400_000] - peaks[100_000] < 15, peaks
