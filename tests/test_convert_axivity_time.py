"""Axivity .cwa sample times against scikit-digital-health's decode (../shared/data/devices/axivity_cwa/*_data.npz),
and skipping damaged blocks as gaps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError, ConvertOptions
from imulog.converters.axivity import (
    BLOCK_BYTES,
    BLOCK_DTYPE,
    HEADER_BYTES,
    MAGIC_AX,
    rate_from_code,
    read_cwa,
    rtc_to_epoch_s,
)


@pytest.fixture(scope="module")
def cwa_dir(shared_data: Path) -> Path:
    return shared_data / "devices" / "axivity_cwa"


def _blocks(path: Path) -> np.ndarray:
    b = np.fromfile(path, dtype=BLOCK_DTYPE, offset=HEADER_BYTES)
    return b[b["magic"] == MAGIC_AX]


def _abs_s(rec) -> np.ndarray:
    start = np.datetime64(rec.metadata["imulog.trial"]["start_time"], "ns").astype(np.int64)
    return (start + rec.imus[0].t_ns) / 1e9


def skdh_rule_s(b: np.ndarray) -> np.ndarray:
    """scikit-digital-health's sample times (read_axivity.f95 get_time): block start RTC - timestampOffset / rate
    (no fraction, no shim), moved to the previous block's nominal end when that is less than 1 s before."""
    f = rate_from_code(b["rate_code"])
    n = b["count"].astype(np.float64)
    t0 = rtc_to_epoch_s(b["rtc"]).astype(np.float64) - b["offset"] / f
    t1 = t0 + n / f
    s = t0.copy()
    s[1:] = np.where(t0[1:] - t1[:-1] < 1.0, t1[:-1], t0[1:])
    return np.concatenate([s[k] + np.arange(int(n[k])) * (t1[k] - s[k]) / n[k] for k in range(len(b))])


def openmovement_block_start_s(b: np.ndarray) -> np.ndarray:
    """OpenMovement's block start: RTC + fraction - (timestampOffset + shim) / rate, shim = fraction * int(rate)."""
    f = rate_from_code(b["rate_code"])
    frac = (b["fractional"].astype(np.int64) & 0x7FFF) << 1
    shim = (frac * f.astype(np.int64)) >> 16
    return rtc_to_epoch_s(b["rtc"]) + frac / 65536 - (b["offset"] + shim) / f


@pytest.mark.parametrize("kind", ["ax3", "ax6"])
def test_time_difference_to_skdh_is_its_rule(cwa_dir: Path, kind: str):
    """The ~10 ms between imulog and skdh: skdh's own rule reproduces its decode to 0.1 ms; imulog's block starts
    are OpenMovement's (and GGIRread's) to 1 us. The difference is skdh dropping the fractional time stamp."""
    path = cwa_dir / f"{kind}_sample.cwa"
    ref = np.load(cwa_dir / f"{kind}_data.npz")
    b = _blocks(path)
    assert np.abs(skdh_rule_s(b) - ref["time"]).max() < 1e-4
    rec = read_cwa(path)
    t = _abs_s(rec)
    first = np.concatenate([[0], np.cumsum(b["count"].astype(np.int64))[:-1]])
    om = openmovement_block_start_s(b)
    rel = rec.imus[0].t_ns[first] / 1e9
    np.testing.assert_allclose(rel, om - om[0], atol=1e-6, rtol=0)
    assert abs(om[0] - t[0]) < 1e-6  # start_time keeps the microseconds
    d = t - ref["time"]
    rate = float(ref["fs"][0])
    assert 0.5 / rate < np.median(d) < 2.5 / rate  # the published gap, explained above


@pytest.mark.parametrize("kind", ["ax3", "ax6"])
def test_block_starts_equal_openmovements_own_parser(cwa_dir: Path, kind: str):
    """Every block's first sample at the time OpenMovement's Python parser (openmovement, BSD, the manufacturer's
    project; dev extra) estimates for it, within 1 us: AX6 as well as AX3. Its ``estimatedFirstSampleTime`` reads
    the RTC as UTC, like the trial's naive local start_time read here."""
    cwa_load = pytest.importorskip("openmovement.load.cwa_load")
    path = cwa_dir / f"{kind}_sample.cwa"
    data = path.read_bytes()
    est, counts = [], []
    for k in range(HEADER_BYTES, len(data), BLOCK_BYTES):
        block = cwa_load._parse_cwa_data(data[k : k + BLOCK_BYTES])
        if block.get("sampleCount"):
            est.append(block["estimatedFirstSampleTime"])
            counts.append(block["sampleCount"])
    rec = read_cwa(path)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    assert len(rec.imus[0]) == sum(counts)
    np.testing.assert_allclose(_abs_s(rec)[first], est, atol=1e-6, rtol=0)


def _flip(src: Path, tmp_path: Path, blocks: list[int]) -> Path:
    data = bytearray(src.read_bytes())
    for k in blocks:
        data[HEADER_BYTES + k * BLOCK_BYTES + 200] ^= 0x04
    out = tmp_path / "damaged.cwa"
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("chunk", [None, 17, 18])
def test_skip_damaged_blocks_as_gaps(cwa_dir: Path, tmp_path: Path, chunk):
    from imulog.converters._binary import concat_chunks
    from imulog.converters.axivity import iter_chunks

    src = cwa_dir / "ax6_sample.cwa"
    good = read_cwa(src).imus[0]
    bad = _flip(src, tmp_path, [17, 18, 40])
    with pytest.raises(ConversionError, match="data block 17"):
        read_cwa(bad)
    opts = ConvertOptions(extra={"skip_damaged": True})
    rec = read_cwa(bad, opts) if chunk is None else concat_chunks(iter_chunks(bad, opts, blocks_per_chunk=chunk))
    imu = rec.imus[0]
    meta = rec.metadata[next(k for k in rec.metadata if k.startswith("imulog.device."))]
    assert meta["skipped_damaged_blocks"] == 3
    assert meta["gaps"] == 2
    runs = sorted(w for w in rec.warnings if "damaged" in w)
    assert any("data blocks 17-18" in w for w in runs) and any("data blocks 40-40" in w for w in runs)
    # the intact samples keep their values; the skipped ones are NaN rows on the nominal grid
    n = 40  # samples per AX6 block
    finite = np.isfinite(imu.acc[:, 0])
    np.testing.assert_array_equal(imu.acc[finite], np.delete(good.acc, np.r_[17 * n : 19 * n, 40 * n : 41 * n], 0))
    # 3 blocks of 40 samples at the device's real ~98.4 Hz, on the nominal 100 Hz grid: 120 + ~2 per skipped block
    assert (~finite).sum() == meta["gap_samples"] and 120 <= meta["gap_samples"] <= 126
    # the block after the skipped run keeps its own start time
    after = np.nonzero(finite)[0][17 * n]
    assert imu.t_ns[after] == good.t_ns[19 * n]
    assert np.all(np.diff(imu.t_ns) > 0)


def test_skip_damaged_from_the_command_line(cwa_dir: Path, tmp_path: Path):
    from click.testing import CliRunner

    from imulog.cli import cli

    bad = _flip(cwa_dir / "ax6_sample.cwa", tmp_path, [17])
    out = tmp_path / "t.mcap"
    refused = CliRunner().invoke(cli, ["convert", str(bad), "-o", str(out)])
    assert refused.exit_code != 0 and "data block 17" in refused.output and "--skip-damaged" in refused.output
    assert not out.exists()
    done = CliRunner().invoke(cli, ["convert", str(bad), "-o", str(out), "--skip-damaged"])
    assert done.exit_code == 0, done.output
    assert out.exists() and "damaged" in done.output


GGIRREAD = Path(__file__).parent / "data"  # GGIRread's AX3 test files (Apache-2.0; ggirread_testfiles.md)


def _unxz(name: str, tmp_path: Path) -> Path:
    import lzma

    out = tmp_path / name.removesuffix(".xz")
    out.write_bytes(lzma.decompress((GGIRREAD / name).read_bytes()))
    return out


@pytest.mark.parametrize("chunk", [None, 13, 50])
def test_real_damaged_file_skips_exactly_the_damaged_blocks(tmp_path: Path, chunk):
    """GGIRread's real AX3 file with data blocks 0, 13, 14, 142, 143 and 144 damaged, against the intact file it
    was made from: refused by default naming block 0; with skip_damaged the three runs are named, counted, the
    intact samples equal the intact file's exactly (times to 1 us, the block before a run to 0.2 ms: its samples
    take the previous block's measured rate), and the run inside the recording is a gap of NaN samples."""
    from imulog.converters._binary import concat_chunks
    from imulog.converters.axivity import iter_chunks

    bad = _unxz("ax3_testfile_corrupt_blocks_0_13_14_142_143_144.cwa.xz", tmp_path)
    intact = read_cwa(_unxz("ax3_testfile.cwa.xz", tmp_path))
    with pytest.raises(ConversionError, match=r"data block 0 \(byte 1024\): checksum mismatch.*--skip-damaged"):
        read_cwa(bad)
    opts = ConvertOptions(extra={"skip_damaged": True})
    rec = read_cwa(bad, opts) if chunk is None else concat_chunks(iter_chunks(bad, opts, blocks_per_chunk=chunk))
    runs = [w.split(": ")[1].split(" damaged")[0] for w in rec.warnings if "damaged" in w]
    assert runs == ["data blocks 0-0", "data blocks 13-14", "data blocks 142-144"]
    meta = rec.metadata[next(k for k in rec.metadata if k.startswith("imulog.device."))]
    assert meta["skipped_damaged_blocks"] == 6 and meta["gaps"] == 1
    imu, ref = rec.imus[0], intact.imus[0]
    n = 120  # samples per AX3 packed block
    block = np.arange(len(ref)) // n
    kept = ((block >= 1) & (block <= 12)) | ((block >= 15) & (block <= 141))
    finite = np.isfinite(imu.acc[:, 0])
    np.testing.assert_array_equal(imu.acc[finite], ref.acc[kept])
    dt = np.abs(_abs_s(rec)[finite] - _abs_s(intact)[kept])
    before_gap = np.isin(block[kept], [12, 141])
    assert dt[~before_gap].max() < 1e-6 and dt[before_gap].max() < 2e-4
    # blocks 13-14 (2 x 120 samples at the device's ~98.8 Hz) are NaN rows on the nominal 100 Hz grid
    assert (~finite).sum() == meta["gap_samples"] and 240 <= meta["gap_samples"] <= 246
    assert np.all(np.diff(imu.t_ns) > 0)


def test_held_out_ax6_csv_export_follows_skdhs_rule(tmp_path: Path):
    """Held out: GGIR's ax6_testfile_formatted_timestamps.csv is a CSV export of GGIRread's ax6_testfile.cwa
    (its first 8 blocks kept in tests/data). Its values equal imulog's .cwa decode and its axivity-csv reading;
    its time stamps follow scikit-digital-health's rule (no fraction, blocks chained) to its 1 ms print
    resolution, so imulog's .cwa times, OpenMovement's block starts, are ~10 ms later than that export."""
    from imulog.converters import convert_file

    cwa = _unxz("ax6_testfile_first8blocks.cwa.xz", tmp_path)
    csv = _unxz("ax6_testfile_formatted_timestamps.csv.xz", tmp_path)
    rec, exported = read_cwa(cwa), convert_file(csv)
    imu, ex = rec.imus[0], exported.imus[0]
    n = len(ex)
    assert n == 210 and len(imu) == 320
    np.testing.assert_allclose(ex.acc, imu.acc[:n], rtol=0, atol=1e-6 * 9.80665)  # g printed to 6 decimals
    np.testing.assert_allclose(ex.gyr, imu.gyr[:n], rtol=0, atol=np.radians(1e-5))  # deg/s to 6 decimals
    csv_s = _abs_s(exported)
    skdh_s = skdh_rule_s(_blocks(cwa))[:n]
    assert np.abs(skdh_s - csv_s).max() < 1.001e-3
    late_ms = (_abs_s(rec)[:n] - csv_s) * 1e3
    assert 9 < np.median(late_ms) < 11 and late_ms.max() < 15
