"""The HDF5 readers in pieces (issue 24, point 4): ``imulog convert`` of BROAD, APDM and OpenSignals ``.h5`` piece by
piece writes the archive it writes from the whole file, sample by sample (the comparison of
``tests/test_convert_pieces_archive.py``). BROAD: every trial in ``../shared/data/broad``. APDM and OpenSignals
``.h5``: no redistributable sample exists (``../shared/data/devices/README.md``), so files are written here in the
published layouts, with what pieces must not change: sensors of different lengths, a rate known only from all the
times (no ``Sample Rate`` attribute, jittered steps), lost samples (an ``nSeq`` jump), movement runs across piece
borders. Hostile files fail with the whole file's one-line error, piece by piece too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_convert_pieces_archive import assert_same_trial, convert_twice

from imulog.archive import TrialReader
from imulog.cli import cli

h5py = pytest.importorskip("h5py")

PIECES = "imulog.converters._h5pieces.PIECE_BYTES"
BROAD = ["02_undisturbed_slow_rotation_B", "05_undisturbed_slow_rotation_with_breaks_B"]
BROAD += ["14_undisturbed_slow_translation_with_breaks_B"]


def test_every_shared_broad_trial_is_a_case(shared_data):
    assert sorted(p.stem for p in (shared_data / "broad").glob("*.hdf5")) == sorted(BROAD)


@pytest.mark.parametrize("stem", BROAD)
def test_broad_pieces_write_the_whole_files_archive(stem, shared_data, tmp_path, monkeypatch):
    src = shared_data / "broad" / f"{stem}.hdf5"
    with h5py.File(src, "r") as f:
        n = len(f["imu_acc"])
        mask = np.asarray(f["movement"], bool) if "movement" in f else np.zeros(n, bool)
    rows = n // 7 + 13  # about 8 pieces, borders at no round sample
    whole, pieces = convert_twice(src, tmp_path, (PIECES, rows * 8 * 16), monkeypatch)
    assert_same_trial(whole, pieces)
    with TrialReader(whole) as a, TrialReader(pieces) as b:
        for topic in ("/imu/imu", "/poses/optical"):
            nans = np.count_nonzero(~np.isfinite(getattr(a.read(topic), "acc" if "imu" in topic else "position")))
            assert nans == 0 or topic == "/poses/optical"
            if topic == "/imu/imu":
                assert a.channel(topic).metadata["nan_samples"] == b.channel(topic).metadata["nan_samples"] == "0"
    borders = np.arange(rows, n, rows)
    if "with_breaks" in stem:  # the movement runs (events) cross piece borders and stay one run each
        assert mask[borders - 1].any() and mask[borders].any()


def test_streamed_pose_counts_nan_orientation_as_the_whole_file(shared_data, tmp_path, monkeypatch):
    """BROAD's optical orientation is NaN where tracking was lost: the whole-file writer counts those samples."""
    src = shared_data / "broad" / f"{BROAD[0]}.hdf5"
    whole, pieces = convert_twice(src, tmp_path, (PIECES, 1 << 20), monkeypatch)
    with TrialReader(whole) as a, TrialReader(pieces) as b:
        assert (
            a.channel("/poses/optical").metadata["nan_samples"] == b.channel("/poses/optical").metadata["nan_samples"]
        )


def write_apdm(path: Path, lengths: tuple[int, ...] = (3000, 2500), jitter: bool = True) -> None:
    """An APDM format-5 file: sensors of ``lengths`` samples; the first without ``Sample Rate`` and (``jitter``)
    with steps of 7812-7813 us and a late sample, so its rate is the median of all its steps."""
    rng = np.random.default_rng(5)
    t0 = 1_600_000_000_000_000
    with h5py.File(path, "w") as f:
        for k, n in enumerate(lengths):
            cid = f"XI-0{k}0203"
            g = f.create_group(f"Sensors/{cid}")
            cfg = g.create_group("Configuration")
            cfg.attrs["Label 0"] = f"Sensor {k}".encode()
            cfg.attrs["Timezone Offset"] = 2.0
            if k or not jitter:
                cfg.attrs["Sample Rate"] = np.uint16(128)
            steps = np.full(n - 1, 7812, np.uint64)
            if jitter and k == 0:
                steps = 7812 + rng.integers(0, 2, n - 1).astype(np.uint64)
                steps[n // 2] += 40_000
            g["Time"] = t0 + 1000 * k + np.concatenate([[0], np.cumsum(steps)]).astype(np.uint64)
            g["Accelerometer"] = rng.normal(0, 1, (n, 3)) + [0, 0, 9.81]
            g["Gyroscope"] = rng.normal(0, 0.3, (n, 3))
            g["Magnetometer"] = rng.normal(20, 5, (n, 3))
            g["Temperature"] = 30 + rng.normal(0, 0.1, n)
            g["Barometer"] = 101 + rng.normal(0, 0.01, n)
            q = rng.normal(0, 1, (n, 4))
            f.create_group(f"Processed/{cid}")["Orientation"] = q / np.linalg.norm(q, axis=1, keepdims=True)


def test_apdm_h5_pieces_write_the_whole_files_archive(tmp_path, monkeypatch):
    src = tmp_path / "apdm.h5"
    write_apdm(src)
    whole, pieces = convert_twice(src, tmp_path, (PIECES, 333 * 8 * 28), monkeypatch)
    assert_same_trial(whole, pieces)
    with h5py.File(src, "r") as f:
        steps_us = np.diff(f["Sensors/XI-000203/Time"][()].astype(np.int64))
    with TrialReader(pieces) as tr:  # the rate of the sensor without one: the median of all its steps
        assert tr.metadata["imulog.device.sensor_0"]["rate_hz"] == 1e6 / float(np.median(steps_us))


def test_apdm_h5_format_3_pieces(tmp_path, monkeypatch):
    """The older layout (CaseIdList, /<id>/Calibrated/...) in pieces."""
    rng = np.random.default_rng(9)
    n = 1000
    src = tmp_path / "20140126-134055-Base.h5"
    with h5py.File(src, "w") as f:
        f.attrs["CaseIdList"] = np.array([b"SI-001007"])
        f.attrs["MonitorLabelList"] = np.array([b"Left Wrist"])
        g = f.create_group("SI-001007")
        g.attrs["SampleRate"] = np.uint16(128)
        g["Time"] = 1_390_000_000_000_000 + np.arange(n, dtype=np.uint64) * 7812
        g["Calibrated/Accelerometers"] = rng.normal(0, 1, (n, 3))
        g["Calibrated/Gyroscopes"] = rng.normal(0, 1, (n, 3))
    whole, pieces = convert_twice(src, tmp_path, (PIECES, 100 * 8 * 7), monkeypatch)
    assert_same_trial(whole, pieces)


def write_opensignals(path: Path) -> None:
    """Two devices of different lengths; the first's nSeq jumps once (lost samples: a warning), both BITalino."""
    rng = np.random.default_rng(4)
    with h5py.File(path, "w") as f:
        for k, (mac, n) in enumerate((("00:07:80:3B:46:61", 4000), ("00:07:80:3B:46:62", 3100))):
            g = f.create_group(mac)
            g.attrs["sampling rate"] = 1000
            g.attrs["resolution"] = [4, 10, 10, 10]
            g.attrs["device"] = "bitalino_rev"
            g.attrs["date"] = "2017-1-20"
            g.attrs["time"] = "14:40:49.587"
            raw = g.create_group("raw")
            seq = np.arange(n) % 16
            if k == 0:
                seq[2100:] = (seq[2100:] + 3) % 16
            raw["nSeq"] = seq.reshape(-1, 1)
            for j, sensor in enumerate(["EMG", "EDA", "ACC"]):
                raw[f"channel_{j + 1}"] = rng.integers(0, 1024, (n, 1))
                raw[f"channel_{j + 1}"].attrs["sensor"] = sensor


def test_opensignals_h5_pieces_write_the_whole_files_archive(tmp_path, monkeypatch):
    src = tmp_path / "opensignals_000780.h5"
    write_opensignals(src)
    whole, pieces = convert_twice(src, tmp_path, (PIECES, 301 * 8 * 8), monkeypatch)
    assert_same_trial(whole, pieces)
    with TrialReader(pieces) as tr:
        warnings = tr.metadata["imulog.conversion"]["warnings"]
    assert any("nSeq jumps at 1 row(s) (first sample 2100)" in w for w in warnings), warnings


def _convert(src: Path, out: Path, monkeypatch, piece_bytes: int | None) -> tuple[int, str]:
    import imulog.commands.convert_stream as cs

    monkeypatch.setattr(cs, "STREAM_MIN_BYTES", 0 if piece_bytes else 1 << 60)
    if piece_bytes:
        monkeypatch.setattr(PIECES, piece_bytes)
    r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
    return r.exit_code, r.output


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        ("late_backwards", "/Sensors/XI-000203/Time does not increase at sample 2999"),
        ("late_epoch", "/Sensors/XI-010203/Time sample 2400: "),
        ("late_nan", "non-finite IMU value at sample 2950"),
        ("apdm_rows", "/Sensors/1234/Time declares shape (2000000000,)"),  # tests/test_hostile_devices.py's files
        ("broad_rows", "imu_acc declares shape (2000000000, 3)"),
    ],
)
def test_damage_late_in_the_file_fails_with_the_whole_files_error(damage, message, tmp_path, monkeypatch):
    """What the whole file's checks find in its last rows fails before the first piece is written, with the same
    one line, and no archive is left; so does a data set declaring 2e9 rows it does not store."""
    if damage.endswith("_rows"):
        from test_hostile_devices import _apdm_h5, _broad_rows

        src = (
            _apdm_h5(tmp_path / "a.h5", rows=2_000_000_000) if damage == "apdm_rows" else _broad_rows(tmp_path / "b.h5")
        )
    elif damage == "late_nan":
        src = tmp_path / "b.hdf5"
        with h5py.File(src, "w") as f:
            f.attrs["sampling_rate"] = 100.0
            f["imu_acc"] = np.ones((3000, 3))
            gyr = np.zeros((3000, 3))
            gyr[2950, 1] = np.nan
            f["imu_gyr"] = gyr
    else:
        src = tmp_path / "a.h5"
        write_apdm(src, jitter=False)
        with h5py.File(src, "a") as f:
            if damage == "late_backwards":
                f["Sensors/XI-000203/Time"][2999] = 0
            else:
                t = f["Sensors/XI-010203/Time"][()]
                t[2400:] += np.uint64(200 * 365 * 86400 * 10**6)
                f["Sensors/XI-010203/Time"][...] = t
    lines = []
    for piece_bytes in (None, 4096):
        out = tmp_path / f"out_{piece_bytes}.mcap"
        code, output = _convert(src, out, monkeypatch, piece_bytes)
        assert code != 0 and message in output and not out.exists(), output
        lines.append(output.strip().splitlines()[-1])
    assert lines[0] == lines[1] and len(lines[0].splitlines()) == 1


@pytest.mark.parametrize("kind", ["broad", "apdm", "opensignals"])
def test_pieces_joined_are_the_whole_recording(kind, shared_data, tmp_path, monkeypatch):
    """The reader's own pieces, joined (``concat_chunks``), are its whole-file Recording: streams bit for bit,
    warnings, metadata (the ``imulog.pieces`` declaration dropped) and sources."""
    from imulog.converters.registry import get
    from test_convert_pieces import _pieces_equal_whole

    if kind == "broad":
        src, name = shared_data / "broad" / f"{BROAD[1]}.hdf5", "broad-hdf5"
    elif kind == "apdm":
        src, name = tmp_path / "apdm.h5", "apdm"
        write_apdm(src)
    else:
        src, name = tmp_path / "opensignals_000780.h5", "opensignals-h5"
        write_opensignals(src)
    conv = get(name)
    whole = conv.convert(src)
    monkeypatch.setattr(PIECES, 1 << 16)
    pieces = list(conv.iter_chunks(src))
    assert "imulog.pieces" in pieces[0].metadata
    _pieces_equal_whole(pieces, whole)
