"""Axivity .cwa: the real AX3 and AX6 samples (scikit-digital-health, MIT) against skdh's reference decodes,
block checksums, fractional block time stamps, chunked reading, and clean failures on damaged files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, detect
from imulog.converters._common import G0
from imulog.converters.axivity import BLOCK_BYTES, HEADER_BYTES, block_start_ns, iter_chunks, read_cwa

from imulog.archive import TrialReader
from imulog.cli import cli


@pytest.fixture(scope="module")
def cwa_dir(shared_data: Path) -> Path:
    return shared_data / "devices" / "axivity_cwa"


def _abs_times_s(rec) -> np.ndarray:
    start = np.datetime64(rec.metadata["imulog.trial"]["start_time"], "ns")
    origin = (start - np.datetime64("1970-01-01T00:00:00", "ns")).astype(np.int64)
    return (origin + rec.imus[0].t_ns) / 1e9


@pytest.mark.parametrize("kind", ["ax3", "ax6"])
def test_values_match_skdh_reference(cwa_dir: Path, kind: str):
    rec = read_cwa(cwa_dir / f"{kind}_sample.cwa")
    ref = np.load(cwa_dir / f"{kind}_data.npz")
    imu = rec.imus[0]
    assert len(imu) == len(ref["time"])
    np.testing.assert_allclose(imu.acc / G0, ref["accel"], atol=5e-5, rtol=0)  # skdh's own tolerance, g
    if kind == "ax6":
        np.testing.assert_allclose(np.degrees(imu.gyr), ref["gyro"], atol=1e-4, rtol=0)
        np.testing.assert_allclose(np.degrees(imu.gyr[0]), [-66.223145, -27.221678, 104.73632], atol=1e-4)
    else:
        assert imu.gyr is None
        np.testing.assert_allclose(imu.acc[0] / G0, [-0.09375, -0.203125, 0.953125], atol=1e-12)
    # times: skdh's rule is the default (tests/test_convert_axivity_time.py), equal to its decode within 0.1 ms
    assert np.abs(_abs_times_s(rec) - ref["time"]).max() < 1e-4
    assert np.all(np.diff(imu.t_ns) > 0)
    # one signal row per block: temperature as skdh computes it, light counts, battery volts
    sig = rec.signals[0]
    per_block = len(imu) // len(sig)
    # temperature: OpenMovement's raw * 75 / 256 - 50; skdh's reference uses (raw - 171) / 3.142: same raw values
    raw_ours = (sig.values[:, 1] + 50.0) * 256.0 / 75.0
    raw_skdh = ref["temperature"][::per_block] * 3.142 + 171.0
    np.testing.assert_allclose(raw_ours, raw_skdh, atol=1e-4)
    np.testing.assert_array_equal(raw_ours, np.round(raw_ours))
    assert 20.0 < np.median(sig.values[:, 1]) < 35.0
    assert sig.columns == ["light", "temperature", "battery"] and sig.units == ["counts", "degC", "V"]
    assert np.all((sig.values[:, 2] > 3.0) & (sig.values[:, 2] < 4.4))


def test_fractional_time_stamps_make_blocks_regular(cwa_dir: Path):
    """With the fraction (and the offset it implies) block starts are regular to < 1 ms; without, to 1/rate."""
    data = np.fromfile(cwa_dir / "ax3_sample.cwa", dtype=np.uint8)[HEADER_BYTES:].reshape(-1, BLOCK_BYTES)
    from imulog.converters.axivity import BLOCK_DTYPE

    blocks = data.view(BLOCK_DTYPE).ravel()
    d_ms = np.diff(block_start_ns(blocks)) / 1e6
    assert d_ms.std() < 1.0
    assert abs(np.median(d_ms) - 608.4) < 0.5  # 120 samples at the device's real ~197.2 Hz


def test_metadata_and_start_time(cwa_dir: Path):
    rec = read_cwa(cwa_dir / "ax3_sample.cwa")
    trial = rec.metadata["imulog.trial"]
    assert trial["start_time"].startswith("2020-02-12T09:03:3")
    assert trial["time_zone"] == "unknown (device local time)"
    dev = rec.metadata["imulog.device.ax3_51888"]
    assert dev["rate_hz"] == 200.0 and dev["accel_range_g"] == 8 and dev["serial"] == "51888"
    rec6 = read_cwa(cwa_dir / "ax6_sample.cwa")
    dev6 = rec6.metadata[f"imulog.device.{rec6.imus[0].name}"]
    assert dev6["model"] == "Axivity AX6" and dev6["gyro_range_dps"] == 2000 and dev6["accel_lsb_per_g"] == 2048
    assert rec6.metadata["imulog.trial"]["start_time"].startswith("2019-10-29T09:03:0")


def test_chunks_assemble_to_the_whole_file(cwa_dir: Path):
    path = cwa_dir / "ax3_sample.cwa"
    whole = read_cwa(path)
    chunks = list(iter_chunks(path, blocks_per_chunk=64))
    assert len(chunks) == 8  # 490 blocks
    t = np.concatenate([c.imus[0].t_ns for c in chunks])
    acc = np.concatenate([c.imus[0].acc for c in chunks])
    np.testing.assert_array_equal(t, whole.imus[0].t_ns)
    np.testing.assert_array_equal(acc, whole.imus[0].acc)


def _with_fixed_checksum(block: np.ndarray) -> np.ndarray:
    words = block.view("<u2").copy()
    words[-1] = 0
    words[-1] = (-int(words.sum(dtype=np.uint64))) & 0xFFFF
    return words.view(np.uint8)


def test_partly_filled_last_block(cwa_dir: Path, tmp_path: Path):
    """A block may hold fewer samples than it can (``sampleCount``): only those are read."""
    src = cwa_dir / "ax6_sample.cwa"
    data = np.frombuffer(src.read_bytes(), dtype=np.uint8).copy()
    last = data[-BLOCK_BYTES:].copy()
    last[28:30] = np.frombuffer(np.uint16(25).tobytes(), dtype=np.uint8)  # sampleCount 40 -> 25
    data[-BLOCK_BYTES:] = _with_fixed_checksum(last)
    path = tmp_path / "partial.cwa"
    path.write_bytes(data.tobytes())
    whole = read_cwa(src).imus[0]
    part = read_cwa(path).imus[0]
    assert len(part) == len(whole) - 15
    np.testing.assert_array_equal(part.acc, whole.acc[: len(part)])
    np.testing.assert_array_equal(part.t_ns, whole.t_ns[: len(part)])


@pytest.mark.parametrize("rule", ["skdh", "openmovement"])
def test_a_pause_becomes_nan_samples(cwa_dir: Path, tmp_path: Path, rule: str):
    """Blocks missing from the middle (the device stopped for 20 s): the samples that would fit are NaN on the
    nominal grid (the project's gap rule), the recorded samples are untouched. By skdh's rule the block after the
    pause starts at its own time, not chained to the block before it (skdh's rule on the cut file, to 1 us); by
    OpenMovement's every block keeps its start."""
    from imulog.converters import ConvertOptions

    opts = ConvertOptions(extra={"cwa_times": rule})
    src = cwa_dir / "ax6_sample.cwa"
    data = src.read_bytes()
    cut = HEADER_BYTES + 100 * BLOCK_BYTES
    path = tmp_path / "pause.cwa"
    path.write_bytes(data[:cut] + data[cut + 50 * BLOCK_BYTES :])
    whole = read_cwa(src, opts).imus[0]
    rec = read_cwa(path, opts)
    imu = rec.imus[0]
    missing = np.isnan(imu.acc).any(axis=1)
    run = np.nonzero(missing)[0]
    assert len(run) and np.array_equal(run, np.arange(run[0], run[-1] + 1))  # one contiguous run
    assert run[0] == 100 * 40 and abs(len(run) - 50 * 40) <= 40  # ~ the 2000 samples of 50 blocks at 100 Hz
    assert np.all(np.diff(imu.t_ns) > 0)
    np.testing.assert_array_equal(imu.acc[~missing], np.concatenate([whole.acc[:4000], whole.acc[6000:]]))
    after = 4040 if rule == "skdh" else 4000  # skdh: the first block after the pause is not chained
    np.testing.assert_array_equal(imu.t_ns[~missing][after:], whole.t_ns[6000 + after - 4000 :])
    if rule == "skdh":
        from cwa_rules import ax_blocks, skdh_rule_s  # skdh itself aborts on a file whose sequence ids skip

        ref = skdh_rule_s(ax_blocks(path))
        np.testing.assert_allclose(_abs_times_s(rec)[~missing], ref, atol=1e-6, rtol=0)
    np.testing.assert_allclose(np.diff(imu.t_ns[run]), 1e7, atol=1)  # 100 Hz
    dev = rec.metadata[f"imulog.device.{imu.name}"]
    assert dev["gaps"] == 1 and dev["gap_samples"] == len(run)


def _synthetic_cwa(tmp_path: Path, src: Path, axes_bps: int, count: int, values: np.ndarray, light: int) -> Path:
    """The real file's header and first two blocks, re-encoded with another sample format (checksums fixed)."""
    data = np.frombuffer(src.read_bytes(), dtype=np.uint8)
    head, blocks = (
        data[:HEADER_BYTES],
        data[HEADER_BYTES : HEADER_BYTES + 2 * BLOCK_BYTES].reshape(2, BLOCK_BYTES).copy(),
    )
    for b, vals in zip(blocks, np.array_split(values, 2), strict=True):
        b[25] = axes_bps
        b[28:30] = np.frombuffer(np.uint16(count).tobytes(), dtype=np.uint8)
        b[18:20] = np.frombuffer(np.uint16(light).tobytes(), dtype=np.uint8)
        raw = vals.astype("<i2").tobytes()
        b[30 : 30 + len(raw)] = np.frombuffer(raw, dtype=np.uint8)
        b[:] = _with_fixed_checksum(b)
    path = tmp_path / f"synthetic_{axes_bps:02x}.cwa"
    path.write_bytes(head.tobytes() + blocks.tobytes())
    return path


def test_unpacked_3_axis_and_9_axis_blocks(cwa_dir: Path, tmp_path: Path):
    rng = np.random.default_rng(5)
    # AX3 unpacked int16 (0x32): 80 samples per block, 1 g = 256 (light scale bits 0)
    v3 = rng.integers(-4096, 4096, size=(160, 3))
    rec = read_cwa(_synthetic_cwa(tmp_path, cwa_dir / "ax3_sample.cwa", 0x32, 80, v3, light=0x0100))
    np.testing.assert_allclose(rec.imus[0].acc / G0, v3 / 256.0, rtol=1e-12)
    # AX6 with magnetometer (0x92): gyro, accel, mag; 26 samples per block; accel 1/2^(8+3) g, gyro 8000/2^2 dps
    v9 = rng.integers(-30000, 30000, size=(52, 9))
    light = (3 << 13) | (2 << 10) | 0x40
    rec = read_cwa(_synthetic_cwa(tmp_path, cwa_dir / "ax6_sample.cwa", 0x92, 26, v9, light=light))
    imu = rec.imus[0]
    np.testing.assert_allclose(np.degrees(imu.gyr), v9[:, 0:3] * 2000.0 / 32768.0, rtol=1e-12)
    np.testing.assert_allclose(imu.acc / G0, v9[:, 3:6] / 2048.0, rtol=1e-12)
    np.testing.assert_allclose(imu.mag, v9[:, 6:9] / 16.0, rtol=1e-12)
    assert rec.signals[0].values[0, 0] == 0x40  # light counts: the low 10 bits only


def test_detected_and_converted_by_the_cli(cwa_dir: Path, tmp_path: Path):
    for kind in ("ax3", "ax6"):
        src = cwa_dir / f"{kind}_sample.cwa"
        assert detect(src).name == "axivity"
        out = tmp_path / f"{kind}.mcap"
        r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
        assert r.exit_code == 0, r.output
        r = CliRunner().invoke(cli, ["doctor", str(out)])
        assert r.exit_code == 0, r.output
        with TrialReader(out) as trial:
            topics = trial.topics()
            imu_topic = next(t for t in topics if t.startswith("/imu/"))
            assert trial.read(imu_topic).acc.shape[0] == (58800 if kind == "ax3" else 10360)
            assert any(t.startswith("/signals/") for t in topics)
            assert trial.metadata["imulog.trial"]["time_zone"] == "unknown (device local time)"


def _damaged(tmp_path: Path, src: Path, how: str) -> Path:
    data = bytearray(src.read_bytes())
    if how == "truncate":
        data = data[: HEADER_BYTES + 17 * BLOCK_BYTES + 100]
    else:  # one flipped bit in a sample of data block 17
        data[HEADER_BYTES + 17 * BLOCK_BYTES + 200] ^= 0x04
    out = tmp_path / f"{how}.cwa"
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("how", ["truncate", "flip"])
def test_damaged_file_one_line_error_and_no_output(cwa_dir: Path, tmp_path: Path, how: str):
    bad = _damaged(tmp_path, cwa_dir / "ax6_sample.cwa", how)
    with pytest.raises(ConversionError) as e:
        read_cwa(bad)
    msg = str(e.value)
    assert "\n" not in msg and bad.name in msg
    assert "data block 17" in msg
    assert ("truncated" in msg) if how == "truncate" else ("checksum" in msg)
    out = tmp_path / "out.mcap"
    r = CliRunner().invoke(cli, ["convert", str(bad), "-o", str(out)])
    assert r.exit_code != 0 and "data block 17" in r.output
    assert not out.exists() and not list(tmp_path.glob("*.mcap*"))
