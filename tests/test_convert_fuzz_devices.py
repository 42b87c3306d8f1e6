"""Fuzzing the device readers that tests/test_hostile.py and tests/test_convert_fuzz_wearables.py do not reach:
truncations, flipped and deleted bytes on real samples and built variants (ActiGraph .gt3x and its ACTIVITY3
rewrite, ActiLife raw CSV, AX3 packed .cwa, NilsPod CSV with its JSON header, C3D in MIPS and DEC, XDF, OpenSignals
.h5, a BIDS-motion recording), and huge declared lengths in every binary header. Only one-line ConversionErrors
(or a conversion), each case within a few seconds: no traceback, no hang."""

from __future__ import annotations

import shutil
import struct
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from gt3x_variants import build_variant
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from imulog.converters import ConversionError, ConvertOptions, get

LIMIT_S = 20.0  # per converted file; each takes well under a second when all is well


def _ops() -> st.SearchStrategy:
    return st.lists(
        st.tuples(st.sampled_from(["flip", "cut", "delete"]), st.floats(0, 1), st.integers(1, 255)),
        min_size=1,
        max_size=3,
    )


def _mutate(data: bytes, ops: list[tuple[str, float, int]], start: int = 0) -> bytes:
    b = bytearray(data)
    for op, where, arg in ops:
        i = min(start + int(where * (len(b) - start)), len(b) - 1)
        if op == "flip":
            b[i] ^= arg
        elif op == "cut":
            del b[i:]
        else:
            del b[i : i + arg]
        if not b:
            b = bytearray(b"\0")
    return bytes(b)


def _convert_bounded(fmt: str, path: Path, options: ConvertOptions | None = None) -> None:
    t0 = time.monotonic()
    try:
        get(fmt).convert(path, options or ConvertOptions())
    except ConversionError as e:
        assert "\n" not in str(e) and len(str(e)) < 600, str(e)[:300]
    assert time.monotonic() - t0 < LIMIT_S, f"{path.name}: {time.monotonic() - t0:.1f} s"


# ------------------------------------------------------------------------------------- seeds per reader
def _gt3x(shared: Path, tmp: Path) -> Path:
    return build_variant(shared / "devices/actigraph_gt3x/example.gt3x", tmp / "a3.gt3x", "activity3")


def _actilife_raw(shared: Path, tmp: Path) -> Path:
    src = shared / "devices/actigraph_gt3x/exampleRAW.csv"
    out = tmp / "exampleRAW.csv"
    out.write_bytes(b"\n".join(src.read_bytes().split(b"\n")[:60]) + b"\n")
    return out


def _cwa_ax3(shared: Path, tmp: Path) -> Path:
    src = shared / "devices/axivity_cwa/ax3_sample.cwa"
    out = tmp / "ax3.cwa"
    out.write_bytes(src.read_bytes()[: 1024 + 40 * 512])
    return out


def _nilspod_csv(shared: Path, tmp: Path) -> Path:
    folder = shared / "devices/nilspod"
    stem = "NilsPodX-6F13_20210109_162824"
    shutil.copy(folder / f"{stem}_header.json", tmp / f"{stem}_header.json")
    out = tmp / f"{stem}_data.csv"
    out.write_bytes(b"\n".join((folder / f"{stem}_data.csv").read_bytes().split(b"\n")[:80]) + b"\n")
    return out


def _c3d(proc_name: str) -> Callable[[Path, Path], Path]:
    def build(shared: Path, tmp: Path) -> Path:
        from imulog.converters.c3d_format import DEC, from_intel

        if proc_name == "mips":
            src = shared / "devices/c3d_samples/MACsample.c3d"
            data = src.read_bytes()
        else:
            data = from_intel((shared / "devices/c3d_samples/pc_int.c3d").read_bytes(), DEC)
        out = tmp / f"{proc_name}.c3d"
        out.write_bytes(data)
        return out

    return build


def _xdf(shared: Path, tmp: Path) -> Path:
    out = tmp / "minimal.xdf"
    shutil.copy(shared / "devices/xdf/minimal.xdf", out)
    return out


def _opensignals_h5(shared: Path, tmp: Path) -> Path:
    h5py = pytest.importorskip("h5py")
    out = tmp / "opensignals.h5"
    with h5py.File(out, "w") as f:
        g = f.create_group("00:07:80:3B:46:61")
        g.attrs["sampling rate"] = 100
        g.attrs["resolution"] = [4, 10, 10]
        g.attrs["device"] = "bitalino_rev"
        g.attrs["date"] = "2017-1-20"
        g.attrs["time"] = "14:40:49.587"
        raw = g.create_group("raw")
        raw["nSeq"] = (np.arange(200) % 16).reshape(-1, 1)
        for k, sensor in enumerate(["EMG", "ACC"]):
            raw[f"channel_{k + 1}"] = (500 + np.arange(200) % 9).reshape(-1, 1)
            raw[f"channel_{k + 1}"].attrs["sensor"] = sensor
    return out


def _bids(shared: Path, tmp: Path) -> Path:
    root = tmp / "bids"
    motion = root / "sub-01" / "motion"
    motion.mkdir(parents=True)
    (root / "dataset_description.json").write_text('{"Name": "fuzz", "BIDSVersion": "1.9.0"}')
    stem = "sub-01_task-reach_tracksys-imu"
    (motion / f"{stem}_motion.json").write_text('{"SamplingFrequency": 100, "TaskName": "reach"}')
    rows = ["name\ttype\tcomponent\ttracked_point\tunits"]
    rows += [f"acc_{a}\tACCEL\t{a}\twrist\tm/s^2" for a in "xyz"] + [f"gyr_{a}\tGYRO\t{a}\twrist\trad/s" for a in "xyz"]
    (motion / f"{stem}_channels.tsv").write_text("\n".join(rows) + "\n")
    data = "".join(f"0.1\t0.2\t9.8\t{i % 5 / 100}\t0\t0\n" for i in range(120))
    out = motion / f"{stem}_motion.tsv"
    out.write_text(data)
    return out


SEEDS: dict[str, tuple[str, Callable[[Path, Path], Path]]] = {
    "actigraph-activity3": ("actigraph", _gt3x),
    "actilife-raw": ("actilife-csv", _actilife_raw),
    "axivity-ax3": ("axivity", _cwa_ax3),
    "nilspod-csv": ("nilspod", _nilspod_csv),
    "c3d-mips": ("c3d", _c3d("mips")),
    "c3d-dec": ("c3d", _c3d("dec")),
    "xdf": ("xdf", _xdf),
    "opensignals-h5": ("opensignals-h5", _opensignals_h5),
    "bids-motion": ("bids-motion", _bids),
}


@pytest.mark.parametrize("key", sorted(SEEDS))
def test_seed_converts(shared_data: Path, tmp_path: Path, key: str):
    fmt, build = SEEDS[key]
    assert get(fmt).convert(build(shared_data, tmp_path), ConvertOptions()).streams(), key


@pytest.mark.parametrize("key", sorted(SEEDS))
def test_mutated_samples_raise_only_conversion_error(shared_data: Path, tmp_path_factory, key: str):
    fmt, build = SEEDS[key]
    folder = tmp_path_factory.mktemp(key)
    path = build(shared_data, folder)
    seed = path.read_bytes()

    @settings(max_examples=10, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
    @given(_ops())
    def check(ops):
        path.write_bytes(_mutate(seed, ops))
        _convert_bounded(fmt, path)

    check()


# ------------------------------------------------------------------------------- huge declared lengths
def _edit(path: Path, fn: Callable[[bytearray], None]) -> Path:
    data = bytearray(path.read_bytes())
    fn(data)
    path.write_bytes(bytes(data))
    return path


def _cwa_huge(shared: Path, tmp: Path) -> list[Path]:
    out = []
    for name, offset, fmt, value in (
        ("count", 1024 + 3 * 512 + 28, "<H", 0xFFFF),  # block 3 declares 65535 samples
        ("length", 1024 + 3 * 512 + 2, "<H", 0xFFFF),
        ("header", 2, "<H", 0xFFFF),
    ):
        p = _cwa_ax3(shared, tmp)
        out.append(
            _edit(p, lambda d, o=offset, f=fmt, v=value: struct.pack_into(f, d, o, v)).rename(tmp / f"{name}.cwa")
        )
    return out


def _gt3x_huge(shared: Path, tmp: Path) -> list[Path]:
    import zipfile

    src = shared / "devices/actigraph_gt3x/example.gt3x"
    with zipfile.ZipFile(src) as z:
        info, log = z.read("info.txt"), z.read("log.bin")
    out = []
    variants = {
        "size": (info, log[:6] + b"\xff\xff" + log[8:]),  # the first record declares 65535 payload bytes
        "rate": (info.replace(b"Sample Rate: 90", b"Sample Rate: 900000000000"), log),
        "sleep": (info.replace(b"Last Sample Time: ", b"Last Sample Time: 9"), log),
        "start": (info.replace(b"Start Date: ", b"Start Date: 9"), log),
    }
    for name, (i, lg) in variants.items():
        p = tmp / f"{name}.gt3x"
        with zipfile.ZipFile(p, "w") as z:
            z.writestr("info.txt", i)
            z.writestr("log.bin", lg)
        out.append(p)
    return out


def _edf_huge(shared: Path, tmp: Path) -> list[Path]:
    src = (shared / "devices/edf/trigno_emg.edf").read_bytes()
    ns = int(src[252:256])
    out = []
    for name, at, width in (("records", 236, 8), ("header_bytes", 184, 8), ("samples", 256 + 216 * ns, 8)):
        d = bytearray(src)
        d[at : at + width] = b"99999999"[:width]
        p = tmp / f"{name}.edf"
        p.write_bytes(bytes(d))
        out.append(p)
    return out


def _geneactiv_huge(shared: Path, tmp: Path) -> list[Path]:
    src = (shared / "devices/geneactiv_bin/GENEActiv_testfile.bin").read_bytes()
    out = []
    for name, old, new in (
        ("pages", b"Number of Pages:222048", b"Number of Pages:999999999999"),
        ("rate", b"Measurement Frequency:85.7", b"Measurement Frequency:1e300"),
    ):
        p = tmp / f"{name}.bin"
        p.write_bytes(src.replace(old, new))
        out.append(p)
    return out


def _c3d_huge(shared: Path, tmp: Path) -> list[Path]:
    src = (shared / "devices/c3d_samples/pc_int.c3d").read_bytes()
    from imulog.converters.c3d_format import parameters

    out = []
    frames = bytearray(src)
    struct.pack_into("<H", frames, 8, 0xFFFF)  # header last frame
    blocks = bytearray(src)
    blocks[(src[0] - 1) * 512 + 2] = 0xFF  # 255 parameter blocks declared
    data_start = bytearray(src)
    struct.pack_into("<H", data_start, 16, 0xFFFF)  # data start block far past the end
    assert parameters(src)
    for name, d in (("frames", frames), ("param_blocks", blocks), ("data_start", data_start)):
        p = tmp / f"{name}.c3d"
        p.write_bytes(bytes(d))
        out.append(p)
    return out


def _xdf_huge(shared: Path, tmp: Path) -> list[Path]:
    src = (shared / "devices/xdf/minimal.xdf").read_bytes()
    # the first chunk after the magic: a 1-byte length count then the length; declare 8 bytes of 2^62
    d = bytearray(src[:4]) + bytes([8]) + struct.pack("<Q", 1 << 62) + src[6:]
    p = tmp / "huge.xdf"
    p.write_bytes(bytes(d))
    return [p]


def _nilspod_huge(shared: Path, tmp: Path) -> list[Path]:
    src = (shared / "devices/nilspod/NilsPodX-6F13_20210109_162824.bin").read_bytes()
    out = []
    for name, at in (("header_size", 0), ("sample_size", 1)):
        d = bytearray(src)
        d[at] = 0xFF
        p = tmp / f"{name}.bin"
        p.write_bytes(bytes(d))
        out.append(p)
    return out


HUGE: dict[str, tuple[str, Callable[[Path, Path], list[Path]]]] = {
    "axivity": ("axivity", _cwa_huge),
    "actigraph": ("actigraph", _gt3x_huge),
    "edf": ("edf", _edf_huge),
    "geneactiv": ("geneactiv", _geneactiv_huge),
    "c3d": ("c3d", _c3d_huge),
    "xdf": ("xdf", _xdf_huge),
    "nilspod": ("nilspod", _nilspod_huge),
}


@pytest.mark.parametrize("key", sorted(HUGE))
def test_huge_declared_lengths_are_bounded(shared_data: Path, tmp_path: Path, key: str):
    fmt, build = HUGE[key]
    for path in build(shared_data, tmp_path):
        _convert_bounded(fmt, path, ConvertOptions(extra={"reader_timeout_s": 10.0}))


def _hangs(*args, **kwargs):
    time.sleep(3600)


@pytest.mark.parametrize("module", ["apdm", "broad"])
def test_h5py_readers_run_guarded(tmp_path: Path, monkeypatch, module: str):
    """APDM and BROAD HDF5 are read by h5py in the guarded child: a reader that never returns is stopped after the
    limit with one line; the readers' own refusals keep their message."""
    h5py = pytest.importorskip("h5py")
    import importlib

    mod = importlib.import_module(f"imulog.converters.{'apdm_h5' if module == 'apdm' else module}")  # the reader's
    read = mod.read_apdm_h5 if module == "apdm" else mod.read_broad
    path = tmp_path / "empty.h5"
    with h5py.File(path, "w") as f:
        f.create_group("nothing")
    with pytest.raises(ConversionError) as refused:
        read(path, {}) if module == "apdm" else read(path)
    assert "did not finish" not in str(refused.value) and "\n" not in str(refused.value)
    monkeypatch.setattr(h5py, "File", _hangs)
    monkeypatch.setattr(mod, "READER_TIMEOUT_S", 1.0)
    t0 = time.monotonic()
    with pytest.raises(ConversionError, match=r"empty\.h5: h5py did not finish within 1 s"):
        read(path, {}) if module == "apdm" else read(path)
    assert time.monotonic() - t0 < 15
