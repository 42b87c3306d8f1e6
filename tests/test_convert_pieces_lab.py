"""``imulog convert`` piece by piece writes the archive it writes from the whole file (issue 24, point 4) for the lab
and device text exports: Motive CSV, Qualisys TSV, OpenSim TRC, ``.sto``/``.mot``, Delsys CSV, Empatica E4 files and
ActiLife epoch CSV. Every shared file of those formats (``../shared/data/devices``) is converted through the command
twice, once whole and once in tiny pieces through the streaming writer (the threshold ``STREAM_MIN_BYTES`` at 0, as
``IMULOG_STREAM_MIN_BYTES=1`` sets it), and the two trials are compared sample by sample, channel metadata and
records (the helpers of ``test_convert_pieces_archive.py``). Formats without a shared file (Qualisys) and what the
whole file decides but the first piece cannot see (a time column with holes, a marker never seen, rates estimated
from every time) are checked on files written here. Bad input (a truncated row, a missing column) gives the same
one-line error in pieces as whole."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import convert_file, detect
from imulog.converters._binary import concat_chunks
from imulog.converters.base import Converter
from test_convert_pieces_archive import assert_same_trial, convert_twice

from imulog.cli import cli

SHARED_DATA = Path(os.environ.get("IMULOG_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
TEXT = "imulog.converters._pieces.PIECE_BYTES"
DEV = SHARED_DATA / "devices"

#: every shared file of the formats: folder -> (file name pattern, the converter that reads it)
FOLDERS = {
    "optitrack_motive": ("*.csv", "motive"),
    "opensim_trc": ("*.trc", "opensim-trc"),
    "opensim_mot": ("*.mot", "opensim-sto"),
    "opensense_sto": ("*.sto", "opensim-sto"),
    "delsys_trigno": ("*.csv", "delsys"),
    "empatica_e4": ("*.csv", "empatica-e4"),
    "actigraph_count_csv": ("*.csv", "actilife-csv"),  # ActiLife epoch CSV
}
#: pieces of 2 KiB, or a sixth of a small file (at least 64 bytes: some rows are longer)
CASES = [
    (f"{folder}/{p.name}", max(64, min(2048, p.stat().st_size // 6)))
    for folder, (pat, _) in FOLDERS.items()
    for p in sorted((DEV / folder).glob(pat))
]


def test_every_shared_file_of_these_formats_is_a_case(shared_data):
    """The shared folders hold the 14 files listed in ../shared/data/devices/SOURCES.tsv for these formats, each
    read by the converter that now reads in pieces (a file added there becomes a case; one of another format fails)."""
    assert len(CASES) == 14
    for rel, _ in CASES:
        folder = rel.split("/")[0]
        conv = detect(shared_data / "devices" / rel)
        assert conv.name == FOLDERS[folder][1], rel
        assert type(conv).iter_chunks is not Converter.iter_chunks, rel  # imulog convert streams it


@pytest.mark.parametrize(("rel", "piece_bytes"), CASES, ids=[Path(c[0]).name for c in CASES])
def test_pieces_write_the_whole_files_archive(rel, piece_bytes, shared_data, tmp_path, monkeypatch):
    """Every value, record and warning, the IMU unit check's too (``plausibility.Excerpts``: the same samples in
    any pieces; the 2 s Delsys recording in 2 KiB pieces missed the whole file's gyroscope-bias warning when each
    piece gave its own excerpt)."""
    whole, pieces = convert_twice(shared_data / "devices" / rel, tmp_path, (TEXT, piece_bytes), monkeypatch)
    assert_same_trial(whole, pieces)


def pieces_equal_whole(path: Path, piece_bytes: int, monkeypatch) -> list:
    """The converter's pieces at ``piece_bytes`` joined equal its whole-file recording (every array, meta, record,
    warning); returns the pieces."""
    import dataclasses

    monkeypatch.setattr(TEXT, piece_bytes)
    conv = detect(path)
    pieces = list(conv.iter_chunks(path))
    assert len(pieces) > 1
    whole, joined = convert_file(path), concat_chunks(pieces)
    assert joined.metadata == whole.metadata and joined.warnings == whole.warnings
    assert [s.topic for s in joined.streams()] == [s.topic for s in whole.streams()]
    for a, b in zip(whole.streams(), joined.streams(), strict=True):
        for f in dataclasses.fields(a):
            va, vb = getattr(a, f.name), getattr(b, f.name)
            if isinstance(va, np.ndarray):
                assert va.dtype == vb.dtype and va.shape == vb.shape and va.tobytes() == vb.tobytes(), (a.topic, f)
            else:
                assert va == vb, (a.topic, f.name)
    return pieces


def same_error(path: Path, piece_bytes: int, monkeypatch) -> str:
    """The one-line error of the whole file and of its pieces (through ``imulog convert`` both ways): the same."""
    import imulog.commands.convert_stream as cs

    out = []
    for threshold in (1 << 60, 0):
        monkeypatch.setattr(cs, "STREAM_MIN_BYTES", threshold)
        monkeypatch.setattr(TEXT, piece_bytes)
        target = path.parent / f"out_{threshold}.mcap"
        r = CliRunner().invoke(cli, ["convert", str(path), "-o", str(target)])
        assert r.exit_code != 0 and not target.exists(), r.output
        out.append(r.output.strip().splitlines()[-1])
    assert out[0] == out[1]
    return out[0]


# ------------------------------------------------------------------ what only the whole file shows
def _edit_rows(src: Path, dst: Path, skip: int, edit) -> None:
    """Copy ``src`` to ``dst`` with ``edit(i, cells)`` applied to the comma-separated data rows after ``skip``."""
    lines = src.read_text().splitlines()
    out = lines[:skip]
    for i, line in enumerate(lines[skip:]):
        cells = line.split(",")
        edit(i, cells)
        out.append(",".join(cells))
    dst.write_text("\n".join(out) + "\n")


def test_trc_time_hole_and_unseen_marker_decided_over_the_whole_file(shared_data, tmp_path, monkeypatch):
    """One empty Time cell near the end makes every time (Frame# - first) / DataRate, and a marker never seen is a
    warning: both known only at the end, both in every piece's result as in the whole file's."""
    path = tmp_path / "holes.trc"

    def edit(i: int, cells: list[str]) -> None:
        if i == 80:
            cells[1] = ""
        cells[5:8] = ["", "", ""]  # ASISr (the second marker) never seen

    _edit_rows(shared_data / "devices/opensim_trc/markers.trc", path, 6, edit)
    pieces = pieces_equal_whole(path, 4096, monkeypatch)
    rec = convert_file(path)
    assert any("Time column unusable" in w for w in rec.warnings)
    assert any("1 of 51 markers have no valid sample (ASISr)" in w for w in rec.warnings)
    assert not pieces[0].warnings  # the first piece could not know
    np.testing.assert_array_equal(rec.markers[0].t_ns, np.arange(93) * 10_000_000)
    assert_same_trial(*convert_twice(path, tmp_path, (TEXT, 4096), monkeypatch))


def test_mot_rate_estimated_from_every_time(shared_data, tmp_path, monkeypatch):
    """No DataRate: the rate is the median step of all times; a slower stretch at the end changes it, which only
    the last piece sees (the pieces refine it in the device record)."""
    path = tmp_path / "slow_end.mot"
    src = shared_data / "devices/opensim_mot/inverse_kin.mot"
    lines = src.read_text().splitlines()
    head = next(i for i, x in enumerate(lines) if x.startswith("time")) + 1
    rows = lines[head:]
    fast = len(rows) // 3  # the first third at 100 Hz, the rest at 50 Hz: the median step is 20 ms
    t = 1.56 + np.concatenate([np.arange(fast) * 0.01, fast * 0.01 + np.arange(len(rows) - fast) * 0.02])
    out = [f"{t[i]:.2f}," + r.split(",", 1)[1] for i, r in enumerate(rows)]
    path.write_text("\n".join(lines[:head] + out) + "\n")
    pieces = pieces_equal_whole(path, 1024, monkeypatch)
    rate = convert_file(path).metadata["imulog.device.opensense"]["rate_hz"]
    assert rate == pytest.approx(50.0) and pieces[0].metadata["imulog.device.opensense"]["rate_hz"] != rate
    assert_same_trial(*convert_twice(path, tmp_path, (TEXT, 1024), monkeypatch))


@pytest.mark.parametrize("hole", [None, "Time", "Frame"])
def test_qualisys_pieces_equal_whole(hole, tmp_path, monkeypatch):
    """A QTM export written here (no shared one exists): NULL and zero samples, and a Time (or Frame and Time)
    cell empty near the end, which sends the whole file to the next clock (Frame, else the row index)."""
    from test_convert_qualisys import write_qtm

    path = tmp_path / "reach_3d.tsv"
    write_qtm(path, n=400)
    lines = path.read_text().splitlines()
    cells = lines[-20].split("\t")
    cells[4] = "NULL"
    if hole:
        cells[1] = ""
    if hole == "Frame":
        cells[0] = ""
    lines[-20] = "\t".join(cells)
    path.write_text("\n".join(lines) + "\n")
    pieces_equal_whole(path, 2048, monkeypatch)
    rec = convert_file(path)
    clock = rec.metadata["imulog.device.qualisys"]["time"]
    assert clock == {None: "Time column (s)", "Time": "(Frame - 1) / 200 Hz", "Frame": "row index / 200 Hz"}[hole]
    assert rec.metadata["imulog.device.qualisys"]["missing_as_zero_samples"] == 1
    assert np.isnan(rec.markers[0].pos[-20, 0, 2])  # the NULL cell: RSHO Z
    assert_same_trial(*convert_twice(path, tmp_path, (TEXT, 2048), monkeypatch))


# ------------------------------------------------------------------ bad input: the same one-line error
def _cut_row(path: Path, row_from_end: int, delim: str, keep: int) -> None:
    lines = path.read_text().splitlines()
    lines[-row_from_end] = delim.join(lines[-row_from_end].split(delim)[:keep])
    path.write_text("\n".join(lines) + "\n")


def test_motive_bad_input_same_error(shared_data, tmp_path, monkeypatch):
    path = tmp_path / "take.csv"
    path.write_bytes((shared_data / "devices/optitrack_motive/sample_optitrack_take.csv").read_bytes())
    _cut_row(path, 30, ",", 10)
    msg = same_error(path, 2048, monkeypatch)
    assert "truncated line: 10 fields" in msg and "line 228" in msg
    lines = path.read_text().splitlines()
    lines[6] = lines[6].replace("Frame,Time,", "Frame,Tick,", 1)
    path.write_text("\n".join(lines) + "\n")
    assert "the second column must be 'Time'" in same_error(path, 2048, monkeypatch)


def test_qualisys_bad_input_same_error(tmp_path, monkeypatch):
    from test_convert_qualisys import write_qtm

    path = tmp_path / "reach_3d.tsv"
    write_qtm(path, n=400)
    _cut_row(path, 30, "\t", 5)
    assert "truncated line: 5 fields, expected 11" in same_error(path, 2048, monkeypatch)
    write_qtm(path, n=400)
    lines = path.read_text().splitlines()[:-30]  # NO_OF_FRAMES says 400
    path.write_text("\n".join(lines) + "\n")
    assert "file ends after 370 of NO_OF_FRAMES 400 frames" in same_error(path, 2048, monkeypatch)
    text = path.read_text().replace("\tRWRA Z", "\tRWRA_Z")
    path.write_text(text)
    assert "no 'RWRA X/Y/Z' columns for marker 'RWRA'" in same_error(path, 2048, monkeypatch)


def test_trc_and_sto_bad_input_same_error(shared_data, tmp_path, monkeypatch):
    trc = tmp_path / "m.trc"
    _edit_rows(
        shared_data / "devices/opensim_trc/markers.trc",
        trc,
        6,
        lambda i, c: c.__setitem__(4, "x") if i == 80 else None,
    )
    assert "'x' is not a number" in same_error(trc, 4096, monkeypatch)
    sto = tmp_path / "o.sto"
    sto.write_bytes(
        (
            shared_data / "devices/opensense_sto/MT_012005D6_009-quaternions_calibration_trial_Facing_negX.sto"
        ).read_bytes()
    )
    _cut_row(sto, 40, "\t", 3)
    assert "truncated line" in same_error(sto, 4096, monkeypatch)
    lines = sto.read_text().splitlines()
    i = next(k for k, x in enumerate(lines) if x.startswith("time"))
    lines[i] = "t" + lines[i][4:]
    sto.write_text("\n".join(lines) + "\n")
    assert "the first column must be 'time'" in same_error(sto, 4096, monkeypatch)


def test_delsys_channels_ending_early_pieces_equal_whole(shared_data, tmp_path, monkeypatch):
    """The IMU channels (148 Hz) end long before the EMG (1259 Hz): later pieces carry the EMG only."""
    path = shared_data / "devices/delsys_trigno/truncated_trigno_sample.csv"
    pieces = pieces_equal_whole(path, 2048, monkeypatch)
    assert pieces[0].imus and not pieces[-1].imus and pieces[-1].analogs


def test_delsys_bad_input_same_error(shared_data, tmp_path, monkeypatch):
    """An IMU time set again after the channel ended (an earlier piece), and a truncated row."""
    path = tmp_path / "trigno.csv"
    lines = (shared_data / "devices/delsys_trigno/truncated_trigno_sample.csv").read_text().splitlines()
    ended = next(i for i, x in enumerate(lines) if i > 20 and x.split(",")[2] == "") + 1  # ACC.X's first empty time
    cells = lines[-10].split(",")
    cells[2:4] = ["1.99", "0.5"]
    lines[-10] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    msg = same_error(path, 2048, monkeypatch)
    assert "empty time cell before the channel's last sample" in msg and f"line {ended}" in msg
    lines = (shared_data / "devices/delsys_trigno/truncated_trigno_sample.csv").read_text().splitlines()
    lines[-10] = ",".join(lines[-10].split(",")[:7])
    path.write_text("\n".join(lines) + "\n")
    assert "truncated line: 7 fields, expected 28" in same_error(path, 2048, monkeypatch)


def test_e4_bad_input_same_error(shared_data, tmp_path, monkeypatch):
    """A short ACC row far into the file, a beat that goes back in IBI.csv, and a final row cut short (dropped
    with the same warning)."""
    src = shared_data / "devices/empatica_e4"
    acc = tmp_path / "ACC.csv"
    lines = (src / "ACC.csv").read_text().splitlines()
    lines[-500] = lines[-500].rsplit(",", 1)[0]
    acc.write_text("\n".join(lines) + "\n")
    msg = same_error(acc, 4096, monkeypatch)
    assert f"line {len(lines) - 499}" in msg, msg
    ibi = tmp_path / "IBI.csv"
    lines = (src / "IBI.csv").read_text().splitlines()
    lines[-50] = "1.0," + lines[-50].split(",")[1]
    ibi.write_text("\n".join(lines) + "\n")
    assert f"line {len(lines) - 49}: beat time does not increase" in same_error(ibi, 1024, monkeypatch)
    acc.write_text((src / "ACC.csv").read_text()[:-3])  # the last row cut inside its last number
    pieces = pieces_equal_whole(acc, 4096, monkeypatch)
    assert any("cut" in w or "ends inside" in w for w in pieces[-1].warnings), pieces[-1].warnings


def _epoch_export(path: Path, n: int = 3000, *, gap_at: int | None = None) -> None:
    """An ActiLife epoch export with a names row and Date/Time columns (15 s epochs), a gap near the end."""
    banner = (
        "------------ Data File Created By ActiGraph GT3X+ ActiLife v6.13.3 Firmware v3.2.1 date format M/d/yyyy "
        "at 30 Hz  Filter Normal -----------\nSerial Number: NEO1F12345678\nStart Time 10:00:00\nStart Date 3/4/2021\n"
        "Epoch Period (hh:mm:ss) 00:00:15\nDownload Time 10:00:00\nDownload Date 3/11/2021\n"
        "Current Memory Address: 0\nCurrent Battery Voltage: 4.10     Mode = 61\n"
        "--------------------------------------------------\n"
    )
    t0 = np.datetime64("2021-03-04T10:00:00")
    rows = ["Date,Time,Axis1,Axis2,Axis3,Steps,Lux,Vector Magnitude"]
    rng = np.random.default_rng(3)
    for i in range(n):
        t = t0 + np.timedelta64(15 * (i + (60 if gap_at is not None and i >= gap_at else 0)), "s")
        d = t.astype(object)
        a = rng.integers(0, 900, 3)
        rows.append(f"{d.month}/{d.day}/{d.year},{d:%H:%M:%S},{a[0]},{a[1]},{a[2]},{i % 7},{i % 50},{a.sum()}")
    path.write_text(banner + "\n".join(rows) + "\n")


def test_actilife_epoch_dated_rows_pieces_equal_whole(tmp_path, monkeypatch):
    """Rows with Date and Time cells read piece by piece; a gap near the end gives the uneven-epoch warning, which
    only the last piece can see."""
    path = tmp_path / "epochs15s.csv"
    _epoch_export(path, gap_at=2900)
    pieces = pieces_equal_whole(path, 8192, monkeypatch)
    rec = convert_file(path)
    assert any("not 15 s apart everywhere" in w for w in pieces[-1].warnings) and not pieces[0].warnings
    (sig,) = rec.signals
    assert sig.t_ns[2900] - sig.t_ns[2899] == 61 * 15 * 10**9 and len(sig.t_ns) == 3000
    assert_same_trial(*convert_twice(path, tmp_path, (TEXT, 8192), monkeypatch))
    lines = path.read_text().splitlines()
    lines[-100] = lines[-100].replace(":", ";", 1)
    path.write_text("\n".join(lines) + "\n")
    assert f"line {len(lines) - 99}" in same_error(path, 8192, monkeypatch)


def test_qualisys_without_clock_columns_cut_off_leaves_no_archive(tmp_path, monkeypatch):
    """Without Frame/Time columns there is no first pass: the row count is checked after the last piece, when the
    streaming writer has taken every piece; the error is the whole file's and no archive is kept."""
    from test_convert_qualisys import write_qtm

    path = tmp_path / "reach_3d.tsv"
    write_qtm(path, n=400, time_columns=False, names_row=False)
    lines = path.read_text().splitlines()[:-30]
    path.write_text("\n".join(lines) + "\n")
    assert "file ends after 370 of NO_OF_FRAMES 400 frames" in same_error(path, 2048, monkeypatch)


def test_an_epoch_export_streams_below_the_general_threshold(tmp_path, monkeypatch):
    """An epoch export is one archive message per row, so `imulog convert` reads one of a few MB piece by piece
    (``ActiLifeCsvConverter.stream_min_bytes``) although it is far below ``STREAM_MIN_BYTES``; the archive is the
    one the whole file gives."""
    from imulog.converters.actilife_csv import ActiLifeCsvConverter
    from imulog.converters.actilife_epoch import EPOCH_PIECE_BYTES

    import imulog.commands.convert_stream as cs

    path = tmp_path / "epochs15s.csv"
    _epoch_export(path, n=60_000)
    size = path.stat().st_size
    assert EPOCH_PIECE_BYTES <= size < cs.STREAM_MIN_BYTES
    streamed = tmp_path / "streamed.mcap"
    r = CliRunner().invoke(cli, ["convert", str(path), "-o", str(streamed)])
    assert r.exit_code == 0 and "converted piece by piece" in r.output, r.output
    assert len(list(ActiLifeCsvConverter().iter_chunks(path))) >= size // EPOCH_PIECE_BYTES
    monkeypatch.setattr(ActiLifeCsvConverter, "stream_min_bytes", None)
    whole = tmp_path / "whole.mcap"
    r = CliRunner().invoke(cli, ["convert", str(path), "-o", str(whole)])
    assert r.exit_code == 0 and "piece by piece" not in r.output, r.output
    assert_same_trial(whole, streamed)
