"""Any text format through .gz, .bz2, .xz and single-file .zip; the bounds on decompression; grouped headers."""

from __future__ import annotations

import bz2
import gzip
import json
import lzma
import zipfile
from pathlib import Path

import imulog.converters.compressed as compressed
import numpy as np
import pytest
from imulog.converters import ConversionError, convert_file, detect

DOT = "movella_dot_csv/bei_D4CA6EF17860_20210830_170505.csv"
# one shared text export per text format read through a compressed file
TEXT_SAMPLES = (
    "actigraph_count_csv/ActiGraph13.csv",
    "actigraph_gt3x/exampleRAW.csv",
    "apdm_csv/apdm_format7.csv",
    "axivity_csv/ax3_testfile_unix_timestamps.csv",
    "delsys_trigno/trigno_sample_header.csv",
    "opensense_sto/myComplexTasksTrial_orientations.sto",
    "opensim_mot/inverse_kin.mot",
    "opensim_trc/markers.trc",
    "optitrack_motive/sample_optitrack_take.csv",
    "xsens_mtmanager/MT2022_ACC_GYRO_ROT_MAT_SEMICOLON_00B42D4B.txt",
)


@pytest.fixture(scope="module")
def dot(shared_data: Path) -> Path:
    return shared_data / "devices" / DOT


def _pack(src: Path, path: Path, kind: str) -> Path:
    data = src.read_bytes()
    if kind == "gz":
        path.write_bytes(gzip.compress(data))
    elif kind == "bz2":
        path.write_bytes(bz2.compress(data))
    elif kind == "xz":
        path.write_bytes(lzma.compress(data))
    else:
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr(src.name, data)
    return path


@pytest.mark.parametrize("kind", ["gz", "bz2", "xz", "zip"])
@pytest.mark.parametrize("sample", TEXT_SAMPLES)
def test_every_text_format_reads_through_compression(shared_data: Path, tmp_path: Path, sample: str, kind: str):
    src = shared_data / "devices" / sample
    packed_path = _pack(src, tmp_path / f"{src.name}.{kind}", kind)
    plain, packed = convert_file(src), convert_file(packed_path)
    assert [s.topic for s in plain.streams()] == [s.topic for s in packed.streams()]
    for a, b in zip(plain.streams(), packed.streams(), strict=True):
        np.testing.assert_array_equal(a.t_ns, b.t_ns)
        for field in ("acc", "gyr", "values", "pos"):
            if getattr(a, field, None) is not None:
                np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    assert packed.metadata.get("imulog.trial") == plain.metadata.get("imulog.trial")


@pytest.mark.parametrize("kind", ["gz", "bz2", "xz", "zip"])
def test_compressed_equals_plain(tmp_path, dot, kind):
    data = dot.read_bytes()
    path = tmp_path / f"{dot.name}.{kind}"
    if kind == "gz":
        path.write_bytes(gzip.compress(data))
    elif kind == "bz2":
        path.write_bytes(bz2.compress(data))
    elif kind == "xz":
        path.write_bytes(lzma.compress(data))
    else:
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr(dot.name, data)
    assert detect(path).name == "compressed"
    plain, packed = convert_file(dot), convert_file(path)
    assert packed.sources == [str(path)]  # the compressed file is what the archive attaches and hashes
    for a, b in zip(plain.streams(), packed.streams(), strict=True):
        assert a.topic == b.topic
        np.testing.assert_array_equal(a.t_ns, b.t_ns)
    np.testing.assert_array_equal(plain.imus[0].acc, packed.imus[0].acc)
    assert packed.metadata["imulog.trial"] == plain.metadata["imulog.trial"]
    comp = packed.metadata["imulog.device.bei"]["compression"]
    assert comp == {"container": path.name, "inner": dot.name, "inner_format": "movella-dot"}
    assert not list(Path(compressed.tempfile.gettempdir()).glob("imulog-unpack-*/" + dot.name))  # cleaned up


def test_errors_name_the_compressed_file(tmp_path):
    bad = tmp_path / "imu.csv.gz"
    bad.write_bytes(gzip.compress(b"Time (s),Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n0,1,2\n"))
    with pytest.raises(ConversionError, match=r"imu\.csv\.gz: imu\.csv \(delimited\): line 2: truncated line"):
        convert_file(bad)
    cut = tmp_path / "cut.csv.gz"
    cut.write_bytes(gzip.compress(b"a,b\n1,2\n" * 1000)[:-20])
    with pytest.raises(ConversionError, match=r"cut\.csv\.gz: damaged compressed data"):
        convert_file(cut)
    multi = tmp_path / "session.zip"
    with zipfile.ZipFile(multi, "w") as zf:
        zf.writestr("ACC.csv", "1\n")
        zf.writestr("BVP.csv", "1\n")
    with pytest.raises(ConversionError, match=r"session\.zip: zip with 2 files \(ACC\.csv, BVP\.csv\).*unpack it"):
        convert_file(multi)
    nested = tmp_path / "twice.csv.gz.gz"
    nested.write_bytes(gzip.compress(gzip.compress(b"a,b\n1,2\n")))
    with pytest.raises(ConversionError, match=r"itself compressed"):
        convert_file(nested)


def test_decompression_bomb_is_refused_in_bounded_work(tmp_path, monkeypatch):
    monkeypatch.setattr(compressed, "RATIO_FLOOR", 1 << 20)
    monkeypatch.setattr(compressed, "MAX_RATIO", 100)
    bomb = tmp_path / "zeros.csv.gz"
    with gzip.open(bomb, "wb") as f:
        for _ in range(16):
            f.write(b"0,0,0,0\n" * (1 << 17))  # 16 MiB of text, ~16 KiB compressed
    with pytest.raises(ConversionError, match=r"zeros\.csv\.gz: decompresses to more than 100 times its size"):
        convert_file(bomb)


def test_mapping_beside_the_compressed_file_applies(tmp_path):
    rng = np.random.default_rng(0)
    n = 300
    t = np.arange(n) / 100
    v = rng.normal(0, 1, (n, 6))
    v[:, 2] += 1.0
    text = "t,a1,a2,a3,g1,g2,g3\n" + "".join(",".join(f"{x:.6f}" for x in [t[i], *v[i]]) + "\n" for i in range(n))
    (tmp_path / "wrist.csv.gz").write_bytes(gzip.compress(text.encode()))
    (tmp_path / "wrist.mapping.json").write_text(
        json.dumps(
            {
                "format": "imulog.mapping/1",
                "time": {"column": "t", "unit": "s"},
                "columns": {
                    f"{q[0]}{k + 1}": {"quantity": q, "axis": a, "unit": u}
                    for q, u in (("acc", "g"), ("gyr", "deg/s"))
                    for k, a in enumerate("xyz")
                },
            }
        )
    )
    rec = convert_file(tmp_path / "wrist.csv.gz")
    np.testing.assert_allclose(rec.imus[0].acc, np.round(v[:, :3], 6) * 9.80665, rtol=1e-12)
