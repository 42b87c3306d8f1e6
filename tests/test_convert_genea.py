"""Older Genea .bin (converters/genea.py): GGIRread's real test file (tests/data/genea_testfile.bin.xz, Apache-2.0)
against the values GGIRread's own test documents, and files built by the documented layout (tests/genea_build.py)
with known counts and times."""

from __future__ import annotations

import lzma
from datetime import datetime
from pathlib import Path

import imulog.converters.genea as genea
import numpy as np
import pytest
from click.testing import CliRunner
from genea_build import BATTERY_RAW, GAINS, OFFSETS, T0, build_genea
from imulog.converters import ConversionError, convert_file, detect
from imulog.converters._common import G0

from imulog.cli import cli

REAL = Path(__file__).parent / "data" / "genea_testfile.bin.xz"


@pytest.fixture(scope="module")
def real(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("genea") / "genea_testfile.bin"
    path.write_bytes(lzma.decompress(REAL.read_bytes()))
    return path


def test_real_file_equals_ggirreads_documented_values(real: Path, monkeypatch):
    """GGIRread's test_GeneaBinReader.R reads pages 1 to 4 (three pages) and expects 993 samples (it keeps them up
    to the first sample of the last time stamp), a sum of 1 058 559 over x, y, z in whole mg (its two integer
    roundings: counts x gain / 8192, then x 1000 / 340), 4 battery readings, the first at 1 269 950 921 s, and the
    100th sample at 1 269 950 922 s within its tolerance (1.5e-8 relative); its own rule puts it at ...921.8375."""
    assert detect(real).name == "genea"
    monkeypatch.setattr(genea, "PAGES_PER_CHUNK", 1)  # one piece per page: pages 1-3 are pieces 1-3
    pieces = list(genea.iter_chunks(real))
    start = datetime.fromisoformat(pieces[0].metadata["imulog.trial"]["start_time"])
    t0 = (start - datetime(1970, 1, 1)).total_seconds()
    imu = [p.imus[0] for p in pieces[1:4]]
    t = t0 + np.concatenate([i.t_ns for i in imu]) / 1e9
    g = np.concatenate([i.acc for i in imu]) / G0
    cal = pieces[0].metadata["imulog.device.genea"]["calibration"]
    assert (cal["gain"], cal["offset"]) == ([8144, 8132, 8004], [1, -3, -13])  # the header's Accel-Gains/-Offsets
    gains, offsets = np.array(cal["gain"], float), np.array(cal["offset"], float)
    counts = np.rint(g * (8192 * 340 / gains) - offsets)  # the stored counts, axis signs applied
    np.testing.assert_allclose(counts, g * (8192 * 340 / gains) - offsets, atol=1e-6)  # whole counts
    rows = int(np.flatnonzero(np.abs(t - np.round(t)) < 1e-6)[-1]) + 1
    assert rows == 993
    mg = np.rint(np.rint((counts + offsets) * gains / 8192) * 1000 / 340)[:rows]
    assert mg.sum() == 1058559
    exact = (counts + offsets) * gains / 8192 * 1000 / 340
    assert np.abs(exact[:rows] - mg).max() < 1.8  # imulog keeps the value GGIRread rounds twice
    bat = np.concatenate([p.signals[0].t_ns for p in pieces[1:4]]) / 1e9 + t0
    assert len(bat) == 4 and np.floor(bat[0] + 1e-6) == 1269950921
    assert t[99] == pytest.approx(1269950921.8375, abs=1e-6) == pytest.approx(1269950922, rel=1.5e-8)


def test_real_file_whole(real: Path):
    rec = convert_file(real)
    (w,) = rec.warnings
    assert "the last page (index 127) is cut short (1626 bytes); dropped" in w  # the file was cut at 256 KiB
    imu = rec.imus[0]
    assert len(imu) == 42598 and len(rec.signals[0]) == 177  # 127 pages: 532 stamps, 177 battery readings
    np.testing.assert_allclose(np.diff(imu.t_ns), 12_500_000, atol=1)  # one stamp per 80 samples: 80 Hz exactly
    assert rec.metadata["imulog.trial"]["start_time"] == "2010-03-30T12:08:36.400000"  # Trial-Start 12:08:36
    g = np.linalg.norm(imu.acc / G0, axis=1)
    assert 0.9 < np.median(g) < 1.1


def test_built_file_decodes_to_its_counts_times_and_battery(tmp_path: Path):
    b = build_genea(tmp_path / "g.bin", seconds=20)
    assert detect(b.path).name == "genea"
    rec = convert_file(b.path)
    assert rec.warnings == []
    (imu,) = rec.imus
    assert len(imu) == len(b.counts) >= 48 + 20 * 80
    np.testing.assert_allclose(imu.acc / G0, b.g, rtol=0, atol=1e-12)
    np.testing.assert_allclose(imu.t_ns, np.round((b.t_rel_s - b.t_rel_s[0]) * 1e9), rtol=0, atol=1)
    (bat,) = rec.signals
    np.testing.assert_allclose(bat.values[:, 0], BATTERY_RAW * 3.3 * 11 / 1024)
    np.testing.assert_array_equal(bat.t_ns, imu.t_ns[b.battery_at])
    trial = rec.metadata["imulog.trial"]
    assert trial["start_time"] == "2010-03-30T12:08:36.400000"  # first stamp 12:08:37 minus 48 samples at 80 Hz
    assert trial["time_zone"] == "unknown (device local time)"
    dev = rec.metadata["imulog.device.genea"]
    assert dev["rate_hz"] == 80 and dev["serial"] == "01275" and dev["time_stamps"] == 21
    assert dev["calibration"]["gain"] == list(GAINS) and dev["calibration"]["offset"] == list(OFFSETS)
    assert T0 == 1269950917


def test_samples_between_stamps_are_spread_evenly_and_warned_when_off_rate(tmp_path: Path):
    b = build_genea(tmp_path / "lost.bin", seconds=12, drop={5: 30})  # second 5 holds 50 samples, not 80
    rec = convert_file(b.path)
    imu = rec.imus[0]
    (w,) = rec.warnings
    assert "1 interval(s) between time stamps" in w and "80 Hz" in w
    # GGIRread's rule: the 50 samples of second 5 cover it evenly (20 ms apart), the others stay 12.5 ms apart
    t = imu.t_ns / 1e9 + (b.t_rel_s[0])
    in5 = (t >= 5 - 1e-9) & (t < 6 - 1e-9)
    assert in5.sum() == 50 and np.allclose(np.diff(t[in5]), 1 / 50)
    np.testing.assert_allclose(imu.acc / G0, b.g, atol=1e-12)


def test_without_sample_rate_in_the_header_the_stamps_give_it(tmp_path: Path):
    b = build_genea(tmp_path / "norate.bin", seconds=8, header_rate=None)
    rec = convert_file(b.path)
    assert rec.metadata["imulog.device.genea"]["rate_hz"] == 80
    np.testing.assert_allclose(rec.imus[0].t_ns, np.round((b.t_rel_s - b.t_rel_s[0]) * 1e9), atol=1)


def test_pieces_assemble_to_the_whole_file(tmp_path: Path, monkeypatch):
    b = build_genea(tmp_path / "g.bin", seconds=30)
    whole = convert_file(b.path)
    monkeypatch.setattr(genea, "PAGES_PER_CHUNK", 2)
    pieces = list(genea.iter_chunks(b.path))
    assert len(pieces) > 3
    np.testing.assert_array_equal(np.concatenate([p.imus[0].t_ns for p in pieces]), whole.imus[0].t_ns)
    np.testing.assert_array_equal(np.concatenate([p.imus[0].acc for p in pieces]), whole.imus[0].acc)
    np.testing.assert_array_equal(np.concatenate([p.signals[0].t_ns for p in pieces]), whole.signals[0].t_ns)


def test_cut_last_page_is_dropped_with_a_warning(tmp_path: Path):
    b = build_genea(tmp_path / "g.bin", seconds=30)
    data = b.path.read_bytes()
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[:-1000])
    rec = convert_file(cut)
    assert any("cut short" in w and "dropped" in w for w in rec.warnings)
    n = len(rec.imus[0])
    assert 0 < n < len(b.counts)
    np.testing.assert_allclose(rec.imus[0].acc / G0, b.g[:n], atol=1e-12)


@pytest.mark.parametrize(
    ("how", "message"),
    [
        ("backwards", r"page \d+: time stamp \d+ does not increase"),
        ("jump", r"page \d+: time stamp \d+ jumps \d+ s ahead"),
        ("no_stamps", r"no time stamp chunk"),
        ("header", r"no 'GENEA' header ended by a blank line"),
        ("gains", r"'Accel-Gains' is not three whole numbers"),
        ("empty", r"no complete 2048-byte data page"),
    ],
)
def test_damage_is_one_line_naming_what(tmp_path: Path, how: str, message: str):
    path = tmp_path / f"{how}.bin"
    if how == "backwards":
        build_genea(path, seconds=10, stamp_edits={6: T0 + 2})
    elif how == "jump":
        build_genea(path, seconds=10, stamp_edits={6: T0 + 40 * 86400})
    else:
        build_genea(path, seconds=10)
        data = path.read_bytes()
        start = data.index(b"\r\n\r\n") + 4
        if how == "no_stamps":
            arr = np.frombuffer(data[start:], np.uint8).reshape(-1, 2048)[:, :2046].reshape(-1, 6).copy()
            arr[(arr[:, 1] >> 4) == 2, 1] = 0x30  # every stamp chunk becomes an unknown type
            pages = np.concatenate([arr.reshape(-1, 2046), np.zeros((len(arr) // 341, 2), np.uint8)], axis=1)
            data = data[:start] + pages.tobytes()
        elif how == "header":
            data = data.replace(b"\r\n\r\n", b"\r\nX\r\n", 1)
        elif how == "gains":
            data = data.replace(b"Accel-Gains:8144 8132 8004", b"Accel-Gains:8144 81x2 8004")
        else:
            data = data[: start + 100]
        path.write_bytes(data)
    with pytest.raises(ConversionError, match=rf"{how}\.bin: .*{message}") as e:
        convert_file(path, "genea")
    assert "\n" not in str(e.value)


def test_geneactiv_reader_names_the_older_format(tmp_path: Path):
    b = build_genea(tmp_path / "g.bin", seconds=3)
    with pytest.raises(ConversionError, match=r"older Genea \.bin .*--format genea"):
        convert_file(b.path, "geneactiv")


def test_cli_convert_inspect_and_doctor(tmp_path: Path):
    b = build_genea(tmp_path / "g.bin", seconds=10)
    out = tmp_path / "g.mcap"
    r = CliRunner().invoke(cli, ["convert", str(b.path), "-o", str(out)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["doctor", str(out)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["convert", "--inspect", str(b.path)])
    assert r.exit_code == 0, r.output
    assert "genea" in r.output and "/imu/genea" in r.output and "2010-03-30T12:08:36.4" in r.output
