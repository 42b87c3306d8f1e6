"""Input validation of the text converters (issue 15 item 4, issue 14 item 4), on the real files in ../shared/data.

* a final row cut short (a copy interrupted, a logger that lost power) is never stored: dropped with a one-line
  warning naming the file and line;
* values a human limb cannot produce in the declared unit give a one-line warning naming the likely unit and
  the option that fixes it (``--unit gyr=deg/s``), and the option fixes it;
* headers without units convert by inferring the units from physical plausibility, saying what was assumed;
* NaN or empty IMU cells are gaps (NaN in the stream), not a refusal.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, ConvertOptions, convert_file
from imulog.converters._common import drop_cut_final_row, final_row_cut
from imulog.converters.plausibility import DEG, imu_warnings, infer_acc_unit, infer_gyr_unit

from imulog.cli import cli as main

REPO = Path(__file__).resolve().parents[1]
FUSION = "imu_text/fusion_sensor_data.csv"  # deg/s, g, uT; 13 514 rows
SIM_IMU = REPO / "recordings/sim/r2g_s00_t00_imu.csv"  # BlueBuddy-style text + mapping file, mz about -31.x


def _cut_inside_last_number(text: bytes, keep: int) -> bytes:
    """The file cut ``keep`` characters into its last number (no line break after)."""
    body = text.rstrip(b"\r\n")
    last = max(body.rfind(b","), body.rfind(b"\t"), body.rfind(b" "))
    return body[: last + 1 + keep]


# ------------------------------------------------------------------------------------------- cut rows
def test_cut_last_number_of_the_simulated_export_is_dropped_not_stored_as_minus_3(tmp_path):
    """The issue's case: ``mz = -31.444`` cut to ``-3``. HEAD stored -3.0 uT as the last sample."""
    src = SIM_IMU.read_bytes()
    cut = tmp_path / "wrist.csv"
    cut.write_bytes(_cut_inside_last_number(src, 2))
    assert cut.read_bytes().endswith(b",-3")
    (tmp_path / "wrist.mapping.json").write_bytes(SIM_IMU.with_name("r2g_s00_t00_imu.mapping.json").read_bytes())
    full = convert_file(SIM_IMU).imus[0]
    rec = convert_file(cut)
    imu = rec.imus[0]
    n_lines = src.rstrip(b"\n").count(b"\n") + 1
    assert len(imu) == len(full) - 1  # the cut row is gone ...
    assert imu.mag[-1, 2] != pytest.approx(-3.0) and imu.mag[-1, 2] == full.mag[-2, 2]  # ... not stored as -3
    assert rec.warnings == [
        f"wrist.csv: line {n_lines}: last row cut short (field 10 '-3' has no decimal point where every row above "
        "has one; the file was probably truncated): dropped"
    ]


@pytest.mark.parametrize(
    "damage, reason",
    [
        (lambda b: _cut_inside_last_number(b, 2), "field 10 '-4' has no decimal point"),  # -40.62421 -> -4
        (lambda b: b.rstrip(b"\n")[: b.rstrip(b"\n").rfind(b",", 0, len(b) - 40)], "fields where the rows above"),
        (lambda b: b[: b.rfind(b",", 0, b.rstrip().rfind(b","))] + b"\n", "8 fields where the rows above have 10"),
    ],
)
def test_cut_final_row_of_a_real_export_is_dropped_with_a_warning(tmp_path, shared_data, damage, reason):
    src = (shared_data / FUSION).read_bytes()
    cut = tmp_path / "fusion.csv"
    cut.write_bytes(damage(src))
    full = convert_file(shared_data / FUSION).imus[0]
    rec = convert_file(cut)
    assert len(rec.imus[0]) == len(full) - 1
    np.testing.assert_array_equal(rec.imus[0].mag, full.mag[:-1])
    (warning,) = rec.warnings
    assert re.fullmatch(r"fusion\.csv: line 13515: last row cut short \(.*\): dropped", warning) and reason in warning


def _sample_arrays(stream) -> dict[str, np.ndarray]:
    """A stream's per-sample arrays (time, values), by attribute name."""
    n = len(stream)
    return {k: v for k, v in vars(stream).items() if isinstance(v, np.ndarray) and v.ndim and len(v) == n}


@pytest.mark.parametrize(
    "name, line",
    [
        ("devices/apdm_csv/imuData01.csv", 1028),  # 100.5734406 -> 1: stored as 1 kPa before
        ("devices/apdm_csv/apdm_format7.csv", 6),  # -0.040588 -> -: refused as "'-' is not a number" before
        ("devices/delsys_trigno/truncated_trigno_sample.csv", 2537),  # 16 of 28 fields: "truncated line" before
        ("devices/optitrack_motive/sample_optitrack_take.csv", 257),
        ("devices/nilspod/NilsPodX-6F13_20210109_162824_data.csv", 636),
        ("devices/opensense_sto/MT_012005D6_009-quaternions_calibration_trial_Facing_negX.sto", 408),
        ("devices/opensim_mot/inverse_kin.mot", 99),
    ],
)
def test_every_table_converter_drops_a_cut_final_row(tmp_path, shared_data, name, line):
    """The APDM, Delsys, Motive, NilsPod CSV and OpenSim storage readers check the final row as the delimited one
    does: a real export cut one character into its last number (trailing empty cells removed) loses that row
    with one warning naming the line; every other sample is the whole file's."""
    src = shared_data / name
    body = src.read_bytes().rstrip(b"\r\n,\t")
    cut = tmp_path / src.name
    cut.write_bytes(body[: max(body.rfind(b","), body.rfind(b"\t")) + 2])
    for companion in src.parent.glob("*_header.json"):  # NilsPod's CSV reads the header beside it
        (tmp_path / companion.name).write_bytes(companion.read_bytes())
    full, rec = convert_file(src), convert_file(cut)
    assert [w for w in rec.warnings if "cut short" in w] == [
        next(w for w in rec.warnings if w.startswith(f"{src.name}: line {line}: last row cut short ("))
    ]
    shorter = 0
    for a, b in zip(rec.streams(), full.streams(), strict=True):
        assert len(b) - len(a) in (0, 1)
        shorter += len(b) - len(a)
        whole = _sample_arrays(b)
        for key, values in _sample_arrays(a).items():
            np.testing.assert_array_equal(values, whole[key][: len(a)], err_msg=f"{a.topic} {key}")
    assert shorter >= 1


def test_complete_files_without_a_final_line_break_keep_their_last_row(tmp_path, shared_data):
    """Also the OpenSense .sto whose %g-printed time ends on a whole number (681.99, then 682): no decimal point,
    but the next step of the time column, so not a cut."""
    sto = "devices/opensense_sto/MT_012005D6_009-quaternions_calibration_trial_Facing_negX.sto"
    for name in (FUSION, "vicon_nexus/markers.csv", sto):
        src = (shared_data / name).read_bytes()
        whole = tmp_path / Path(name).name
        whole.write_bytes(src.rstrip(b"\r\n"))
        a, b = convert_file(whole), convert_file(shared_data / name)
        assert a.warnings == [] and [len(s) for s in a.streams()] == [len(s) for s in b.streams()]


def test_cut_marker_z_of_a_real_nexus_export_is_dropped(tmp_path, shared_data):
    """Issue 15: a marker z stored as 0.009 m instead of 0.0997 m when the copy stops inside the number."""
    src = (shared_data / "vicon_nexus/markers.csv").read_bytes()
    cut = tmp_path / "markers.csv"
    cut.write_bytes(_cut_inside_last_number(src, 1))  # 99.6826 -> 9
    full = convert_file(shared_data / "vicon_nexus/markers.csv").markers[0]
    rec = convert_file(cut)
    m = rec.markers[0]
    assert m.pos.shape == (579, 51, 3)
    np.testing.assert_array_equal(m.pos, full.pos[:579])
    assert rec.warnings and "markers.csv: line 585: last row cut short" in rec.warnings[0]


def test_cut_last_row_of_a_real_xsens_export_is_dropped(tmp_path, shared_data):
    name = "devices/xsens_mtmanager/MT_012005D6_031-000_00B421AF.txt"  # tab-separated, 3369 samples
    cut = tmp_path / Path(name).name
    cut.write_bytes(_cut_inside_last_number((shared_data / name).read_bytes(), 2))  # -0.814863 -> -0
    full = convert_file(shared_data / name)
    rec = convert_file(cut)
    assert len(rec.imus[0]) == len(full.imus[0]) - 1 == 3368
    for a, b in zip(rec.signals, full.signals, strict=True):
        np.testing.assert_array_equal(a.values, b.values[:-1])
    assert any(w.startswith(f"{cut.name}: line 3375: last row cut short") for w in rec.warnings)


def test_cut_adc_line_is_dropped(tmp_path):
    path = tmp_path / "witilt.txt"
    path.write_text("".join(f"X={510 + i % 7}\tY=498\tZ={600 + i % 5}\n" for i in range(40)) + "X=512\tY=498\tZ=6")
    rec = convert_file(path, options=ConvertOptions(rate_hz=10.0))
    assert len(rec.imus[0]) == 40 and rec.warnings == [
        "witilt.txt: line 41: last row cut short (field 3 has 3 characters where the rows above have at least 5; "
        "the file was probably truncated): dropped"
    ]


def test_shared_helper_for_new_converters():
    """``drop_cut_final_row`` is what a converter calls on its bytes: the end without the cut row, and the line."""
    data = b"t,a\n1.25,2.5\n3.5,4"
    end, warning = drop_cut_final_row(Path("x.csv"), data, ",", start=4)
    assert data[:end] == b"t,a\n1.25,2.5\n" and warning.startswith("x.csv: line 3: last row cut short")
    assert drop_cut_final_row(Path("x.csv"), data + b".5\n", ",", start=4) == (len(data) + 3, None)


def test_final_row_check_sees_decimal_points_and_exponents():
    rows = b"".join(b"%d,1.5e-05,-31.25\n" % i for i in range(5))
    assert final_row_cut(rows + b"5,1.5e-05,-31", ",", at_eof=True)[1].endswith(
        "no decimal point where every row above has one"
    )
    assert "no exponent" in final_row_cut(rows + b"5,1.50,-31.25", ",", at_eof=True)[1]
    assert final_row_cut(rows + b"5,1.5e-05,-31.25", ",", at_eof=True) is None  # complete, no line break
    assert final_row_cut(rows + b"5,1.5e-05,-3\n", ",", at_eof=True) is None  # a line break: written whole


# ------------------------------------------------------------------------------------------ plausibility
def _relabel(shared_data: Path, tmp_path: Path, old: str, new: str) -> Path:
    path = tmp_path / "wrist.csv"
    path.write_text((shared_data / FUSION).read_text().replace(old, new))
    return path


def test_deg_per_s_gyroscope_under_a_rad_per_s_header_warns_and_unit_option_fixes_it(tmp_path, shared_data):
    wrong = _relabel(shared_data, tmp_path, "(deg/s)", "(rad/s)")
    runner = CliRunner()
    res = runner.invoke(main, ["convert", str(wrong), "-o", str(tmp_path / "a.mcap")])
    assert res.exit_code == 0
    (line,) = [ln for ln in res.stderr.splitlines() if "gyroscope" in ln]
    assert "/imu/imu: gyroscope peaks of 216 rad/s" in line and "--unit gyr=deg/s" in line
    res = runner.invoke(main, ["convert", str(wrong), "--unit", "gyr=deg/s", "-o", str(tmp_path / "b.mcap")])
    assert res.exit_code == 0 and "gyroscope" not in res.stderr
    from imulog.archive import TrialReader

    with TrialReader(tmp_path / "b.mcap") as trial:
        gyr = trial.read("/imu/imu").gyr
        assert "warnings" not in trial.metadata["imulog.conversion"]
    with TrialReader(tmp_path / "a.mcap") as trial:  # the warning is kept with the trial
        assert any("gyroscope peaks" in w for w in trial.metadata["imulog.conversion"]["warnings"])
    np.testing.assert_allclose(gyr, convert_file(shared_data / FUSION).imus[0].gyr)


def test_static_deg_per_s_gyroscope_declared_rad_per_s_is_seen_through_the_accelerometer(shared_data):
    """A still sensor never turns fast, so peaks say nothing; but the accelerometer shows it still, and a bias of
    a few tenths of a deg/s read as rad/s would turn gravity by tens of degrees per second."""
    imu = convert_file(shared_data / "devices/xsens_mtmanager/MT_012005D6_031-000_00B421AF.txt").imus[0]
    still = slice(0, 300)  # the first 3 s: the sensors lie still before the trial
    acc, gyr, t = imu.acc[still], imu.gyr[still], imu.t_ns[still]
    assert np.linalg.norm(gyr, axis=1).max() < 0.1  # rad/s: truly at rest
    assert imu_warnings("/imu/x", acc, gyr, t) == []
    (line,) = imu_warnings("/imu/x", acc, gyr / DEG, t)
    assert "at rest the gyroscope reads" in line and "--unit gyr=deg/s" in line


def test_accelerometer_in_g_and_markers_in_mm_declared_otherwise_warn(tmp_path, shared_data):
    wrong = _relabel(shared_data, tmp_path, "(g)", "(m/s^2)")
    (line,) = [w for w in _convert_warnings(wrong) if "acc" in w]
    assert "median |acc| at rest is 0.994 m/s^2" in line and "--unit acc=g" in line
    text = (shared_data / "vicon_nexus/markers.csv").read_text()
    lines = text.split("\n")
    lines[4] = lines[4].replace("mm", "m")
    metres = tmp_path / "markers.csv"
    metres.write_text("\n".join(lines))
    (line,) = _convert_warnings(metres)
    assert "/markers/vicon: marker coordinates reach" in line and "--unit markers=mm" in line
    fixed = convert_file(metres, options=ConvertOptions(extra={"units": {"markers": "mm"}}))
    np.testing.assert_array_equal(
        fixed.markers[0].pos, convert_file(shared_data / "vicon_nexus/markers.csv").markers[0].pos
    )


def _convert_warnings(path: Path) -> list[str]:
    from imulog.converters.plausibility import recording_warnings

    rec = convert_file(path)
    return [*rec.warnings, *recording_warnings(rec)]


def test_real_files_in_their_declared_units_give_no_warning(shared_data):
    for name in (
        FUSION,
        "imu_text/shimmer_consensys_export.csv",
        "gaitmap_foot/imu_sample.csv",
        "devices/xsens_mtmanager/MT_012005D6_031-000_00B4227B.txt",
        "devices/apdm_csv/imuData01.csv",  # its 'Static' sensor vibrates: acceleration without rotation, not tilt
        "broad/05_undisturbed_slow_rotation_with_breaks_B.hdf5",
        "vicon_nexus/markers.csv",
    ):
        assert _convert_warnings(shared_data / name) == [], name


# ---------------------------------------------------------------------------------- headers without units
def _fusion_columns(shared_data: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    df = pd.read_csv(shared_data / FUSION)
    return df.iloc[:, 0].to_numpy(), df.iloc[:, 4:7].to_numpy(), df.iloc[:, 1:4].to_numpy()  # t s, acc g, gyr deg/s


def _write(path: Path, header: str, columns: list[np.ndarray]) -> Path:
    with open(path, "w") as f:
        f.write(header + "\n")
        np.savetxt(f, np.column_stack(columns), delimiter=",", fmt="%.12g")
    return path


@pytest.mark.parametrize(
    "name, header, order",
    [
        ("wrist_acc.csv", "Time,X,Y,Z", "a"),  # per-sensor body-part files: the quantity is in the file name
        ("wrist_gyro.csv", "Time,X,Y,Z", "g"),
        ("wrist.csv", "time,ax,ay,az,gx,gy,gz", "ag"),  # compact names without units
        ("wrist.csv", "acc,,,,gyr,,\nTime,X,Y,Z,X,Y,Z", "ag"),  # X,Y,Z twice under group labels
        ("wrist.csv", "Time,X,Y,Z,X,Y,Z", "ga"),  # two columns named Y, no labels: told apart by the values
    ],
)
def test_unitless_layouts_convert_with_the_units_inferred_and_said(tmp_path, shared_data, name, header, order):
    t, acc_g, gyr_dps = _fusion_columns(shared_data)
    path = _write(tmp_path / name, header, [t, *[acc_g if q == "a" else gyr_dps for q in order]])
    runner = CliRunner()
    res = runner.invoke(main, ["convert", str(path), "-o", str(tmp_path / "t.mcap")])
    assert res.exit_code == 0, res.output
    (note,) = [ln for ln in res.stderr.splitlines() if "no units in the header" in ln]
    assert "assumed time in s (99.21 Hz)" in note and "--unit QUANTITY=UNIT" in note
    ref = convert_file(shared_data / FUSION).imus[0]
    imu = convert_file(path).imus[0]
    np.testing.assert_array_equal(imu.t_ns, ref.t_ns)
    if "a" in order:
        assert "acc in g" in note
        np.testing.assert_allclose(imu.acc, ref.acc, rtol=1e-7)
    if "g" in order:
        assert "gyr in deg/s" in note
        np.testing.assert_allclose(imu.gyr, ref.gyr, rtol=1e-7)


def test_unit_option_replaces_the_inferred_unit(tmp_path, shared_data):
    t, acc_g, gyr_dps = _fusion_columns(shared_data)
    path = _write(tmp_path / "wrist.csv", "time,ax,ay,az,gx,gy,gz", [t, acc_g, gyr_dps])
    rec = convert_file(path, options=ConvertOptions(extra={"units": {"gyr": "rad/s", "acc": "m/s^2"}}))
    np.testing.assert_allclose(rec.imus[0].gyr, gyr_dps)
    np.testing.assert_allclose(rec.imus[0].acc, acc_g)
    assert "gyr in" not in rec.warnings[0] and "acc in" not in rec.warnings[0]


def test_mapping_file_names_duplicated_columns_by_position(tmp_path, shared_data):
    t, acc_g, gyr_dps = _fusion_columns(shared_data)
    path = _write(tmp_path / "wrist.csv", "Time,X,Y,Z,X,Y,Z", [t, gyr_dps, acc_g])
    mapping = {
        "format": "imulog.mapping/1",
        "time": {"column": "Time", "unit": "s"},
        "columns": {
            **{a: {"quantity": "gyr", "axis": a.lower(), "unit": "deg/s"} for a in "XYZ"},
            **{
                f"{a} (column {i})": {"quantity": "acc", "axis": a.lower(), "unit": "g"}
                for i, a in zip((5, 6, 7), "XYZ", strict=True)
            },
        },
    }
    (tmp_path / "wrist.mapping.json").write_text(json.dumps(mapping))
    rec = convert_file(path)
    ref = convert_file(shared_data / FUSION).imus[0]
    np.testing.assert_allclose(rec.imus[0].acc, ref.acc, rtol=1e-7)
    np.testing.assert_allclose(rec.imus[0].gyr, ref.gyr, rtol=1e-7)
    assert rec.warnings == []  # nothing assumed: the mapping said it


@pytest.mark.parametrize(
    "name, acc_unit, gyr_unit",
    [
        ("gaitmap_foot/imu_sample.csv", "m/s^2", "deg/s"),
        ("broad/02_undisturbed_slow_rotation_B.hdf5", "m/s^2", "rad/s"),
        ("devices/xsens_mtmanager/MT_012005D6_031-000_00B421AF.txt", "m/s^2", "rad/s"),
        ("imu_text/shimmer_consensys_export.csv", "m/s^2", "deg/s"),  # 2 s at rest: told by the gyro bias
    ],
)
def test_unit_inference_on_real_recordings(shared_data, name, acc_unit, gyr_unit):
    """Real recordings of four devices with their known units: the inference finds them from the values alone
    (the gyroscope from its peaks, its agreement with the tilt seen by the accelerometer, or its bias at rest)."""
    imu = convert_file(shared_data / name).imus[0]
    to_unit = {"m/s^2": 1.0, "g": 9.80665, "rad/s": 1.0, "deg/s": DEG}
    raw_acc = imu.acc / to_unit[acc_unit]
    assert infer_acc_unit(raw_acc, imu.t_ns).unit == acc_unit
    raw_gyr = imu.gyr / to_unit[gyr_unit]
    assert infer_gyr_unit(raw_gyr, raw_acc, imu.t_ns).unit == gyr_unit


def test_gyroscope_unit_that_the_values_cannot_tell_is_refused_with_the_option(tmp_path, shared_data):
    """A calibrated gyroscope lying still: peaks, tilt and bias fit rad/s and deg/s alike. No guess: refused."""
    t, acc_g, gyr_dps = (x[:300] for x in _fusion_columns(shared_data))  # the first 3 s, at rest
    path = _write(tmp_path / "still.csv", "time,ax,ay,az,gx,gy,gz", [t, acc_g, gyr_dps])
    with pytest.raises(
        ConversionError, match=r"still\.csv: column 'gx': no gyr unit in the header and the values cannot tell"
    ) as info:
        convert_file(path)
    assert "give --unit gyr=UNIT or a mapping file" in str(info.value)
    rec = convert_file(path, options=ConvertOptions(extra={"units": {"gyr": "deg/s"}}))
    np.testing.assert_allclose(rec.imus[0].gyr, gyr_dps * DEG)


# ---------------------------------------------------------------------------------------------- gaps
def test_nan_and_empty_imu_cells_are_gaps_kept_through_the_archive(tmp_path, shared_data):
    lines = (shared_data / FUSION).read_text().split("\n")
    for i in range(101, 121):  # 20 samples without a gyroscope reading (empty cells)
        cells = lines[i].split(",")
        cells[1:4] = ["", "", ""]
        lines[i] = ",".join(cells)
    for i in range(500, 503):  # 3 samples the logger wrote as NaN
        cells = lines[i].split(",")
        cells[4:7] = ["NaN", "nan", "NaN"]
        lines[i] = ",".join(cells)
    path = tmp_path / "gaps.csv"
    path.write_text("\n".join(lines))
    ref = convert_file(shared_data / FUSION).imus[0]
    imu = convert_file(path).imus[0]
    assert len(imu) == len(ref)
    gyr_gap = ~np.isfinite(imu.gyr).all(axis=1)
    acc_gap = ~np.isfinite(imu.acc).all(axis=1)
    assert np.flatnonzero(gyr_gap).tolist() == list(range(100, 120))
    assert np.flatnonzero(acc_gap).tolist() == [499, 500, 501]
    np.testing.assert_array_equal(imu.gyr[~gyr_gap], ref.gyr[~gyr_gap])
    res = CliRunner().invoke(main, ["convert", str(path), "-o", str(tmp_path / "g.mcap")])
    assert res.exit_code == 0, res.output
    from imulog.archive import TrialReader

    with TrialReader(tmp_path / "g.mcap") as trial:
        stored = trial.read("/imu/imu")
        info = next(c for c in trial.channels if c.topic == "/imu/imu")
    np.testing.assert_array_equal(np.isnan(stored.gyr), np.isnan(imu.gyr))
    assert info.metadata.get("nan_samples") == "23"


def test_unit_option_is_checked(tmp_path, shared_data):
    res = CliRunner().invoke(
        main, ["convert", str(shared_data / FUSION), "--unit", "gyr=furlong/s", "-o", str(tmp_path / "x.mcap")]
    )
    assert res.exit_code == 2 and "unknown gyr unit 'furlong/s'" in res.output
    assert not (tmp_path / "x.mcap").exists()


def test_plausibility_of_a_long_recording_is_judged_on_excerpts():
    """A day at 25 Hz (2.16 M samples) is checked on evenly spread 60 s excerpts: bounded cost, same verdict."""
    from imulog.converters.plausibility import MAX_CHECK_SAMPLES, excerpts

    n = 2_160_000
    t = np.arange(n, dtype=np.int64) * 40_000_000
    rng = np.random.default_rng(0)
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 0.02, (n, 3))
    gyr_dps = rng.normal(0, 0.05, (n, 3)) + [0.6, -0.4, 0.2]  # an uncalibrated gyroscope at rest, deg/s
    t_x, (a_x,) = excerpts(t, acc)
    excerpt_count = 1440 // 32  # the 60 s blocks 0, 32, 64, ... of the day's 1440: 45 x 1500 samples fit
    assert len(t_x) <= MAX_CHECK_SAMPLES and np.all(np.diff(t_x) > 0)
    assert np.isnan(a_x[:, 0]).sum() == excerpt_count - 1 > 20
    (line,) = imu_warnings("/imu/day", acc, gyr_dps, t)  # declared rad/s
    assert "at rest the gyroscope reads 0.72 rad/s" in line  # |(0.6, -0.4)|: about the horizontal axes
    assert imu_warnings("/imu/day", acc, gyr_dps * DEG, t) == []


def test_streamed_text_is_judged_on_excerpts_from_every_piece(tmp_path, monkeypatch):
    """A long text file converted piece by piece: a gyroscope in deg/s declared rad/s that only turns after the first
    piece is still warned about (the checks see excerpts spread over all pieces, not the first piece alone)."""
    from imulog.converters import delimited

    from imulog.archive import TrialReader
    from imulog.commands import convert_stream as convert_command

    rng = np.random.default_rng(5)
    n = 60_000  # 10 min at 100 Hz, ~4 pieces of 1.5 MB
    t = np.arange(n) / 100.0
    gyr = rng.normal(0, 0.002, (n, 3))
    gyr[n // 2 :, 2] += 180.0 * np.sin(t[n // 2 :])  # deg/s numbers under a rad/s header, after the first piece
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 0.01, (n, 3))
    header = "Time (s)," + ",".join(
        [f"Gyroscope {a} (rad/s)" for a in "XYZ"] + [f"Accelerometer {a} (m/s^2)" for a in "XYZ"]
    )
    path = tmp_path / "long.csv"
    np.savetxt(path, np.column_stack([t, gyr, acc]), delimiter=",", header=header, comments="", fmt="%.6f")
    monkeypatch.setattr(convert_command, "STREAM_MIN_BYTES", 0)
    monkeypatch.setattr("imulog.converters._pieces.PIECE_BYTES", 1_500_000)
    assert len(list(delimited.CONVERTER.iter_chunks(path))) >= 3
    out = tmp_path / "long.mcap"
    res = CliRunner().invoke(main, ["convert", str(path), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "converted piece by piece" in res.output and "gyroscope peaks of" in res.output
    with TrialReader(out) as trial:
        assert any("gyroscope peaks of" in w for w in trial.metadata["imulog.conversion"]["warnings"])
