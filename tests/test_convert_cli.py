"""``imulog convert`` end to end: every format opens in ``imulog info --json`` with the right rates, units,
sample counts and durations; metadata, attachments, folders, and clean failures."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader
from imulog.cli import cli

IMU_UNITS = '["m/s^2", "rad/s", "uT"]'


def run(*args: str | Path) -> tuple[int, str, str]:
    result = CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def info_json(path: Path) -> dict:
    code, out, err = run("info", "--json", path)
    assert code == 0, err
    data = json.loads(out)
    return {c["topic"]: c for c in data["channels"]} | {
        "__metadata__": data["metadata"],
        "__attachments__": data["attachments"],
    }


def check_channel(
    ch: dict,
    *,
    samples: int,
    rate_hz: float,
    first_ns: int,
    last_ns: int,
    units: str | None = None,
    rate_tol: float = 1e-3,
):
    assert ch["samples"] == samples
    assert ch["rate_hz"] == pytest.approx(rate_hz, rel=rate_tol)
    assert ch["start_ns"] == first_ns and ch["end_ns"] == last_ns
    assert ch["duration_s"] == pytest.approx((last_ns - first_ns) / 1e9, abs=1e-9)
    if units is not None:
        assert ch["units"] == units


def test_list_formats_names_every_builtin():
    code, out, _ = run("convert", "--list-formats")
    assert code == 0
    for name in ("delimited", "xsens", "adc", "vicon-csv", "c3d", "broad-hdf5", "gaitmap"):
        assert name in out


def test_imu_text_to_trial_with_metadata_and_attachments(tmp_path, shared_data):
    src = shared_data / "imu_text/fusion_sensor_data.csv"
    meta = tmp_path / "subject.toml"
    meta.write_text('subject = "S07"\ntask = "r2g"\n[anthropometrics]\nforearm_length_m = 0.27\n')
    out = tmp_path / "fusion.mcap"
    code, stdout, err = run("convert", src, "-o", out, "--meta-file", meta, "--meta", "side=left", "--meta", "trial=3")
    assert code == 0, err
    t = pd.read_csv(src)["Time (s)"].to_numpy()
    chans = info_json(out)
    n = len(t)
    check_channel(
        chans["/imu/imu"],
        samples=n,
        rate_hz=(n - 1) / (t[-1] - t[0]),
        first_ns=0,
        last_ns=round(t[-1] * 1e9),
        units=IMU_UNITS,
        rate_tol=0.01,
    )
    md = chans["__metadata__"]
    assert md["imulog.trial"] == {"subject": "S07", "task": "r2g", "side": "left", "trial": 3}
    assert md["imulog.anthropometrics"] == {"forearm_length_m": 0.27}
    assert md["imulog.device.imu"]["units"] == {"acc": "g", "gyr": "deg/s", "mag": "uT"}
    sha = hashlib.sha256(src.read_bytes()).hexdigest()
    assert md["imulog.conversion"]["sha256"] == {src.name: sha}
    with TrialReader(out) as trial:
        (att,) = trial.attachments()
        assert att.name == src.name and att.data == src.read_bytes() and att.sha256 == sha


def test_no_attach(tmp_path, shared_data):
    out = tmp_path / "x.mcap"
    code, _, err = run("convert", shared_data / "imu_text/shimmer_consensys_export.csv", "-o", out, "--no-attach")
    assert code == 0, err
    with TrialReader(out) as trial:
        assert trial.attachments() == []
        imu = trial.read("/imu/shimmer_40ac")
    assert len(imu) == 90 and imu.temperature is not None
    chans = info_json(out)
    assert chans["/imu/shimmer_40ac"]["samples"] == 90
    assert "/signals/shimmer_40ac" in chans


def test_vicon_csv_pair_and_c3d_give_the_same_channels(tmp_path, shared_data):
    d = shared_data / "vicon_nexus"
    a, b = tmp_path / "csv.mcap", tmp_path / "c3d.mcap"
    assert run("convert", d / "markers.csv", d / "analogs.csv", "-o", a)[0] == 0
    assert run("convert", d / "markers_analogs.c3d", "-o", b)[0] == 0
    frames = pd.read_csv(d / "markers.csv", skiprows=5, header=None)[0].to_numpy()
    for path in (a, b):
        chans = info_json(path)
        check_channel(
            chans["/markers/vicon"],
            samples=len(frames),
            rate_hz=100.0,
            first_ns=0,
            last_ns=(len(frames) - 1) * 10_000_000,
            units="m",
        )
        check_channel(
            chans["/analog/vicon"],
            samples=20 * len(frames),
            rate_hz=2000.0,
            first_ns=0,
            last_ns=(20 * len(frames) - 1) * 500_000,
        )
        assert json.loads(chans["/analog/vicon"]["units"]) == ["V"] * 38
    with TrialReader(a) as ta, TrialReader(b) as tb:
        ma, mb = ta.read("/markers/vicon"), tb.read("/markers/vicon")
    np.testing.assert_array_equal(ma.valid, mb.valid)
    assert np.nanmax(np.abs(ma.pos - mb.pos)) <= 5e-6 + 1e-9  # the CSV's 6 significant digits (see format tests)


def test_c3d_non_integer_rate_and_broad_and_gaitmap(tmp_path, shared_data):
    import ezc3d

    ktk = shared_data / "c3d/ktk_sample_propulsion_upperlimb.c3d"
    rate = float(ezc3d.c3d(str(ktk))["parameters"]["POINT"]["RATE"]["value"][0])
    out = tmp_path / "ktk.mcap"
    assert run("convert", ktk, "-o", out)[0] == 0
    check_channel(
        info_json(out)["/markers/vicon"],
        samples=700,
        rate_hz=rate,
        first_ns=0,
        last_ns=round(699 / rate * 1e9),
        units="m",
        rate_tol=1e-5,
    )

    broad = shared_data / "broad/14_undisturbed_slow_translation_with_breaks_B.hdf5"
    with h5py.File(broad) as f:
        n, brate = len(f["imu_acc"]), float(f.attrs["sampling_rate"])
    out = tmp_path / "broad.mcap"
    assert run("convert", broad, "-o", out)[0] == 0
    chans = info_json(out)
    check_channel(
        chans["/imu/imu"],
        samples=n,
        rate_hz=brate,
        first_ns=0,
        last_ns=round((n - 1) / brate * 1e9),
        units=IMU_UNITS,
        rate_tol=1e-5,
    )
    assert chans["/poses/optical"]["samples"] == n

    out_dir = tmp_path / "gait"
    code, _, err = run("convert", shared_data / "gaitmap_foot", "-o", out_dir)
    assert code == 0, err
    chans = info_json(out_dir / "sample.mcap")
    idx = pd.read_csv(shared_data / "gaitmap_foot/imu_sample.csv", header=[0, 1], index_col=0).index.to_numpy()
    for side in ("left_sensor", "right_sensor"):
        check_channel(
            chans[f"/imu/{side}"],
            samples=len(idx),
            rate_hz=204.8,
            first_ns=0,
            last_ns=round(idx[-1] / 204.8 * 1e9),
            rate_tol=1e-5,
        )
        assert chans[f"/imu/{side}"]["units"].startswith('["m/s^2", "rad/s"')
    check_channel(
        chans["/markers/mocap"], samples=3870, rate_hz=100.0, first_ns=0, last_ns=3869 * 10_000_000, units="m"
    )


def test_xsens_and_adc_end_to_end(tmp_path):
    from test_convert_formats import _xsens_data, write_xsens  # tests/ is on sys.path (rootdir import mode)

    n = 250
    counters = (65500 + np.arange(n)) % 65536
    files = [
        write_xsens(tmp_path / "MT_00B41234.txt", "00B41234", counters, None, _xsens_data(n, 1)),
        write_xsens(tmp_path / "MT_00B45678.txt", "00B45678", counters, None, _xsens_data(n, 2)),
    ]
    out = tmp_path / "xsens.mcap"
    code, _, err = run("convert", *files, "-o", out, "--device-name", "00B45678=wrist")
    assert code == 0, err
    chans = info_json(out)
    for topic in ("/imu/mt_00b41234", "/imu/wrist"):
        check_channel(
            chans[topic],
            samples=n,
            rate_hz=100.0,
            first_ns=65500 * 10_000_000,
            last_ns=(65500 + n - 1) * 10_000_000,
            units='["m/s^2", "rad/s"]',
        )
    assert chans["__metadata__"]["imulog.device.wrist"]["serial"] == "00B45678"

    adc = tmp_path / "witilt.txt"
    adc.write_text("".join(f"X={500 + i % 20}\tY=498\tZ=600\n" for i in range(300)))
    out = tmp_path / "adc.mcap"
    code, _, err = run("convert", adc, "-o", out)
    assert code != 0 and "--rate" in err and not out.exists()
    code, _, err = run("convert", adc, "-o", out, "--rate", "40", "--adc-zero", "500", "--adc-counts-per-g", "128")
    assert code == 0, err
    chans = info_json(out)
    check_channel(chans["/imu/acc"], samples=300, rate_hz=40.0, first_ns=0, last_ns=299 * 25_000_000, units='["m/s^2"]')
    with TrialReader(out) as trial:
        acc = trial.read("/imu/acc").acc
    np.testing.assert_allclose(acc[:20, 0], np.arange(20) / 128 * 9.80665, rtol=1e-12)


def test_bad_input_fails_cleanly_without_output(tmp_path, shared_data):
    bad = tmp_path / "bad.csv"
    lines = (shared_data / "imu_text/fusion_sensor_data.csv").read_text().splitlines()[:50]
    lines[20] = lines[20].replace(",", ",oops,", 1)
    bad.write_text("\n".join(lines) + "\n")
    out = tmp_path / "bad.mcap"
    code, stdout, err = run("convert", bad, "-o", out)
    assert code == 1
    assert not out.exists() and not list(tmp_path.glob("*.mcap*"))
    msg = err.strip().splitlines()
    assert len(msg) == 1 and "bad.csv: line 21" in msg[0]
    # a good IMU file together with a bad one: still nothing written
    code, _, err = run("convert", shared_data / "vicon_nexus/markers.csv", bad, "-o", out)
    assert code == 1 and not out.exists()
    # unknown format and a forced wrong format
    junk = tmp_path / "junk.bin"
    junk.write_bytes(bytes(range(256)))
    code, _, err = run("convert", junk, "-o", out)
    assert code == 1 and "unknown format" in err and not out.exists()
    code, _, err = run("convert", shared_data / "vicon_nexus/markers.csv", "--format", "xsens", "-o", out)
    assert code == 1 and "markers.csv" in err and not out.exists()
    code, _, err = run("convert", junk, "--format", "nope", "-o", out)
    assert code == 2 and "unknown format 'nope'" in err


def test_folder_of_exports_one_trial_per_recording(tmp_path, shared_data):
    sim = pytest.importorskip("imulog.simulate")
    exports = tmp_path / "exports"
    for trial in range(2):
        s = sim.simulate("r2g", trial=trial, repetitions=1, opening_static_s=1.0)
        sim.write_trial_files(s, exports)
    (exports / "broken_imu.csv").write_text(
        "Time (s),Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n0,1,2,3\n0,1,2,3\n"
    )
    out = tmp_path / "trials"
    code, stdout, err = run("convert", exports, "-o", out, "--meta", "site=lab1")
    assert code == 1  # one recording is broken ...
    assert "broken_imu.csv: line 3" in err and "duplicated time stamp" in err
    written = sorted(p.name for p in out.glob("*.mcap"))
    assert written == ["r2g_s00_t00.mcap", "r2g_s00_t01.mcap"]  # ... the others are converted
    for name in written:
        chans = info_json(out / name)
        assert {"/imu/wrist", "/markers/vicon"} <= set(chans)
        md = chans["__metadata__"]
        assert md["imulog.trial"]["site"] == "lab1"
        assert md["imulog.trial"]["subject"] == "S00"  # from the recording's <stem>_meta.json
        assert "forearm_length_m" in md["imulog.anthropometrics"]
        assert md["imulog.device.wrist"]["rate_hz"] == pytest.approx(114.9)


def test_implausible_accelerometer_unit_warns(tmp_path, shared_data):
    """The x-io Fusion file's accelerometer is in g; a header that claims m/s^2 is not an error in the file,
    but the trial would hold gravity as ~1 m/s^2: convert says so on stderr (and not for the real header)."""
    src = (shared_data / "imu_text" / "fusion_sensor_data.csv").read_text()
    assert src.count("(g)") == 3
    code, _, err = run("convert", shared_data / "imu_text" / "fusion_sensor_data.csv", "-o", tmp_path / "ok.mcap")
    assert code == 0 and "warning" not in err
    wrong = tmp_path / "fusion_wrong_unit.csv"
    wrong.write_text(src.replace("(g)", "(m/s^2)"))
    code, _, err = run("convert", wrong, "-o", tmp_path / "wrong.mcap")
    assert code == 0 and "/imu/" in err and "median |acc|" in err and "unit g rather than m/s^2" in err


def test_explicit_mapping_converts_a_header_without_units(tmp_path):
    """A BlueBuddy-style export (timestamp,ax,...) with its mapping file elsewhere: `--mapping FILE` used to
    be ignored by format detection ('unknown format'); without it, the units are inferred from the values
    (issue 14 item 4) and the assumption is said in one line."""
    from imulog.simulate import simulate, write_trial_files

    paths = write_trial_files(simulate("r2g", seed=0, repetitions=1), tmp_path / "sim")
    data = tmp_path / "wrist.csv"
    data.write_bytes(paths["imu"].read_bytes())  # no wrist.mapping.json beside it
    code, _, err = run("convert", data, "-o", tmp_path / "a.mcap")
    assert code == 0 and "no units in the header: assumed time in ms" in err and "gyr in deg/s" in err
    code, out, err = run("convert", data, paths["vicon"], "--mapping", paths["mapping"], "-o", tmp_path / "b.mcap")
    assert code == 0, err
    assert "/imu/wrist" in out and "/markers/vicon" in out
    meta = info_json(tmp_path / "b.mcap")["__metadata__"]
    assert meta["imulog.conversion"]["formats"][data.name] == "delimited"


def test_folder_to_a_single_mcap_path(tmp_path, shared_data):
    """`convert FOLDER -o x.mcap` used to create a *directory* named x.mcap; a folder of one recording now
    writes that file, a folder of several is a usage error that creates nothing."""
    out = tmp_path / "gait.mcap"
    code, out_text, err = run("convert", shared_data / "gaitmap_foot", "-o", out)
    assert code == 0, err
    assert out.is_file() and "/imu/left_sensor" in info_json(out)
    several = tmp_path / "several"
    several.mkdir()
    for name in ("a_imu.csv", "b_imu.csv"):
        (several / name).write_bytes((shared_data / "imu_text" / "fusion_sensor_data.csv").read_bytes())
    code, _, err = run("convert", several, "-o", tmp_path / "x.mcap")
    assert code == 2 and "2 recordings" in err and not (tmp_path / "x.mcap").exists()


def test_adc_sidecar_gives_the_rate_so_a_simulated_adl_folder_converts_in_one_call(tmp_path):
    """Raw ADC text has no time stamps: the board's rate comes from ``<stem>.mapping.json`` beside it."""
    from imulog.simulate import simulate, write_trial_files

    sim = simulate("adl", seed=3, repetitions=2)
    paths = write_trial_files(sim, tmp_path / "raw")
    assert run("convert", tmp_path / "raw", "-o", tmp_path / "out")[0] == 0
    trials = sorted((tmp_path / "out").glob("*.mcap"))
    assert len(trials) == 1  # IMU text, ADC text and Vicon CSV of one session: one trial
    acc = info_json(trials[0])["/imu/acc"]
    n = len(Path(paths["adc"]).read_text().splitlines())
    rate = float(sim.adc["rate_hz"])
    assert acc["samples"] == n and abs(acc["rate_hz"] - rate) < 1e-6
    # counts -> m/s^2 with the nominal calibration (zero 512, 256 counts/g), parsed independently here
    from imulog.converters._common import G0

    counts = np.array(
        [[int(f.split("=")[1]) for f in line.split()] for line in Path(paths["adc"]).read_text().splitlines()]
    )
    with TrialReader(trials[0]) as trial:
        np.testing.assert_array_equal(trial.read("/imu/acc").acc, (counts - 512.0) / 256.0 * G0)
    # the command line still wins over the sidecar
    code, _, _ = run("convert", paths["adc"], "--rate", "50", "-o", tmp_path / "r50.mcap")
    assert code == 0 and abs(info_json(tmp_path / "r50.mcap")["/imu/acc"]["rate_hz"] - 50) < 1e-6
