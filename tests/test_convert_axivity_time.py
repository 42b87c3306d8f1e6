"""Axivity .cwa sample times: by default scikit-digital-health's rule, equal to its decode (the shipped
../shared/data/devices/axivity_cwa/*_data.npz and its reader run here) and to GGIR's CSV export; OpenMovement's
rule on request (``cwa_times``); skipping damaged blocks as gaps under both."""

from __future__ import annotations

import lzma
from pathlib import Path

import numpy as np
import pytest
from cwa_rules import ax_blocks, openmovement_block_start_s, skdh_own_start_s, skdh_rule_s
from imulog.converters import ConversionError, ConvertOptions
from imulog.converters.axivity import BLOCK_BYTES, HEADER_BYTES, read_cwa

OM = ConvertOptions(extra={"cwa_times": "openmovement"})
GGIRREAD = Path(__file__).parent / "data"  # GGIRread's test files (Apache-2.0; ggirread_testfiles.md)


@pytest.fixture(scope="module")
def cwa_dir(shared_data: Path) -> Path:
    return shared_data / "devices" / "axivity_cwa"


def _unxz(name: str, tmp_path: Path) -> Path:
    out = tmp_path / name.removesuffix(".xz")
    out.write_bytes(lzma.decompress((GGIRREAD / name).read_bytes()))
    return out


def _file(kind: str, cwa_dir: Path, tmp_path: Path) -> Path:
    if kind in ("ax3", "ax6"):
        return cwa_dir / f"{kind}_sample.cwa"
    return _unxz(
        {"ggirread_ax3": "ax3_testfile.cwa.xz", "ggirread_ax6": "ax6_testfile_first8blocks.cwa.xz"}[kind], tmp_path
    )


def _abs_s(rec) -> np.ndarray:
    start = np.datetime64(rec.metadata["imulog.trial"]["start_time"], "ns").astype(np.int64)
    return (start + rec.imus[0].t_ns) / 1e9


KINDS = ["ax3", "ax6", "ggirread_ax3", "ggirread_ax6"]


@pytest.mark.parametrize("kind", KINDS)
def test_default_times_equal_skdhs_decode(cwa_dir: Path, tmp_path: Path, kind: str):
    """Every sample at the time scikit-digital-health's own reader gives it (run here, to 1 us) and, for the shared
    samples, at the time of its shipped decode (to 0.1 ms: the .npz keeps fewer digits); the trial's start_time is
    its first sample. Before, imulog read these files 9-19 ms (median) later."""
    skdh_io = pytest.importorskip("skdh.io")
    path = _file(kind, cwa_dir, tmp_path)
    rec = read_cwa(path)
    t = _abs_s(rec)
    ref = np.asarray(skdh_io.ReadCwa().predict(file=str(path))["time"])
    assert len(t) == len(ref)
    np.testing.assert_allclose(t, ref, atol=1e-6, rtol=0)
    if kind in ("ax3", "ax6"):
        shipped = np.load(cwa_dir / f"{kind}_data.npz")["time"]
        assert np.abs(t - shipped).max() < 1e-4
        assert np.abs(skdh_rule_s(ax_blocks(path)) - shipped).max() < 1e-4  # the rule, restated independently
    assert rec.metadata[next(k for k in rec.metadata if k.startswith("imulog.device."))]["time_rule"] == "skdh"
    assert np.all(np.diff(rec.imus[0].t_ns) > 0)


@pytest.mark.parametrize("kind", KINDS)
def test_openmovement_rule_block_starts_equal_openmovements_own_parser(cwa_dir: Path, tmp_path: Path, kind: str):
    """With ``cwa_times="openmovement"`` (``--cwa-times openmovement``) every block's first sample is at the time
    OpenMovement's Python parser (openmovement, BSD, the manufacturer's project; dev extra) estimates for it, within
    1 us (GGIRread starts its blocks there too). Its ``estimatedFirstSampleTime`` reads the RTC as UTC, like the
    trial's naive local start_time read here. That rule reads the same files 0.5-2.5 samples later (median) than
    skdh's, which drops the fraction of the block's second."""
    cwa_load = pytest.importorskip("openmovement.load.cwa_load")
    path = _file(kind, cwa_dir, tmp_path)
    data = path.read_bytes()
    est, counts = [], []
    for k in range(HEADER_BYTES, len(data), BLOCK_BYTES):
        block = cwa_load._parse_cwa_data(data[k : k + BLOCK_BYTES])
        if block.get("sampleCount"):
            est.append(block["estimatedFirstSampleTime"])
            counts.append(block["sampleCount"])
    rec = read_cwa(path, OM)
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    assert len(rec.imus[0]) == sum(counts)
    t = _abs_s(rec)
    np.testing.assert_allclose(t[first], est, atol=1e-6, rtol=0)
    np.testing.assert_allclose(t[first], openmovement_block_start_s(ax_blocks(path)), atol=1e-6, rtol=0)
    rate = float(rec.metadata[f"imulog.device.{rec.imus[0].name}"]["rate_hz"])
    late = t - _abs_s(read_cwa(path))
    assert 0.5 / rate < np.median(late) < 2.5 / rate


def test_unknown_time_rule_is_one_line(cwa_dir: Path):
    with pytest.raises(ConversionError, match=r"unknown \.cwa time rule 'utc'; known: skdh, openmovement"):
        read_cwa(cwa_dir / "ax6_sample.cwa", ConvertOptions(extra={"cwa_times": "utc"}))


def test_cwa_times_from_the_command_line(cwa_dir: Path, tmp_path: Path):
    """``--cwa-times openmovement`` reaches the reader: the archive's start is OpenMovement's first block start."""
    from click.testing import CliRunner

    from imulog.archive import TrialReader
    from imulog.cli import cli

    src = cwa_dir / "ax6_sample.cwa"
    starts = {}
    for rule in ("skdh", "openmovement"):
        out = tmp_path / f"{rule}.mcap"
        done = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out), "--cwa-times", rule])
        assert done.exit_code == 0, done.output
        with TrialReader(out) as trial:
            starts[rule] = trial.metadata["imulog.trial"]["start_time"]
    om = openmovement_block_start_s(ax_blocks(src))[0]
    sk = skdh_rule_s(ax_blocks(src))[0]
    for rule, want in (("openmovement", om), ("skdh", sk)):
        got = np.datetime64(starts[rule], "ns").astype(np.int64) / 1e9
        assert abs(got - want) < 1e-6, (rule, starts[rule])


def _flip(src: Path, tmp_path: Path, blocks: list[int]) -> Path:
    data = bytearray(src.read_bytes())
    for k in blocks:
        data[HEADER_BYTES + k * BLOCK_BYTES + 200] ^= 0x04
    out = tmp_path / "damaged.cwa"
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("rule", ["skdh", "openmovement"])
@pytest.mark.parametrize("chunk", [None, 17, 18])
def test_skip_damaged_blocks_as_gaps(cwa_dir: Path, tmp_path: Path, chunk, rule: str):
    """Under either time rule: the runs are named and counted, the intact samples keep their values, the skipped
    ones are NaN, and the block after a run starts at its own time (skdh's rule: not chained to the block before
    the run; OpenMovement's: its block start), every other block at the intact file's times (by OpenMovement's
    rule the block before a run within 0.2 ms)."""
    from imulog.converters._binary import concat_chunks
    from imulog.converters.axivity import iter_chunks

    src = cwa_dir / "ax6_sample.cwa"
    good = read_cwa(src, ConvertOptions(extra={"cwa_times": rule})).imus[0]
    bad = _flip(src, tmp_path, [17, 18, 40])
    with pytest.raises(ConversionError, match="data block 17"):
        read_cwa(bad)
    opts = ConvertOptions(extra={"skip_damaged": True, "cwa_times": rule})
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
    kept = np.delete(np.arange(len(good)), np.r_[17 * n : 19 * n, 40 * n : 41 * n])
    np.testing.assert_array_equal(imu.acc[finite], good.acc[kept])
    # 3 blocks of 40 samples at the device's real ~98.4 Hz, on the nominal 100 Hz grid: 120 + ~2 per skipped block
    assert (~finite).sum() == meta["gap_samples"] and 120 <= meta["gap_samples"] <= 126
    t, want = imu.t_ns[finite], good.t_ns[kept].copy()
    if rule == "skdh":  # blocks 19 and 41 start at their own time, at the nominal rate
        b = ax_blocks(src)
        own = np.round((skdh_own_start_s(b) - skdh_own_start_s(b)[0]) * 1e9).astype(np.int64)
        for k in (19, 41):
            want[np.isin(kept, np.arange(k * n, (k + 1) * n))] = own[k] + np.arange(n) * 10_000_000
    # OpenMovement's rule: the block before a run (16, 39) takes the previous block's measured rate (0.2 ms)
    before = np.isin(kept // n, [16, 39]) if rule == "openmovement" else np.zeros(len(kept), dtype=bool)
    np.testing.assert_allclose(t[~before], want[~before], atol=1000, rtol=0)  # 1 us
    np.testing.assert_allclose(t[before], want[before], atol=200_000, rtol=0)
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


@pytest.mark.parametrize("rule", ["skdh", "openmovement"])
@pytest.mark.parametrize("chunk", [None, 13, 50])
def test_real_damaged_file_skips_exactly_the_damaged_blocks(tmp_path: Path, chunk, rule: str):
    """GGIRread's real AX3 file with data blocks 0, 13, 14, 142, 143 and 144 damaged, against the intact file it
    was made from: refused by default naming block 0; with skip_damaged the three runs are named, counted, the
    intact samples equal the intact file's exactly, and the run inside the recording is a gap of NaN samples.
    Times equal the intact file's to 1 us except: by skdh's rule the first block after a run (1 and 15) starts at
    its own time at the nominal rate; by OpenMovement's the block before a run (12) takes the previous block's
    measured rate (0.2 ms)."""
    from imulog.converters._binary import concat_chunks
    from imulog.converters.axivity import iter_chunks

    bad = _unxz("ax3_testfile_corrupt_blocks_0_13_14_142_143_144.cwa.xz", tmp_path)
    intact_path = _unxz("ax3_testfile.cwa.xz", tmp_path)
    intact = read_cwa(intact_path, ConvertOptions(extra={"cwa_times": rule}))
    with pytest.raises(ConversionError, match=r"data block 0 \(byte 1024\): checksum mismatch.*--skip-damaged"):
        read_cwa(bad)
    opts = ConvertOptions(extra={"skip_damaged": True, "cwa_times": rule})
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
    want = _abs_s(intact)[kept]
    if rule == "skdh":
        own = skdh_own_start_s(ax_blocks(intact_path))
        for k in (1, 15):
            want[block[kept] == k] = own[k] + np.arange(n) / 100.0
        special = np.zeros(len(want), dtype=bool)
    else:
        special = np.isin(block[kept], [12, 141])
    dt = np.abs(_abs_s(rec)[finite] - want)
    assert dt[~special].max() < 1e-6
    assert not special.any() or dt[special].max() < 2e-4
    # blocks 13-14 (2 x 120 samples at the device's ~98.8 Hz) are NaN rows on the nominal 100 Hz grid
    assert (~finite).sum() == meta["gap_samples"] and 240 <= meta["gap_samples"] <= 246
    assert np.all(np.diff(imu.t_ns) > 0)


def test_held_out_ax6_csv_export_follows_the_default_rule(tmp_path: Path):
    """Held out: GGIR's ax6_testfile_formatted_timestamps.csv is a CSV export of GGIRread's ax6_testfile.cwa
    (its first 8 blocks kept in tests/data). Its values equal imulog's .cwa decode and its axivity-csv reading,
    and its time stamps equal imulog's default (skdh's rule) to their 1 ms print resolution; by OpenMovement's
    rule imulog reads ~10 ms later than the export."""
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
    assert np.abs(_abs_s(rec)[:n] - csv_s).max() < 1.001e-3
    assert np.abs(skdh_rule_s(ax_blocks(cwa))[:n] - csv_s).max() < 1.001e-3
    late_ms = (_abs_s(read_cwa(cwa, OM))[:n] - csv_s) * 1e3
    assert 9 < np.median(late_ms) < 11 and late_ms.max() < 15
