"""Mapping files for files of several IMUs (columns per sensor) without a time column, and marker CSVs with one
column per marker axis (the 5-segment chain layout of issue 32): written here, values checked against the text."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from imulog.converters import ConversionError, ConvertOptions, convert_file
from imulog.converters.mapping import load_mapping

G = 9.80665
DEG = np.pi / 180


def _chain_imu(tmp: Path, n_seg: int = 5, n: int = 400) -> tuple[Path, np.ndarray]:
    rng = np.random.default_rng(7)
    vals = np.round(rng.normal(0, 1, (n, n_seg, 6)), 5)
    vals[:, :, 2] += 1.0  # g
    names = [f"seg{s + 1}_{q}_{a}" for s in range(n_seg) for q in ("acc", "gyr") for a in "xyz"]
    path = tmp / "chain_imu.csv"
    rows = [",".join(names)] + [",".join(f"{v:.5f}" for v in vals[i].reshape(-1)) for i in range(n)]
    path.write_text("\n".join(rows) + "\n")
    return path, vals


def _imu_mapping(tmp: Path, n_seg: int = 5, *, time: bool = False) -> Path:
    columns = {
        f"seg{s + 1}_{q}_{a}": {"quantity": q, "axis": a, "unit": u, "sensor": f"seg{s + 1}"}
        for s in range(n_seg)
        for q, u in (("acc", "g"), ("gyr", "deg/s"))
        for a in "xyz"
    }
    doc = {"format": "imulog.mapping/1", "columns": columns}
    if time:
        doc["time"] = {"column": None}
    path = tmp / "chain.mapping.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("time_null", [False, True])
def test_several_imus_in_one_csv_with_rate_for_the_missing_time(tmp_path, time_null):
    path, vals = _chain_imu(tmp_path)
    mapping = _imu_mapping(tmp_path, time=time_null)
    rec = convert_file(path, options=ConvertOptions(mapping=mapping, rate_hz=40.0))
    assert [i.name for i in rec.imus] == [f"seg{s}" for s in range(1, 6)]
    for s, imu in enumerate(rec.imus):
        np.testing.assert_allclose(imu.acc, vals[:, s, 0:3] * G, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(imu.gyr, vals[:, s, 3:6] * DEG, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(imu.t_ns, np.arange(400) * 25_000_000)  # 40 Hz
    assert not rec.signals  # every column mapped: nothing left over


def test_several_imus_without_mapping_get_a_readable_error(tmp_path):
    path, _ = _chain_imu(tmp_path)
    with pytest.raises(ConversionError) as err:
        convert_file(path, options=ConvertOptions(rate_hz=40.0))
    msg = str(err.value)
    assert "15 acc columns (5 x, 5 y, 5 z: 'seg1_acc_x', 'seg1_acc_y', 'seg1_acc_z', ...)" in msg
    assert "several sensors in one file; a mapping file names the sensor of each column" in msg
    assert len(msg) < 330 and "\n" not in msg


def test_no_rate_and_no_time_says_what_to_give(tmp_path):
    path, _ = _chain_imu(tmp_path)
    with pytest.raises(ConversionError, match=r"no time column in the header and no rate given .*--rate"):
        convert_file(path, options=ConvertOptions(mapping=_imu_mapping(tmp_path, time=True)))


def test_marker_csv_with_one_column_per_marker_axis(tmp_path):
    rng = np.random.default_rng(8)
    n = 300
    t = np.arange(n) / 30
    pos = np.round(rng.normal(0, 200, (n, 2, 4, 3)), 3)  # 2 segments x 4 markers, mm
    pos[50:60, 0, 1] = np.nan  # an occlusion: empty cells
    names = [f"seg{s + 1}_marker{m + 1}_{a}" for s in range(2) for m in range(4) for a in "xyz"]
    flat = pos.reshape(n, -1)
    lines = ["time," + ",".join(names)]
    for i in range(n):
        cells = ["" if np.isnan(v) else f"{v:.3f}" for v in flat[i]]
        lines.append(f"{t[i]:.6f}," + ",".join(cells))
    path = tmp_path / "chain_markers.csv"
    path.write_text("\n".join(lines) + "\n")
    columns = {
        nm: {
            "quantity": "marker",
            "marker": nm.rsplit("_", 1)[0],
            "axis": nm[-1],
            "unit": "mm",
            "sensor": nm.split("_")[0],
        }
        for nm in names
    }
    mapping = tmp_path / "m.mapping.json"
    mapping.write_text(
        json.dumps({"format": "imulog.mapping/1", "time": {"column": "time", "unit": "s"}, "columns": columns})
    )
    rec = convert_file(path, options=ConvertOptions(mapping=mapping))
    assert not rec.imus
    assert [m.name for m in rec.markers] == ["seg1", "seg2"]
    for s, ms in enumerate(rec.markers):
        assert ms.labels == [f"seg{s + 1}_marker{m + 1}" for m in range(4)]
        np.testing.assert_allclose(ms.pos, pos[:, s] / 1000, rtol=1e-12)  # NaN where occluded
        np.testing.assert_array_equal(ms.valid, np.isfinite(pos[:, s]).all(axis=2))
    assert not rec.markers[0].valid[55, 1] and rec.markers[0].valid[55, 0]


def test_mapping_errors_are_readable(tmp_path):
    bad = tmp_path / "bad.mapping.json"
    for doc, expect in (
        ({"columns": {"m1x": {"quantity": "marker", "axis": "x", "unit": "mm"}}}, r"columns\.m1x\.marker must name"),
        ({"columns": {"m1x": {"quantity": "marker", "marker": "m1", "axis": "x", "unit": "deg"}}}, "not a length unit"),
        ({"columns": {"ax": {"quantity": "acc", "axis": "x", "unit": "g", "sensor": ""}}}, r"columns\.ax\.sensor"),
        ({"unmapped": "drop"}, r"'unmapped' must be"),
    ):
        bad.write_text(json.dumps({"format": "imulog.mapping/1", **doc}))
        with pytest.raises(ConversionError, match=expect):
            load_mapping(bad)


def test_unmapped_ignore_reads_only_the_named_columns(tmp_path):
    path, vals = _chain_imu(tmp_path, n_seg=2)
    doc = json.loads(_imu_mapping(tmp_path, n_seg=1).read_text())
    doc["unmapped"] = "ignore"
    mapping = tmp_path / "one.mapping.json"
    mapping.write_text(json.dumps(doc))
    rec = convert_file(path, options=ConvertOptions(mapping=mapping, rate_hz=40.0))
    assert [i.name for i in rec.imus] == ["seg1"] and not rec.signals
