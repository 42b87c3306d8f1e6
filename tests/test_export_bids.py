"""BIDS-motion export, checked against the BIDS schema with bidsschematools."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli

bst_schema = pytest.importorskip("bidsschematools.schema")
bst_validator = pytest.importorskip("bidsschematools.validator")


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f, delimiter="\t"))


def _matching(rules, datatype, suffix, extension):
    """The schema rules whose selectors are all plain ==-tests met by this file."""
    env = {"datatype": datatype, "suffix": suffix, "extension": extension}
    out = []
    for name, rule in rules.items():
        ok = True
        for sel in rule.get("selectors", []):
            left, op, right = sel.partition(" == ")
            if not op or left not in env or env[left] != right.strip('"'):
                ok = False
                break
        if ok:
            out.append((name, rule))
    return out


@pytest.fixture(scope="module")
def bids_folder(processed_r2g, tmp_path_factory):
    out = tmp_path_factory.mktemp("bids") / "r2g_bids"
    result = CliRunner().invoke(cli, ["export", str(processed_r2g), "--to", "bids", "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    return out, json.loads(result.output)


def test_every_file_name_is_valid_bids(bids_folder):
    out, report = bids_folder
    result = bst_validator.validate_bids(str(out))
    assert result["path_tracking"] == [], result["path_tracking"]  # every file matched a BIDS rule
    names = {p.name for p in out.rglob("*") if p.is_file()}
    assert {
        "dataset_description.json",
        "sub-S00_task-r2g_tracksys-wrist_run-0_motion.tsv",
        "sub-S00_task-r2g_tracksys-vicon_run-0_channels.tsv",
        "sub-S00_task-r2g_run-0_events.tsv",
    } <= names
    assert len(report["files"]) == 8


def test_sidecars_and_tables_meet_the_schema(bids_folder):
    out, _ = bids_folder
    schema = bst_schema.load_schema()
    motion = out / "sub-S00" / "motion"
    columns_obj = schema.objects.columns
    for system in ("wrist", "vicon"):
        sidecar = json.loads((motion / f"sub-S00_task-r2g_tracksys-{system}_run-0_motion.json").read_text())
        rules = _matching(schema.rules.sidecars.motion, "motion", "motion", ".json")
        assert len(rules) >= 3
        for _, rule in rules:
            for key, level in rule.fields.items():
                level = level if isinstance(level, str) else level["level"]
                if level == "required":
                    assert key in sidecar, (system, key)
        assert sidecar["TaskName"] == "r2g"
        channels = _rows(motion / f"sub-S00_task-r2g_tracksys-{system}_run-0_channels.tsv")
        ((_, table_rule),) = _matching(schema.rules.tabular_data.motion, "motion", "channels", ".tsv")
        for col, level in table_rule.columns.items():
            level = level if isinstance(level, str) else level["level"]
            name = columns_obj[col]["name"]
            if level == "required":
                assert name in channels[0], (system, name)
            enum = columns_obj[col].get("enum")
            if enum and name in channels[0]:
                allowed = {e if isinstance(e, str) else e.get("value") for e in enum} | {"n/a"}
                assert {row[name] for row in channels} <= allowed, (system, name)
        # the data file has one column per channel row and no header
        data = np.genfromtxt(
            motion / f"sub-S00_task-r2g_tracksys-{system}_run-0_motion.tsv",
            delimiter="\t",
            missing_values="n/a",
            filling_values=np.nan,
        )
        assert data.shape[1] == len(channels)
        counts = {}
        for row in channels:
            counts[row["type"]] = counts.get(row["type"], 0) + 1
        for typ, n in counts.items():
            assert sidecar[f"{typ}ChannelCount"] == n
    events = _rows(motion / "sub-S00_task-r2g_run-0_events.tsv")
    ((_, ev_rule),) = [
        r for r in _matching(schema.rules.tabular_data.events, "motion", "events", ".tsv") if r[0] == "Events"
    ]
    for col, level in ev_rule.columns.items():
        level = level if isinstance(level, str) else level["level"]
        if level == "required":
            assert columns_obj[col]["name"] in events[0]
    description = json.loads((out / "dataset_description.json").read_text())
    assert {"Name", "BIDSVersion"} <= set(description)


def test_values_and_times_equal_the_archive(bids_folder, processed_r2g):
    out, _ = bids_folder
    motion = out / "sub-S00" / "motion"
    with TrialReader(processed_r2g) as trial:
        imu = trial.read("/imu/wrist")
        mk = trial.read("/markers/vicon")
        phases = trial.read("/derived/phases/wrist")
        alignment = trial.metadata["imulog.alignment"]
    wrist = np.genfromtxt(motion / "sub-S00_task-r2g_tracksys-wrist_run-0_motion.tsv", delimiter="\t")
    names = [r["name"] for r in _rows(motion / "sub-S00_task-r2g_tracksys-wrist_run-0_channels.tsv")]
    np.testing.assert_array_equal(wrist[:, names.index("wrist_gyr_y")], imu.gyr[:, 1])
    np.testing.assert_array_equal(wrist[:, names.index("wrist_acc_z")], imu.acc[:, 2])
    assert "wrist_quat_w" in names  # the orientation channel rides along as ORNT
    vicon = np.genfromtxt(
        motion / "sub-S00_task-r2g_tracksys-vicon_run-0_motion.tsv",
        delimiter="\t",
        missing_values="n/a",
        filling_values=np.nan,
    )
    vnames = [r["name"] for r in _rows(motion / "sub-S00_task-r2g_tracksys-vicon_run-0_channels.tsv")]
    ox = np.where(mk.valid[:, 0], mk.pos[:, 0, 0], np.nan)
    np.testing.assert_array_equal(vicon[:, vnames.index("O_x")], ox)  # gaps as n/a
    # one time axis: latency of the IMU and Vicon files and the event onsets all count from one origin
    lat_imu = wrist[:, names.index("latency")]
    lat_vicon = vicon[:, vnames.index("latency")]
    offset_s = (imu.t_ns[0] - mk.t_ns[0] + alignment["offset_ns"]) / 1e9  # IMU start on the Vicon clock
    assert lat_imu[0] == pytest.approx(offset_s, abs=1e-3) and lat_vicon[0] == 0.0
    events = _rows(motion / "sub-S00_task-r2g_run-0_events.tsv")
    phase_events = [e for e in events if e["source"] == "/derived/phases/wrist"]
    assert [e["trial_type"] for e in phase_events] == list(phases.labels)
    np.testing.assert_allclose(
        [float(e["onset"]) for e in phase_events], (phases.start_ns - mk.t_ns[0]) / 1e9, atol=2e-3
    )  # device clock vs Vicon: drift only


def test_existing_folder_needs_overwrite(bids_folder, processed_r2g):
    out, _ = bids_folder
    result = CliRunner().invoke(cli, ["export", str(processed_r2g), "--to", "bids", "-o", str(out)])
    assert result.exit_code == 1 and "--overwrite" in result.output
    result = CliRunner().invoke(
        cli, ["export", str(processed_r2g), "--to", "bids", "-o", str(out), "--overwrite", "--clock", "reference"]
    )
    assert result.exit_code == 0, result.output
    sidecar = json.loads((out / "sub-S00/motion/sub-S00_task-r2g_tracksys-wrist_run-0_motion.json").read_text())
    assert sidecar["imulog"]["clock"] == "reference"
    assert not list(out.parent.glob(".r2g_bids.*"))  # no temporary folder left


def test_the_motion_table_is_written_in_pieces_in_bounded_memory(tmp_path, monkeypatch):
    """A day of wrist data at 50 Hz took 8.4 GB to export (every row's text at once; `imulog simulate home --days 1
    --set rate_hz=50`, /usr/bin/time -v: 0.80 GB in pieces). The pieces give the same bytes, and the export's
    peak of traced memory in pieces is a fraction of the export formatting every row at once."""
    import tracemalloc

    from imulog.archive import write_trial
    from imulog.export import bids
    from imulog.model import ImuStream, Recording

    n = 120_000
    rng = np.random.default_rng(3)
    t = np.arange(n, dtype=np.int64) * 20_000_000
    imu = ImuStream("wrist", t, acc=rng.normal(0, 1, (n, 3)), gyr=rng.normal(0, 1, (n, 3)))
    trial = write_trial(tmp_path / "t.mcap", Recording(imus=[imu]))
    with TrialReader(trial) as reader:
        columns = [reader.read("/imu/wrist").t_ns / 1e9, *reader.read("/imu/wrist").acc.T]
    pieces = tmp_path / "pieces.tsv"
    bids.write_matrix_tsv(pieces, columns, rows_per_piece=7_000)
    assert pieces.read_text() == bids.matrix_tsv(columns)

    def peak(rows_per_piece: int) -> tuple[int, str]:
        monkeypatch.setattr(bids, "MOTION_ROWS_PER_PIECE", rows_per_piece)
        out = tmp_path / f"bids_{rows_per_piece}"
        tracemalloc.start()
        try:
            with TrialReader(trial) as reader:
                bids.export_bids(reader, out)
            return tracemalloc.get_traced_memory()[1], next(out.rglob("*_motion.tsv")).read_text()
        finally:
            tracemalloc.stop()

    at_once, text = peak(n)
    in_pieces, same = peak(5_000)
    assert same == text and len(text.splitlines()) == n
    assert in_pieces < at_once / 3, (in_pieces, at_once)


def _oriented_trial(path, n: int):
    """A trial of ``n`` samples at 50 Hz (acc, gyr) with its orientation channel (stored in other block sizes)."""
    from imulog.archive import write_trial
    from imulog.model import ImuStream, Recording
    from imulog.steps.orientation import run_orientation

    rng = np.random.default_rng(5)
    t = np.arange(n, dtype=np.int64) * 20_000_000
    acc = rng.normal(0, 0.2, (n, 3)) + [0.0, 0.0, 9.81]
    imu = ImuStream("wrist", t, acc=acc, gyr=rng.normal(0, 0.05, (n, 3)), meta={"rate_hz": 50.0})
    trial = write_trial(path, Recording(imus=[imu]))
    run_orientation(trial)
    return trial


def test_each_channel_is_read_block_by_block(tmp_path, monkeypatch):
    """The channels were read whole (a week at 100 Hz: 3-4 GB by estimate) though the text was written in pieces.
    Now the IMU and its orientation are read block by block, the orientation's blocks (another size) lined up row
    for row with the IMU's: the values are the archive's, and what the export holds besides the text does not grow
    with the recording (4x the samples: the traced peak grows by far less than the channel read whole; the day at
    50 Hz measured with /usr/bin/time -v: benchmarks/README.md, bids_memory.py)."""
    import tracemalloc

    from imulog.export import bids

    small = _oriented_trial(tmp_path / "small.mcap", 100_000)
    with TrialReader(small) as reader:
        blocks = [len(b) for b in reader.iter_blocks("/imu/wrist")]
        quat_blocks = [len(b) for b in reader.iter_blocks("/derived/orientation/wrist")]
        imu, quat = reader.read("/imu/wrist"), reader.read("/derived/orientation/wrist").values
        bids.export_bids(reader, tmp_path / "bids")
    assert len(blocks) >= 2 and blocks != quat_blocks  # boundaries differ: the rows are lined up across them
    motion = next((tmp_path / "bids").rglob("*_motion.tsv"))
    names = [r["name"] for r in _rows(motion.with_name(motion.name.replace("_motion.tsv", "_channels.tsv")))]
    table = np.loadtxt(motion, delimiter="\t")
    assert table.shape == (100_000, 11)
    np.testing.assert_array_equal(table[:, names.index("wrist_acc_z")], imu.acc[:, 2])
    for k, comp in enumerate(("quat_w", "quat_x", "quat_y", "quat_z")):
        np.testing.assert_array_equal(table[:, names.index(f"wrist_{comp}")], quat[:, k])

    monkeypatch.setattr(bids, "matrix_tsv", lambda columns: "")  # the text's pieces: the test above

    def peak(trial) -> int:
        tracemalloc.start()
        try:
            with TrialReader(trial) as reader:
                bids.export_bids(reader, tmp_path / f"bids_{trial.stem}")
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    big = _oriented_trial(tmp_path / "big.mcap", 400_000)
    grown = peak(big) - peak(small)
    whole = 300_000 * 8 * (1 + 6 + 4 + 1)  # the 300,000 more samples read at once: t_ns, acc, gyr, quat, latency
    # 9.4 MB more here, not from the file's length: the small trial's orientation is one chunk, read without the
    # next chunk decompressed ahead; beyond, each block's peak is bounded (benchmarks/reader_memory.py). Whole: 28.8 MB
    assert grown < whole / 2, (grown, whole)


def test_the_orientation_line_up_holds_two_blocks_at_most():
    """The quaternions are lined up with the IMU's blocks through bids._Rows. It concatenated what was left with
    each new block and kept a view of the copy: up to about three blocks, and its traced peak grew with the
    channel (12.9 MB at 400,000 rows, 14.0 MB at 1.6 M, for the orientation's 112,750-row blocks taken 42,500 at
    a time, as an oriented trial at 50 Hz has them). Now: at most the two blocks the rows are in plus one take's
    copy, whatever the length, and the rows handed out are the channel's, in order."""
    import tracemalloc
    from types import SimpleNamespace

    from imulog.export.bids import _Rows

    block, take = 112_750, 42_500
    row_bytes = 8 + 4 * 8  # t_ns and a quaternion

    def blocks(total: int):
        for lo in range(0, total, block):
            n = min(block, total - lo)
            yield SimpleNamespace(t_ns=np.arange(lo, lo + n, dtype=np.int64), values=np.full((n, 4), lo / 1.0))

    def run(total: int) -> None:
        rows, done = _Rows(blocks(total)), 0
        while done < total:
            t, v = rows.take(min(take, total - done))
            if not tracemalloc.is_tracing():  # the values once, untraced
                np.testing.assert_array_equal(t, np.arange(done, done + len(t)))
                np.testing.assert_array_equal(v[:, 0], (t // block * block).astype(float))
            done += len(t)
        assert rows.take(1) is None and rows.exhausted()

    def peak(total: int) -> int:
        tracemalloc.start()
        try:
            run(total)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    run(400_000)
    short, long = peak(400_000), peak(1_600_000)
    assert abs(long - short) < 100_000, (short, long)  # not with the length
    assert long < 1.1 * (2 * block + take) * row_bytes, long  # two blocks and one take's copy (10.7 MB)
