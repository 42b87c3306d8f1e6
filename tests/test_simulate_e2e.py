"""Simulated raw files -> converters -> MCAP archive: the trial read back equals the simulation and the
ground truth's sample counts, rates and clock offsets."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.simulate import load_truth, simulate, write_trial_files

SHORT = {"repetitions": 3, "opening_static_s": 5.0, "post_wave_static_s": 3.0}


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    sim = simulate("r2g", subject=2, trial=1, seed=11, **SHORT)
    out = tmp_path_factory.mktemp("sim")
    return sim, write_trial_files(sim, out)


def _assert_same_imu(a, b):
    assert a.name == b.name
    assert np.array_equal(a.t_ns, b.t_ns)
    for q in ("acc", "gyr", "mag"):
        # the text holds exact decimals; the parser may differ from the simulator by 1 ulp
        np.testing.assert_allclose(getattr(a, q), getattr(b, q), rtol=1e-15, atol=1e-12)


def test_converters_read_back_the_in_memory_recording(written):
    converters = pytest.importorskip("imulog.converters.registry")
    sim, paths = written
    rec = converters.convert_files([Path(paths["imu"]), Path(paths["vicon"])])
    _assert_same_imu(rec.imus[0], sim.recording.imus[0])
    # the converter adds how the text's numbers are stored (its unit factors as the counts' scale, issue 28)
    meta = dict(rec.imus[0].meta)
    resolution = meta.pop("resolution", None)
    assert meta == sim.recording.imus[0].meta
    assert resolution is None or set(resolution) <= {"acc", "gyr", "mag"}
    mk, ref = rec.markers[0], sim.recording.markers[0]
    assert mk.name == ref.name == "vicon" and mk.labels == ref.labels == ["O", "X", "Y", "A"]
    assert np.array_equal(mk.t_ns, ref.t_ns)
    assert np.array_equal(mk.valid, ref.valid)
    np.testing.assert_allclose(mk.pos, ref.pos, rtol=0, atol=1e-12)
    # device records: every field the converters report that the simulation also reports agrees
    for name in ("imulog.device.wrist", "imulog.device.vicon"):
        ours, theirs = sim.recording.metadata[name], rec.metadata[name]
        common = set(ours) & set(theirs)
        assert {"model", "rate_hz"} <= common
        assert {k: ours[k] for k in common} == {k: theirs[k] for k in common}


def test_archive_has_the_truths_counts_rates_and_offsets(written, tmp_path):
    pytest.importorskip("imulog.archive")
    from imulog.archive import TrialReader
    from imulog.commands.convert import convert
    from imulog.process.alignment import device_to_reference

    sim, paths = written
    out = tmp_path / "trial.mcap"
    result = CliRunner().invoke(
        convert, [str(paths["imu"]), str(paths["vicon"]), "--meta-file", str(paths["meta"]), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    truth = load_truth(paths["truth"])
    with TrialReader(out) as trial:
        channels = {c.topic: c for c in trial.channels}
        imu_ch, vicon_ch = channels["/imu/wrist"], channels["/markers/vicon"]
        assert imu_ch.sample_count == len(truth.imu_t_ref_ns)
        assert vicon_ch.sample_count == len(truth.t_ns)
        assert vicon_ch.rate_hz == pytest.approx(100.0, rel=1e-6)
        # the device clock ticks at the nominal rate except where samples were dropped
        n_expected = len(truth.imu_t_ref_ns) + len(truth.imu_dropped_t_dev_ns)
        span_s = (imu_ch.end_ns - imu_ch.start_ns) / 1e9
        assert (n_expected - 1) / span_s == pytest.approx(114.9, rel=1e-5)
        imu = trial.read("/imu/wrist")
        _assert_same_imu(imu, sim.recording.imus[0])
        assert imu.t_ns[0] == truth.alignment["t0_ns"]
        assert np.abs(device_to_reference(imu.t_ns, truth.alignment) - truth.imu_t_ref_ns).max() <= 1
        markers = trial.read("/markers/vicon")
        assert np.array_equal(markers.t_ns, truth.t_ns)
        meta = trial.metadata
        assert meta["imulog.trial"]["subject"] == "S02" and meta["imulog.trial"]["task"] == "r2g"
        assert meta["imulog.anthropometrics"]["h1_m"] == pytest.approx(truth.anthropometrics["h1_m"])


def test_adc_text_converts_to_the_boards_counts(tmp_path):
    adc_mod = pytest.importorskip("imulog.converters.adc")
    from imulog.converters.base import ConvertOptions

    sim = simulate("adl", seed=6, activity=1, repetitions=2)
    paths = write_trial_files(sim, tmp_path)
    rec = adc_mod.CONVERTER.convert(Path(paths["adc"]), ConvertOptions(rate_hz=sim.adc["rate_hz"]))
    acc = rec.imus[0].acc
    counts = sim.adc["counts"]
    assert len(acc) == len(counts)
    np.testing.assert_allclose(acc, (counts - 512.0) / 256.0 * 9.80665, rtol=1e-12)
    dt = np.diff(rec.imus[0].t_ns)
    assert np.all(np.abs(dt - 1e9 / sim.adc["rate_hz"]) <= 1)


def test_meta_file_holds_trial_and_anthropometrics(written):
    sim, paths = written
    doc = json.loads(Path(paths["meta"]).read_text())
    assert set(doc) == {"imulog.trial", "imulog.anthropometrics"}
    assert doc["imulog.trial"]["subject"] == "S02" and doc["imulog.trial"]["trial"] == 1


def test_nexus_layout_matches_a_real_export(written, shared_data):
    """Header structure of the simulated CSV equals the real Nexus export's (pyomeca sample)."""
    _, paths = written
    real = (shared_data / "vicon_nexus" / "markers.csv").read_bytes().split(b"\r\n")
    ours = Path(paths["vicon"]).read_bytes().split(b"\r\n")
    assert ours[-1] == b"" and real[-1] == b""  # CRLF-terminated lines
    width_real = real[0].count(b",")
    assert all(line.count(b",") == width_real for line in real[:10])
    width = ours[0].count(b",")
    assert all(line.count(b",") == width for line in ours[:-1])  # every row padded to full width
    for k in (0, 3):
        assert ours[k].split(b",")[:3] == real[k].split(b",")[:3]  # 'Trajectories' / 'Frame,Sub Frame,X'
    assert real[1].split(b",")[0] == b"100" == ours[1].split(b",")[0]
    assert ours[4].split(b",")[:3] == real[4].split(b",")[:3] == [b"", b"", b"mm"]
    assert ours[2].split(b",")[2:6] == [b"O", b"", b"", b"X"]
    gap_rows = [line for line in ours[5:] if b",," in line]
    assert gap_rows, "the noisy simulation has occlusion gaps written as empty cells"


def test_bundled_recording_is_reproducible_and_converts(repo_root, tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_recordings", repo_root / "recordings" / "make_recordings.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    written = module.main(tmp_path)
    bundled = repo_root / "recordings" / "sim"
    total = sum(p.stat().st_size for p in bundled.iterdir())
    assert total < 2.2e6
    for paths in written:
        for kind, path in paths.items():
            ref = bundled / path.name
            if kind == "truth_npz":  # zip member dates differ: compare the arrays
                with np.load(path) as a, np.load(ref) as b:
                    assert sorted(a.files) == sorted(b.files)
                    assert all(np.array_equal(a[k], b[k]) for k in a.files)
            else:
                assert path.read_bytes() == ref.read_bytes(), f"{ref} is stale: run recordings/make_recordings.py"
    converters = pytest.importorskip("imulog.converters.registry")
    truth = load_truth(bundled / "r2g_s00_t00_truth.json")
    rec = converters.convert_files([bundled / "r2g_s00_t00_imu.csv", bundled / "r2g_s00_t00_vicon.csv"])
    assert len(rec.imus[0]) == len(truth.imu_t_ref_ns) and len(rec.markers[0]) == len(truth.t_ns)
    assert sorted(set(truth.phases.labels)) == ["lift", "reach", "return_bottle", "return_hand"]
    assert int(truth.phases.task_index.max()) == 5
