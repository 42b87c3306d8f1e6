"""OpenSim .trc markers and scalar .mot/.sto (../shared/data/devices/opensim_trc, opensim_mot: pyomeca's test
files) against the text, and tab-separated variants built from them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, convert_file, detect

from imulog.cli import cli

TRC = "devices/opensim_trc/markers.trc"
MOT = "devices/opensim_mot/inverse_kin.mot"


def _cells(path: Path, delim: str, skip: int) -> list[list[str]]:
    return [x.split(delim) for x in path.read_text().splitlines()[skip:] if x.strip(delim + " ")]


def test_trc_matches_the_text(shared_data: Path):
    path = shared_data / TRC
    assert detect(path).name == "opensim-trc"
    rec = convert_file(path)
    (m,) = rec.markers
    names = path.read_text().splitlines()[3].split(",")
    labels = [c for c in names[2:] if c]
    assert m.labels == labels and len(labels) == 51
    rows = _cells(path, ",", 6)
    assert len(m) == len(rows) == 93
    xyz = np.array([[float(c) if c else np.nan for c in r[2 : 2 + 3 * 51]] for r in rows]) / 1000.0  # mm -> m
    np.testing.assert_allclose(m.pos.reshape(len(m), -1), xyz, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(m.t_ns, np.round(np.array([float(r[1]) for r in rows]) * 1e9).astype(np.int64))
    assert rec.metadata["imulog.device.trc"]["units"] == "mm"
    assert any("NumFrames=652" in w for w in rec.warnings)  # the sample holds the first 93 of 652 frames


def _tab_trc(shared_data: Path, tmp_path: Path, units: str = "m", drop_tail: bool = False) -> Path:
    lines = (shared_data / TRC).read_text().splitlines()
    out = []
    for i, line in enumerate(lines):
        cells = line.split(",")
        if i == 2:
            cells[4] = units
        if i >= 6 and drop_tail:  # a short row: the last markers missing
            cells = cells[: 2 + 3 * 49]
        if i >= 6 and i % 7 == 0:
            cells[2:5] = ["", "", ""]  # a missing marker
        out.append("\t".join(cells))
    p = tmp_path / "tab.trc"
    p.write_text("\r\n".join(out) + "\r\n")
    return p


def test_tab_separated_trc_in_metres_with_gaps(shared_data: Path, tmp_path: Path):
    ref = convert_file(shared_data / TRC).markers[0]
    rec = convert_file(_tab_trc(shared_data, tmp_path, units="m", drop_tail=True))
    (m,) = rec.markers
    gap = (np.arange(len(m)) + 6) % 7 == 0  # file line i = data row + 6
    assert not m.valid[gap, 0].any() and m.valid[~gap, 0].all()
    assert not m.valid[:, 49:].any() and any("2 of 51 markers have no valid sample" in w for w in rec.warnings)
    np.testing.assert_allclose(m.pos[~gap, 1:49], ref.pos[~gap, 1:49] * 1000.0)  # same numbers read as metres


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda s: s.replace(",mm,", ",furlong,", 1), r"unknown Units 'furlong'"),
        (lambda s: s.replace("Frame#,Time", "Frame,Tim"), r"line 4: line 4 must start with 'Frame#' and 'Time'"),
        (lambda s: s.replace("\n2,0.01,", "\n2,0,"), r"column 'Time': duplicated time stamp"),
        (
            lambda s: s.replace("\n3,0.02,733", "\n3,0.02,x733"),
            r"line 9, column 'ASISl.X': 'x733.0995' is not a number",
        ),
    ],
)
def test_damaged_trc(shared_data: Path, tmp_path: Path, damage, message):
    bad = tmp_path / "bad.trc"
    bad.write_text(damage((shared_data / TRC).read_text()))
    with pytest.raises(ConversionError, match=message) as e:
        convert_file(bad)
    assert "\n" not in str(e.value)


def test_mot_joint_angles_with_units(shared_data: Path):
    path = shared_data / MOT
    assert detect(path).name == "opensim-sto"
    rec = convert_file(path)
    (sig,) = rec.signals
    cols = path.read_text().splitlines()[10].split(",")
    assert sig.topic == "/signals/coordinates" and sig.columns == cols[1:]
    units = dict(zip(sig.columns, sig.units, strict=True))
    assert units["thorax_tilt"] == "deg" and units["thorax_tx"] == "m" and units["elbow_flexion"] == "deg"
    rows = _cells(path, ",", 11)
    np.testing.assert_array_equal(sig.values, np.array([[float(c) for c in r[1:]] for r in rows]))
    assert sig.t_ns[0] == 1_560_000_000 and len(sig) == 88
    assert rec.metadata["imulog.device.opensense"]["in_degrees"] is True
    assert any("nRows=250" in w for w in rec.warnings)


def test_tab_inverse_dynamics_sto(tmp_path: Path):
    """An inverse-dynamics result: tab-separated, no inDegrees; moments and forces by OpenSim's naming."""
    p = tmp_path / "inverse_dynamics.sto"
    p.write_text(
        "Inverse Dynamics Generalized Forces\nversion=1\nnRows=3\nnColumns=4\ninDegrees=no\nendheader\n"
        "time\tpelvis_tx_force\thip_flexion_r_moment\tground_force_vy\n"
        "0.00\t1.5\t-20.25\t700\n0.01\t1.6\t-20.5\t701\n0.02\t1.7\t-21\t702\n"
    )
    rec = convert_file(p)
    (sig,) = rec.signals
    assert sig.topic == "/signals/inverse_dynamics_generalized_forces"
    assert sig.units == ["N", "N*m", "N"]
    np.testing.assert_array_equal(sig.values[:, 1], [-20.25, -20.5, -21])


def test_cli_convert_and_doctor(shared_data: Path, tmp_path: Path):
    for src in (TRC, MOT):
        out = tmp_path / (Path(src).stem + ".mcap")
        r = CliRunner().invoke(cli, ["convert", str(shared_data / src), "-o", str(out)])
        assert r.exit_code == 0, r.output
        r = CliRunner().invoke(cli, ["doctor", str(out)])
        assert r.exit_code == 0, r.output
