"""BIDS-motion input: imulog's own BIDS export read back (round trip), and a hand-written dataset in other units,
both checked with bidsschematools first."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, convert_file, detect
from imulog.converters.bids import _tables, iter_motion
from imulog.converters.registry import group_directory

from imulog.archive import TrialReader
from imulog.cli import cli

bst_validator = pytest.importorskip("bidsschematools.validator")


@pytest.fixture(scope="module")
def exported(repo_root: Path, tmp_path_factory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("bidsin")
    trial = tmp / "t.mcap"
    sim = repo_root / "recordings" / "sim"
    r = CliRunner().invoke(
        cli,
        [
            "convert",
            str(sim / "r2g_s00_t00_imu.csv"),
            str(sim / "r2g_s00_t00_vicon.csv"),
            "--meta",
            "subject=S00",
            "--meta",
            "task=r2g",
            "-o",
            str(trial),
        ],
    )
    assert r.exit_code == 0, r.output
    out = tmp / "ds"
    r = CliRunner().invoke(cli, ["export", str(trial), "--to", "bids", "-o", str(out)])
    assert r.exit_code == 0, r.output
    return trial, out


def test_round_trip_of_imulog_export(exported, tmp_path: Path):
    trial, ds = exported
    assert bst_validator.validate_bids(str(ds))["path_tracking"] == []
    groups = group_directory(ds)
    assert len(groups) == 1 and len(groups[0][1]) == 2  # one recording: the wrist and vicon tracking systems
    motion = sorted((ds / "sub-S00" / "motion").glob("*_motion.tsv"))
    assert all(detect(p).name == "bids-motion" for p in motion)
    out = tmp_path / "back"
    r = CliRunner().invoke(cli, ["convert", str(ds), "-o", str(out)])
    assert r.exit_code == 0, r.output
    (back,) = list(out.rglob("*.mcap"))
    with TrialReader(back) as b, TrialReader(trial) as o:
        assert sorted(b.topics()) == ["/imu/wrist", "/markers/vicon"]
        a, i = b.read("/imu/wrist"), o.read("/imu/wrist")
        np.testing.assert_array_equal(a.acc, i.acc)
        np.testing.assert_array_equal(a.gyr, i.gyr)
        np.testing.assert_array_equal(np.diff(a.t_ns), np.diff(i.t_ns))  # LATENCY keeps every sample's time
        m, n = b.read("/markers/vicon"), o.read("/markers/vicon")
        assert m.labels == n.labels
        np.testing.assert_array_equal(m.valid, n.valid)
        np.testing.assert_array_equal(m.pos[m.valid], n.pos[n.valid])
        # the two systems keep their offset on the shared latency axis
        assert (a.t_ns[0] - m.t_ns[0]) == (i.t_ns[0] - n.t_ns[0])


def _dataset(tmp_path: Path) -> Path:
    ds = tmp_path / "lab"
    mot = ds / "sub-P1" / "ses-1" / "motion"
    mot.mkdir(parents=True)
    (ds / "dataset_description.json").write_text(json.dumps({"Name": "lab", "BIDSVersion": "1.10.0"}))
    (ds / "participants.tsv").write_text("participant_id\nsub-P1\n")
    stem = "sub-P1_ses-1_task-walk_run-1"
    rows = ["name\tcomponent\ttype\ttracked_point\tunits"]
    rows += [f"acc_{a}\t{a}\tACCEL\tshank\tg" for a in "xyz"] + [f"gyr_{a}\t{a}\tGYRO\tshank\tdeg/s" for a in "xyz"]
    rows += [f"q_{c}\tquat_{c}\tORNT\tshank\tn/a" for c in "wxyz"] + ["temp\tn/a\tMISC\tshank\tdegC"]
    (mot / f"{stem.replace('_run', '_tracksys-imu_run')}_channels.tsv").write_text("\n".join(rows) + "\n")
    data = np.column_stack(
        [
            np.tile([0, 0, 1.0], (50, 1)),
            np.tile([90.0, 0, 0], (50, 1)),
            np.tile([1.0, 0, 0, 0], (50, 1)),
            np.full(50, 30.5),
        ]
    )
    data[10, 0] = np.nan
    text = "\n".join("\t".join("n/a" if not np.isfinite(v) else repr(float(v)) for v in r) for r in data) + "\n"
    (mot / f"{stem.replace('_run', '_tracksys-imu_run')}_motion.tsv").write_text(text)
    (mot / f"{stem.replace('_run', '_tracksys-imu_run')}_motion.json").write_text(
        json.dumps({"TaskName": "walk", "SamplingFrequency": 100, "TrackingSystemName": "imu"})
    )
    (mot / f"{stem}_events.tsv").write_text("onset\tduration\ttrial_type\n0.25\tn/a\theel_strike\n0.1\t0.2\tstance\n")
    return ds


def test_hand_written_dataset_units_and_events(tmp_path: Path):
    ds = _dataset(tmp_path)
    assert bst_validator.validate_bids(str(ds))["path_tracking"] == []
    path = next(ds.rglob("*_motion.tsv"))
    rec = convert_file(path)
    (imu,) = rec.imus
    assert imu.name == "shank" and len(imu) == 50 and imu.t_ns[1] == 10_000_000  # no LATENCY: k / 100 Hz
    np.testing.assert_allclose(imu.acc[0], [0, 0, 9.80665])
    np.testing.assert_allclose(imu.gyr[0], [np.pi / 2, 0, 0])
    assert np.isnan(imu.acc[10, 0])  # n/a is a gap
    assert [s.topic for s in rec.signals] == ["/orientation/shank", "/signals/imu"]
    assert rec.signals[1].columns == ["temp"] and rec.signals[1].units == ["degC"]
    (ev,) = rec.events
    assert ev.labels == ["stance", "heel_strike"] and ev.start_ns.tolist() == [100_000_000, 250_000_000]
    assert (ev.end_ns - ev.start_ns).tolist() == [200_000_000, 0]


def test_bad_inputs_one_line(tmp_path: Path):
    ds = _dataset(tmp_path)
    path = next(ds.rglob("*_motion.tsv"))
    ch = path.with_name(path.name.replace("_motion.tsv", "_channels.tsv"))
    ch.write_text(ch.read_text().replace("deg/s", "furlong/s"))
    with pytest.raises(ConversionError, match=r"column 'gyr_x': unknown gyr unit 'furlong/s'"):
        convert_file(path)
    ch.unlink()
    with pytest.raises(ConversionError, match=r"no .*_channels\.tsv beside it"):
        convert_file(path, fmt="bids-motion")


def _genfromtxt(path: Path) -> np.ndarray:
    """numpy's own reader of the table, the reference the converter read it with before issue 24's pieces."""
    return np.genfromtxt(path, delimiter="\t", missing_values="n/a", filling_values=np.nan, ndmin=2)


@pytest.mark.parametrize("piece_bytes", [None, 4096, 1 << 20])
def test_motion_table_values_equal_numpy_whole_and_in_pieces(exported, tmp_path: Path, piece_bytes):
    """Every table (the export's IMU and markers with n/a gaps, the hand-written one) read through the one text
    cutter, whole and in pieces of 4 KiB (many pieces) and 1 MiB, gives numpy.genfromtxt's values bit for bit,
    gaps at the same cells, times on the same rows."""
    _, ds = exported
    paths = sorted(ds.rglob("*_motion.tsv")) + sorted(_dataset(tmp_path).rglob("*_motion.tsv"))
    gaps = 0
    for path in paths:
        ref = _genfromtxt(path)
        chans = (path.with_name(path.name.replace("_motion.tsv", "_channels.tsv")).read_text().count("\n")) - 1
        pieces = list(_tables(path, [{"name": f"c{i}"} for i in range(chans)], "channels", piece_bytes))
        got = np.concatenate([p.values for p in pieces])
        assert got.shape == ref.shape, path.name
        np.testing.assert_array_equal(got, ref)  # NaN where numpy has NaN, every other bit equal
        gaps += int(np.isnan(ref).sum())
        if piece_bytes == 4096 and path.stat().st_size > 3 * 4096:
            assert len(pieces) > 2
            lines = np.cumsum([0] + [len(p.values) for p in pieces[:-1]]) + 1
            assert [p.first_line for p in pieces] == lines.tolist()
        whole = list(iter_motion(path, piece_bytes=None))
        parts = list(iter_motion(path, piece_bytes=piece_bytes))
        for a, b in zip(whole[0].streams(), [s for r in parts[:1] for s in r.streams()], strict=True):
            assert type(a) is type(b)
        t_whole = np.concatenate([r.streams()[0].t_ns for r in whole])
        t_parts = np.concatenate([r.streams()[0].t_ns for r in parts])
        np.testing.assert_array_equal(t_whole, t_parts)
    assert gaps > 0  # the export's markers and the hand-written table have n/a cells


def test_bad_table_rows_name_their_line(tmp_path: Path):
    ds = _dataset(tmp_path)
    path = next(ds.rglob("*_motion.tsv"))
    lines = path.read_text().splitlines()
    lines[7] = lines[7].replace("\t", "\tx", 1)
    path.write_text("\n".join(lines) + "\n")
    for piece_bytes in (None, 256):
        with pytest.raises(ConversionError, match=r"line 8"):
            list(iter_motion(path, piece_bytes=piece_bytes))
    lines[7] = "\t".join(lines[8].split("\t")[:-1])  # a row one cell short
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConversionError, match=r"line 8.*truncated line"):
        convert_file(path)


def test_one_column_table_with_a_missing_value(tmp_path: Path):
    """A lone ``n/a`` is a gap, not a blank line, whole and in pieces (as numpy reads it)."""
    path = tmp_path / "sub-01_tracksys-x_motion.tsv"
    path.write_text("1.0\nn/a\n2.5\n" * 200)
    for piece_bytes in (None, 64):
        got = np.concatenate([p.values for p in _tables(path, [{"name": "c"}], "channels", piece_bytes)])
        np.testing.assert_array_equal(got, _genfromtxt(path))
