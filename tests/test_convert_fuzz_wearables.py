"""Fuzzing the wearable text readers as the other converters are: truncations, flipped bytes, duplicated lines,
huge numbers; only one-line ConversionErrors, never a traceback or a hang."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from imulog.converters import ConversionError, ConvertOptions, get

from imulog.model import Recording

BANNER = (
    "------------ Data File Created By ActiGraph GT3X+ ActiLife v6.13.3 Firmware v3.2.1 date format M/d/yyyy Filter "
    "Normal -----------\nSerial Number: MOS2E12345678\nStart Time 10:00:00\nStart Date 3/1/2020\n"
    "Epoch Period (hh:mm:ss) 00:01:00\nDownload Time 12:00:00\nDownload Date 3/2/2020\nCurrent Memory Address: 0\n"
    "Current Battery Voltage: 4.1     Mode = 61\n--------------------------------------------------\n"
)
SEEDS = {
    "actilife-epoch": (
        "actilife-csv",
        "counts.csv",
        BANNER + "".join(f"{i},{2 * i},{i % 7},{i % 3}\n" for i in range(40)),
    ),
    "axivity-csv": (
        "axivity-csv",
        "ax.csv",
        "".join(f"{1551178506 + i / 100:.4f},0.1,{-0.2 + i / 1000:.6f},0.98\n" for i in range(40)),
    ),
    "movella-dot": (
        "movella-dot",
        "dot.csv",
        "sep=,\nDeviceTag:,bei\nStartTime: ,2021-08-30_17:05:05_000 GMT+8\n\n"
        "PacketCounter,SampleTimeFine,Euler_X,Euler_Y,Euler_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z\n"
        + "".join(f"{i},{4294960000 + 8333 * i},1,2,3,0.1,0.2,9.8,0.5,0.6,0.7\n" for i in range(40)),
    ),
    "empatica-e4": (
        "empatica-e4",
        "ACC.csv",
        "1600000000.0, 1600000000.0, 1600000000.0\n32.0, 32.0, 32.0\n"
        + "".join(f"{i % 5},{-i % 7},64\n" for i in range(40)),
    ),
    "shimmer-csv": (
        "shimmer-csv",
        "shimmer.csv",
        "Shimmer_5E3B,Shimmer_5E3B,Shimmer_5E3B,Shimmer_5E3B,Shimmer_5E3B,Shimmer_5E3B,Shimmer_5E3B,\n"
        "Timestamp,Low Noise Accelerometer X,Low Noise Accelerometer Y,Low Noise Accelerometer Z,Gyroscope X,"
        "Gyroscope Y,Gyroscope Z,\nCAL,CAL,CAL,CAL,CAL,CAL,CAL,\n"
        "mSecs,m/(sec^2),m/(sec^2),m/(sec^2),deg/sec,deg/sec,deg/sec,\n"
        + "".join(f"{i * 19.53125:.5f},0.1,0.2,9.8,{i % 9},1.5,-2,\n" for i in range(40)),
    ),
    "opensignals": (
        "opensignals",
        "os.txt",
        '# OpenSignals Text File Format\n# {"00:07:80:3B:46:61": {"device": "bitalino_rev", "sampling rate": 100, '
        '"column": ["nSeq", "I1", "A1", "A2"], "sensor": ["EMG", "ACC"], "resolution": [4, 1, 10, 10], '
        '"date": "2017-1-20", "time": "14:40:49.587"}}\n# EndOfHeader\n'
        + "".join(f"{i % 16}\t0\t{500 + i % 9}\t{300 + i % 4}\t\n" for i in range(40)),
    ),
    "delimited-grouped": (
        "delimited",
        "grouped.csv",
        "Time (s);Vicon Position (mm);;;Vicon Orientation;;;;IMU Acceleration (m/s^2);;;IMU Gyroscope (rad/s);;;\n"
        ";X;Y;Z;W;X;Y;Z;X;Y;Z;X;Y;Z;\n"
        + "".join(f"{i / 100:.2f};1;2;3;1;0;0;0;0.1;0.2;9.8;0.01;0.02;{i / 1000:.3f}\n" for i in range(40)),
    ),
}
_MUTATION = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("flip"), st.floats(0, 1), st.integers(0, 255)),
    st.tuples(st.just("dupline"), st.floats(0, 1)),
    st.tuples(
        st.just("line"), st.floats(0, 1), st.sampled_from(["", "x", "1e308,1e308,1e308", "nan,nan", ",,,,", "9" * 40])
    ),
)


def _mutate(data: bytes, mutations: list[tuple]) -> bytes:
    for m in mutations:
        pos = int(m[1] * len(data))
        if m[0] == "truncate":
            data = data[:pos]
        elif m[0] == "flip":
            data = data[:pos] + bytes([m[2]]) + data[pos + 1 :]
        else:
            lines = data.split(b"\n")
            i = min(int(m[1] * len(lines)), len(lines) - 1)
            if m[0] == "dupline":
                lines.insert(i, lines[i])
            else:
                lines[i] = m[2].encode()
            data = b"\n".join(lines)
    return data


def _check(rec: Recording) -> None:
    for s in rec.streams():
        t = getattr(s, "t_ns", None)
        if t is not None and len(t) > 1:
            assert np.all(np.diff(t) > 0), s
    for imu in rec.imus:
        for arr in (imu.acc, imu.gyr):
            if arr is not None:
                assert not np.isinf(arr).any()


def _run(tmp: Path, key: str, data: bytes, compress: bool = False) -> None:
    fmt, name, _ = SEEDS[key]
    for old in tmp.iterdir():
        old.unlink()
    path = tmp / (name + (".gz" if compress else ""))
    path.write_bytes(gzip.compress(data) if compress else data)
    try:
        rec = get("compressed" if compress else fmt).convert(path, ConvertOptions())
    except ConversionError as e:
        assert "\n" not in str(e)
        return
    _check(rec)


def test_seeds_convert(tmp_path):
    for key, (_, _, text) in SEEDS.items():
        _run(tmp_path, key, text.encode())
        fmt, name, _ = SEEDS[key]
        assert get(fmt).convert(tmp_path / name, ConvertOptions()).streams(), key


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(sorted(SEEDS)), mutations=st.lists(_MUTATION, min_size=1, max_size=3))
def test_damaged_files_raise_only_conversion_error(tmp_path, key, mutations):
    _run(tmp_path, key, _mutate(SEEDS[key][2].encode(), mutations))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(sorted(SEEDS)), mutations=st.lists(_MUTATION, min_size=0, max_size=2))
def test_damaged_compressed_files_raise_only_conversion_error(tmp_path, key, mutations):
    _run(tmp_path, key, _mutate(SEEDS[key][2].encode(), mutations), compress=True)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(key=st.sampled_from(sorted(SEEDS)), data=st.binary(max_size=300))
def test_arbitrary_bytes_raise_only_conversion_error(tmp_path, key, data):
    _run(tmp_path, key, data)
    _run(tmp_path, key, data, compress=True)
