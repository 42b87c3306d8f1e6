"""Older Genea .bin (converters/genea.py) on files built by the documented layout (tests/genea_build.py).

The layout and the published conversion were checked on GGIR's real genea_testfile.bin, which is not redistributed
(LGPL): ``python benchmarks/genea_reference.py genea_testfile.bin`` prints GGIRread's documented values for it next
to imulog's (all equal). Here the builder writes files with known counts and times."""

from __future__ import annotations

from pathlib import Path

import imulog.converters.genea as genea
import numpy as np
import pytest
from click.testing import CliRunner
from genea_build import BATTERY_RAW, GAINS, OFFSETS, T0, build_genea
from imulog.converters import ConversionError, convert_file, detect
from imulog.converters._common import G0

from imulog.cli import cli


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
