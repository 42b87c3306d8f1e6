"""GENEActiv .bin (../shared/data/devices/geneactiv_bin, GGIRread's test file) against GGIRread's documented values
and scikit-digital-health's reader."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, detect
from imulog.converters._common import G0
from imulog.converters.geneactiv import PAGE_MARK, iter_chunks, read_bin

from imulog.cli import cli

BIN = "devices/geneactiv_bin/GENEActiv_testfile.bin"


@pytest.fixture(scope="module")
def src(shared_data: Path) -> Path:
    return shared_data / BIN


def whole_pages(src: Path, tmp_path: Path, n: int | None = None) -> Path:
    """The file without its cut last page (or with ``n`` pages), header page count fixed to match."""
    data = src.read_bytes()
    marks = [i for i in range(len(data)) if data.startswith(PAGE_MARK, i)] if n else [data.rfind(PAGE_MARK)]
    cut = marks[n] if n else marks[0]
    k = n or data[:cut].count(PAGE_MARK)
    out = tmp_path / "whole.bin"
    out.write_bytes(data[:cut].replace(b"Number of Pages:222048", f"Number of Pages:{k:<6d}".encode()))
    return out


def test_values_match_ggirread_documented(src: Path):
    assert detect(src).name == "geneactiv"
    rec = read_bin(src)
    imu = rec.imus[0]
    assert len(imu) == 16 * 300  # 17 pages, the last one cut short in this 64 KB sample
    # GGIRread tests/testthat/test_readGENEActiv.R: z[300], temperature[1], light[2], time[1], rate
    assert imu.acc[299, 2] / G0 == pytest.approx(-0.80836403369903564453, abs=1e-7)
    light = rec.signals[0]
    assert light.topic == "/signals/geneactiv" and light.values[1, 0] == pytest.approx(2.666667, abs=1e-6)
    page = rec.signals[1]
    assert page.values[0, 0] == 21.5 and page.units == ["degC", "V"]
    meta = rec.metadata["imulog.device.geneactiv"]
    assert meta["rate_hz"] == 85.7 and meta["serial"] == "012967"
    trial = rec.metadata["imulog.trial"]
    # GGIRread's time[1] = 1369908774.5 s is the page time read as UTC; the header says Time Zone: GMT +01:00
    assert trial["start_time"] == "2013-05-30T10:12:54.500000+01:00" and trial["time_zone"] == "+01:00"
    assert np.all(np.diff(imu.t_ns) > 0)
    # page k starts at its Page Time; samples are 1/85.7 s apart within a page
    np.testing.assert_array_equal(page.t_ns, imu.t_ns[::300])
    assert page.t_ns[1] == 3_500_000_000
    assert imu.t_ns[299] == round(299 * 1e9 / 85.7)
    assert any("222048 pages" in w for w in rec.warnings) and any("cut short" in w for w in rec.warnings)


def test_matches_scikit_digital_health(src: Path, tmp_path: Path):
    skdh_io = pytest.importorskip("skdh.io")
    path = whole_pages(src, tmp_path)  # skdh refuses a file whose last page is cut
    ref = skdh_io.ReadBin().predict(file=str(path))
    rec = read_bin(path)
    imu = rec.imus[0]
    assert len(imu) == len(ref["time"])
    np.testing.assert_allclose(imu.acc / G0, ref["accel"], atol=1e-12, rtol=0)
    np.testing.assert_allclose(rec.signals[1].values[:, 0], ref["temperature"][::300])
    # skdh times are local epoch seconds (float64: ~0.2 us resolution)
    np.testing.assert_allclose(imu.t_ns / 1e9, ref["time"] - ref["time"][0], atol=1e-6, rtol=0)
    assert ref["time"][0] == 1369908774.5
    assert not any("cut short" in w or "declares" in w for w in rec.warnings)


def test_chunks_assemble_to_the_whole_file(src: Path, monkeypatch):
    import imulog.converters.geneactiv as ga

    whole = read_bin(src)
    monkeypatch.setattr(ga, "PAGES_PER_CHUNK", 5)
    parts = list(iter_chunks(src))
    assert len(parts) == 4
    np.testing.assert_array_equal(np.concatenate([p.imus[0].t_ns for p in parts]), whole.imus[0].t_ns)
    np.testing.assert_array_equal(np.concatenate([p.imus[0].acc for p in parts]), whole.imus[0].acc)


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda d: d.replace(b"x gain:25875", b"x gain:abc"), r"'x gain' missing or not a number"),
        (lambda d: d.replace(b"Calibration Data", b"Calibration Dat"), r"no 'Calibration Data' section"),
        (lambda d: d.replace(b"Recorded Data", b"Recorded Dat"), r"no 'Recorded Data' page"),
        (lambda d: d.replace(b"Sequence Number:3\r\n", b"Sequence Number:3\r\nX:1\r\n"), r"page index 3: damaged"),
        (lambda d: d.replace(b"Page Time:2013-05-30 10:13:01", b"Page Time:2013-05-30 10:12:01"), r"goes backwards"),
        (lambda d: b"GENEA" + d[5:], r"older Genea \.bin .*--format genea"),
    ],
)
def test_damaged_file_one_line_error(src: Path, tmp_path: Path, damage, message):
    bad = tmp_path / "bad.bin"
    bad.write_bytes(damage(src.read_bytes()))
    with pytest.raises(ConversionError, match=message) as e:
        read_bin(bad)
    assert "\n" not in str(e.value) and "bad.bin" in str(e.value)


def test_hex_damage_names_the_page(src: Path, tmp_path: Path):
    data = bytearray(src.read_bytes())
    third = [i for i in range(len(data)) if data.startswith(PAGE_MARK, i)][3]
    hex_at = data.index(b"Measurement Frequency:85.7\r\n", third) + 30
    data[hex_at + 5] = ord("G")
    bad = tmp_path / "hex.bin"
    bad.write_bytes(bytes(data))
    with pytest.raises(ConversionError, match=r"page sequence 3: the data line is not 12-digit hex"):
        read_bin(bad)


def test_cli_convert_and_doctor(src: Path, tmp_path: Path):
    out = tmp_path / "ga.mcap"
    r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["doctor", str(out)])
    assert r.exit_code == 0, r.output
