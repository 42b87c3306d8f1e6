"""NilsPod .bin (../shared/data/devices/nilspod, NilsPodLib's test session, fw 0.18) against NilsPodLib's own decode
shipped beside it (_data.csv, _header.json), and that CSV + JSON pair read on its own."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, convert_file, detect
from imulog.converters.nilspod import parse_header, read_bin

from imulog.cli import cli

STEM = "devices/nilspod/NilsPodX-6F13_20210109_162824"


def _ref(shared_data: Path) -> tuple[dict, dict[str, np.ndarray]]:
    hdr = json.loads((shared_data / f"{STEM}_header.json").read_text())
    lines = (shared_data / f"{STEM}_data.csv").read_text().splitlines()
    names = lines[0].split(",")
    table = np.array([[float(v) for v in x.split(",")] for x in lines[1:]])
    return hdr, {n: table[:, i] for i, n in enumerate(names)}


def test_bin_equals_nilspodlib_decode(shared_data: Path):
    path = shared_data / f"{STEM}.bin"
    assert detect(path).name == "nilspod"
    hdr, ref = _ref(shared_data)
    mine = parse_header(path, path.read_bytes())
    for key in (
        "sample_size",
        "sampling_rate_hz",
        "acc_range_g",
        "gyro_range_dps",
        "utc_start",
        "utc_stop",
        "n_samples",
        "mac_address",
        "version_firmware",
        "sync_role",
        "session_termination",
    ):
        assert mine[key] == hdr[key], key
    assert mine["enabled_sensors"] == hdr["enabled_sensors"]
    rec = read_bin(path)
    (imu,) = rec.imus
    assert len(imu) == hdr["n_samples"] == 635
    np.testing.assert_allclose(imu.acc, np.column_stack([ref[f"acc_{a}"] for a in "xyz"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.degrees(imu.gyr), np.column_stack([ref[f"gyr_{a}"] for a in "xyz"]), atol=1e-12)
    np.testing.assert_allclose(imu.temperature, ref["temp"], atol=1e-12)
    np.testing.assert_allclose(imu.t_ns / 1e9, ref["t"], atol=1e-9)
    sig = rec.signals[0]
    assert sig.columns == ["mag_x", "mag_y", "mag_z", "baro", "analog_0", "analog_1", "analog_2"]
    np.testing.assert_allclose(sig.values, np.column_stack([ref[c] for c in sig.columns]), atol=1e-9)
    trial = rec.metadata["imulog.trial"]
    assert trial["time_zone"] == "UTC" and trial["start_time"].startswith("2021-01-09T15:28:24")
    assert not rec.warnings


def test_csv_with_header_json(shared_data: Path):
    path = shared_data / f"{STEM}_data.csv"
    assert detect(path).name == "nilspod"
    rec = convert_file(path)
    bin_rec = read_bin(shared_data / f"{STEM}.bin")
    np.testing.assert_allclose(rec.imus[0].acc, bin_rec.imus[0].acc, atol=1e-12)
    np.testing.assert_array_equal(rec.imus[0].t_ns, bin_rec.imus[0].t_ns)
    assert rec.metadata["imulog.trial"]["start_time"] == "2021-01-09T15:28:24+00:00"


def _bin(shared_data: Path, tmp_path: Path, damage) -> Path:
    data = bytearray((shared_data / f"{STEM}.bin").read_bytes())
    data = damage(data)
    out = tmp_path / "NilsPodX-bad.bin"
    out.write_bytes(bytes(data))
    return out


def test_counter_gap_and_damage(shared_data: Path, tmp_path: Path):
    size, hsz = 32, 52
    # drop samples 100..109: the counter jumps, a warning counts the missing samples
    cut = _bin(shared_data, tmp_path, lambda d: d[: hsz + 100 * size] + d[hsz + 110 * size :])
    rec = read_bin(cut)
    assert len(rec.imus[0]) == 625 and rec.imus[0].t_ns[100] - rec.imus[0].t_ns[99] == round(11e9 / 102.4)
    assert any("skips 10 samples in 1 places" in w for w in rec.warnings)
    swap = _bin(
        shared_data,
        tmp_path,
        lambda d: (
            d[: hsz + 5 * size]
            + d[hsz + 6 * size : hsz + 7 * size]
            + d[hsz + 5 * size : hsz + 6 * size]
            + d[hsz + 7 * size :]
        ),
    )
    with pytest.raises(ConversionError, match=r"sample 6: the counter does not increase"):
        read_bin(swap)
    old = _bin(shared_data, tmp_path, lambda d: d[:49] + bytes([0, 13, 0]) + d[52:])
    with pytest.raises(ConversionError, match=r"firmware v0\.13\.0: the header layout before v0\.14"):
        read_bin(old)
    wrong = _bin(shared_data, tmp_path, lambda d: d[:1] + bytes([30]) + d[2:])
    with pytest.raises(ConversionError, match=r"sample size 30 bytes, the enabled sensors need 32"):
        read_bin(wrong)


def test_cli_convert_and_doctor(shared_data: Path, tmp_path: Path):
    out = tmp_path / "np.mcap"
    r = CliRunner().invoke(cli, ["convert", str(shared_data / f"{STEM}.bin"), "-o", str(out)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["doctor", str(out)])
    assert r.exit_code == 0, r.output


def test_equals_nilspodlib_reader(shared_data: Path):
    nilspodlib = pytest.importorskip("nilspodlib")
    path = shared_data / f"{STEM}.bin"
    ds = nilspodlib.Dataset.from_bin_file(path)
    rec = read_bin(path)
    imu = rec.imus[0]
    np.testing.assert_allclose(imu.acc, ds.acc.data, atol=1e-12, rtol=0)
    np.testing.assert_allclose(np.degrees(imu.gyr), ds.gyro.data, atol=1e-12, rtol=0)
    np.testing.assert_allclose(imu.temperature, ds.temperature.data[:, 0], atol=1e-12)
    np.testing.assert_allclose(rec.signals[0].values[:, 3], ds.baro.data[:, 0], atol=1e-9)
    np.testing.assert_allclose(imu.t_ns / 1e9, ds.utc_counter - ds.utc_counter[0], atol=1e-9)
    start = np.datetime64(rec.metadata["imulog.trial"]["start_time"][:26], "us").astype(np.int64) / 1e6
    assert start == pytest.approx(ds.utc_counter[0], abs=1e-6)
