"""Delsys Trigno CSV: both real exports of ../shared/data/devices/delsys_trigno (neuromechanist/emgio,
BSD-3-Clause) against their numbers: a time column per channel, EMG in V, ACC g and GYRO deg/s stored in SI."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError, convert_file, detect

G = 9.80665
TRIGNO = "devices/delsys_trigno"


def channels(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Channel name -> (times s, values) read by hand: the X[s] column before each channel, padding dropped."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    hi = next(i for i, r in enumerate(rows) if r and r[0] == "X[s]")
    names = rows[hi]
    out = {}
    for j in range(1, len(names), 2):
        if not names[j]:
            continue
        pairs = [(float(r[j - 1]), float(r[j])) for r in rows[hi + 1 :] if len(r) > j and r[j - 1] != ""]
        out[names[j]] = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
    return out


@pytest.mark.parametrize("name", ["truncated_trigno_sample.csv", "trigno_sample_header.csv"])
def test_trigno_export_matches_the_file(shared_data, name):
    path = shared_data / TRIGNO / name
    assert detect(path).name == "delsys"
    rec = convert_file(path)
    ch = channels(path)
    assert [i.name for i in rec.imus] == ["mini_sensor_10", "mini_sensor_11"]
    for imu, analog, k in zip(rec.imus, rec.analogs, (10, 11), strict=True):
        t, emg = ch[f"Mini sensor {k}: EMG {k}"]
        assert analog.channel_names == ["EMG"] and analog.units == ["V"]
        np.testing.assert_array_equal(analog.values[:, 0], emg)  # V in the label lines
        np.testing.assert_array_equal(analog.t_ns, np.round(t * 1e9).astype(np.int64))
        ta, ax = ch[f"Mini sensor {k}: ACC.X {k}"]
        np.testing.assert_array_equal(imu.t_ns, np.round(ta * 1e9).astype(np.int64))  # its own, slower, clock
        np.testing.assert_allclose(imu.acc[:, 0], ax * G, rtol=1e-15)  # g -> m/s^2
        _, gz = ch[f"Mini sensor {k}: GYRO.Z {k}"]
        np.testing.assert_allclose(imu.gyr[:, 2], gz * math.pi / 180, rtol=1e-15)  # deg/s -> rad/s
        meta = rec.metadata[f"imulog.device.{imu.name}"]
        assert meta["serial"] == str(k) and meta["channels"]["GYRO.Z"]["unit"] == "°/s"
        assert meta["channels"]["EMG"]["rate_hz"] == pytest.approx(1259.259)
        assert imu.meta["rate_hz"] == pytest.approx(148.1481)
    if name.startswith("truncated"):
        assert len(rec.analogs[0]) == 2519 and len(rec.imus[0]) == 297  # slower channels padded with empty cells


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda s: s.replace("Unit: g ", "Unit: furlong ", 1), r"ACC.X 10: unknown unit 'furlong'"),
        # a short row above the last is an error; a cut last row is dropped with a warning (test_convert_validation)
        (
            lambda s: s.replace(s.splitlines()[-2], s.splitlines()[-2][: s.splitlines()[-2].rindex(",")]),
            r"line 2536: truncated line: 27 fields, expected 28",
        ),
        (lambda s: s.replace("0.0007941176,", "0.0007941176x,", 1), r"line 20, column 'X\[s\]': '0.0007941176x'"),
        (lambda s: s.replace("\n0.223147,-0.0003482872", "\n,-0.0003482872", 1), r"empty time cell before"),
        (lambda s: s.split("\nX[s]")[0], r"no 'X\[s\],<channel>,...' names row"),
    ],
)
def test_damaged_trigno_file(shared_data, tmp_path, damage, message):
    src = (shared_data / TRIGNO / "truncated_trigno_sample.csv").read_text(encoding="utf-8")
    bad = tmp_path / "bad.csv"
    bad.write_text(damage(src), encoding="utf-8")
    with pytest.raises(ConversionError, match=message):
        convert_file(bad)
