"""Epoch summaries (imulog process epochs): ENMO and MAD against an independent numpy computation, non-wear
against the home simulator's removal truth, window independence, calibration, counts' published behaviour."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from imulog.process import epochs as ep
from imulog.steps.epochs import EpochParams, run_epochs

G0 = 9.80665


@pytest.fixture(scope="module")
def half_day(tmp_path_factory) -> tuple[Path, np.ndarray, dict]:
    """12 h at 25 Hz with two device removals, converted; returns (trial, removal minutes, sim params)."""
    from imulog.simulate.home import HomeParams, removals, write_home_cwa

    out = tmp_path_factory.mktemp("home")
    p = HomeParams(days=0.5, rate_hz=25.0, removals_per_day=2, seed=3, removal_min_minutes=60)
    write_home_cwa(out / "h.cwa", p)
    trial = out / "h.mcap"
    _convert(out / "h.cwa", trial)
    return trial, np.array(removals(p)), p


def _convert(src: Path, dst: Path) -> None:
    from click.testing import CliRunner

    from imulog.cli import cli as main

    r = CliRunner().invoke(main, ["convert", str(src), "-o", str(dst)])
    assert r.exit_code == 0, r.output


def _epochs(trial: Path, name: str):
    from imulog.archive import TrialReader

    with TrialReader(trial) as t:
        return t.read(name), t.metadata["imulog.epochs"]


def test_enmo_mad_equal_numpy_and_nonwear_finds_each_removal(half_day):
    trial, truth, p = half_day
    assert len(truth) >= 1
    run_epochs(trial, params=EpochParams(calibrate=False), force=True)
    from imulog.archive import TrialReader

    with TrialReader(trial) as t:
        imu = t.read("/imu/ax6_4321")
    g = np.asarray(imu.acc, dtype=np.float64) / G0
    for e_s in (5, 60):
        stream, record = _epochs(trial, f"/derived/epochs/{e_s}s/ax6_4321")
        per = int(e_s * 25)
        k = len(g) // per
        r = np.linalg.norm(g[: k * per].reshape(k, per, 3), axis=2)
        enmo = np.clip(r - 1, 0, None).mean(axis=1)
        mad = np.abs(r - r.mean(axis=1, keepdims=True)).mean(axis=1)
        col = stream.columns
        np.testing.assert_allclose(stream.values[:k, col.index("enmo_g")], enmo, rtol=0, atol=1e-9)
        np.testing.assert_allclose(stream.values[:k, col.index("mad_g")], mad, rtol=0, atol=1e-9)
        assert np.array_equal(stream.t_ns[:k], imu.t_ns[: k * per : per])
    # non-wear: each removal found within one 15-min block at both ends, nothing else flagged
    found = np.array(record["nonwear"], dtype=np.int64) / 60e9
    assert len(found) == len(truth), (found, truth)
    np.testing.assert_allclose(found, truth, atol=15.0)
    assert record["by_day"][0]["wear_h"] == pytest.approx(
        record["by_day"][0]["recorded_h"] - (found[:, 1] - found[:, 0]).sum() / 60, abs=1e-3
    )


def test_windows_give_the_whole_computation(half_day):
    """Cores of 1 h (12 windows) and one 12-h window: the same epochs (the step-window contract)."""
    trial, _, _ = half_day
    run_epochs(trial, params=EpochParams(), force=True)
    many, rec_many = _epochs(trial, "/derived/epochs/60s/ax6_4321")
    run_epochs(trial, params=EpochParams(core_s=43200.0), force=True)
    one, rec_one = _epochs(trial, "/derived/epochs/60s/ax6_4321")
    assert np.array_equal(many.t_ns, one.t_ns)
    np.testing.assert_allclose(many.values[:, :2], one.values[:, :2], atol=1e-12)
    counts = many.columns.index("counts_x")
    assert np.abs(many.values[:, counts : counts + 3] - one.values[:, counts : counts + 3]).max() <= 1.0
    assert rec_many["nonwear"] == rec_one["nonwear"]
    assert rec_many["calibration"] == rec_one["calibration"]


def test_calibration_recovers_offset_and_scale():
    rng = np.random.default_rng(1)
    d = rng.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    offset, scale = np.array([0.02, -0.015, 0.03]), np.array([1.01, 0.98, 1.02])
    raw = d / scale - offset + rng.normal(0, 0.001, d.shape)  # so that (raw + offset) * scale = d
    cal = ep.fit_calibration(raw)
    assert cal.applied
    np.testing.assert_allclose(cal.offset, offset, atol=2e-3)
    np.testing.assert_allclose(cal.scale, scale, atol=2e-3)
    assert cal.error_after_mg < cal.error_before_mg / 5
    flat = ep.fit_calibration(np.tile([0.0, 0.0, 1.0], (200, 1)))
    assert not flat.applied and "reach" in flat.reason


def test_nonwear_rule_sd_and_range():
    rng = np.random.default_rng(0)
    per = 100
    still = rng.normal(0, 0.003, (8 * per, 3)) + [0, 0, 1]
    moving = still.copy()
    moving[4 * per :, 0] += np.sin(np.arange(4 * per) / 3)  # blocks 4..7 move on one axis only
    assert ep.nonwear_blocks(ep.AxisStats.of_blocks(still, per)).all()
    assert ep.nonwear_blocks(ep.AxisStats.of_blocks(moving, per)).all()  # 2 of 3 axes still: non-wear
    moving[4 * per :, 1] += np.cos(np.arange(4 * per) / 3)
    flags = ep.nonwear_blocks(ep.AxisStats.of_blocks(moving, per))
    assert flags[:4].all() and not flags[4:].any()


def test_block_statistics_combine_exactly():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(1000, 3))
    sd, span = ep.AxisStats.of_blocks(a, 100).windows(4)
    np.testing.assert_allclose(sd[3], a[300:700].std(axis=0, ddof=1), rtol=1e-12)
    np.testing.assert_allclose(span[3], np.ptp(a[300:700], axis=0), rtol=0)


def test_counts_published_behaviour():
    """Neishabouri 2022: still data gives 0 counts; a step in gravity is not counted after the first sample's state;
    counts are capped at 128 per 30 Hz sample (so at most 1280 per second per axis)."""
    f = ep.CountsFilter()
    assert ep.counts_per_epoch(f(np.tile([0.1, -0.2, 0.97], (900, 1))), 1.0).sum() == 0
    t = np.arange(30 * 60) / 30
    big = np.column_stack([8 * np.sin(2 * np.pi * 1.0 * t)] * 3)
    c = ep.counts_per_epoch(ep.CountsFilter()(big), 60.0)
    assert c.max() <= 128 * 10 * 60 and c.min() > 0
    # a 1 Hz wave is in the pass band: counts grow with amplitude
    small = ep.counts_per_epoch(ep.CountsFilter()(big / 40), 60.0)
    assert 0 < small.max() < c.max()


def test_counts_resampling_factors():
    assert ep.counts_factors(100) == (3, 10)
    assert ep.counts_factors(30) == (1, 1)
    assert ep.counts_factors(25) == (6, 5)
    with pytest.raises(ValueError, match="30 Hz"):
        ep.counts_factors(102.4001)


def test_cli_json_and_export(half_day, tmp_path):
    from click.testing import CliRunner

    from imulog.cli import cli as main

    trial, _, _ = half_day
    r = CliRunner().invoke(main, ["process", "epochs", str(trial), "--epoch-s", "60", "--json"])
    assert r.exit_code == 0, r.output
    rec = json.loads(r.output)
    assert rec["epochs_s"] == [60.0] and len(rec["by_hour"]) >= 12
    out = tmp_path / "e.csv"
    r = CliRunner().invoke(main, ["export", str(trial), "-t", "/derived/epochs/60s/ax6_4321", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "enmo_g" in out.read_text().splitlines()[0]


def test_epoch_not_whole_samples_is_one_line(half_day):
    from click.testing import CliRunner

    from imulog.cli import cli as main

    trial, _, _ = half_day
    r = CliRunner().invoke(main, ["process", "epochs", str(trial), "--epoch-s", "0.01"])
    assert r.exit_code != 0 and "whole number of samples" in r.output and len(r.output.strip().splitlines()) == 1


def test_a_geneactiv_at_85_7_hz_is_told_which_epochs_fit(tmp_path):
    """85.7 Hz holds no whole number of samples in 5 s: the one error line names the epochs that do (10 s
    multiples), and the command it gives runs on the real GENEActiv file."""
    from click.testing import CliRunner

    from imulog.cli import cli as main

    src = (
        Path(__file__).parent.parent / ".." / "shared" / "data" / "devices" / "geneactiv_bin" / "GENEActiv_testfile.bin"
    )
    if not src.exists():
        pytest.skip(f"{src} not available")
    trial = tmp_path / "g.mcap"
    _convert(src, trial)
    r = CliRunner().invoke(main, ["process", "epochs", str(trial)])
    assert r.exit_code != 0 and len(r.output.strip().splitlines()) == 1
    assert r.output.strip().endswith(
        "at 85.7 Hz (at this rate use epochs of 10 s multiples: --epoch-s 10 --epoch-s 60; in imulog batch "
        "--set epochs.epochs_s=10,60)"
    )
    r = CliRunner().invoke(main, ["process", "epochs", str(trial), "--epoch-s", "10", "--epoch-s", "60"])
    assert r.exit_code == 0, r.output
    # the batch's form of the same, as the line gives it (a study's batch printed the command line's only)
    r = CliRunner().invoke(main, ["batch", str(trial), "--steps", "epochs", "--set", "epochs.epochs_s=10,60"])
    assert r.exit_code == 0 and "0 failed" in r.output, r.output


def test_simulated_removals_are_still():
    from datetime import datetime

    from imulog.simulate.home import HomeParams, minute_signals, removals

    p = HomeParams(days=1.0, rate_hz=25.0, removals_per_day=1, seed=5)
    (a, b), *_ = removals(p)
    acc, _, moving = minute_signals(p, a + 1, datetime.fromisoformat(p.start))
    assert moving == 0 and acc.std(axis=0).max() < 0.006
    assert replace(p, removals_per_day=0) != p and removals(replace(p, removals_per_day=0)) == []


def _shared_counts(name: str, topic: str, rate: int, tmp_path) -> tuple[np.ndarray, np.ndarray]:
    from imulog.archive import TrialReader

    src = Path(__file__).parent.parent / ".." / "shared" / "data" / "devices" / name
    if not src.exists():
        pytest.skip(f"{src} not available")
    trial = tmp_path / "t.mcap"
    _convert(src, trial)
    with TrialReader(trial) as t:
        g = np.asarray(t.read(topic).acc, dtype=np.float64) / G0
    ours = ep.counts_per_epoch(ep.CountsFilter()(ep.to_30hz(g, rate)), 10.0)
    import csv

    with open(Path(__file__).parent / "data" / "agcounts_10s.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["file"] == name]
    ref = np.array([[float(r[c]) for c in ("counts_x", "counts_y", "counts_z")] for r in rows])
    return ours, ref


def test_counts_equal_agcounts_on_the_actigraph_sample(tmp_path):
    """90 Hz ActiGraph GT9X: every 10-s epoch within 1 count of agcounts (ActiGraph's reference)."""
    ours, ref = _shared_counts("actigraph_gt3x/example.gt3x", "/imu/tas1e31150129", 90, tmp_path)
    assert len(ref) == 18 and len(ours) >= len(ref)
    assert np.abs(ours[: len(ref)] - ref).max() <= 1.0


def test_counts_equal_agcounts_on_the_axivity_sample(tmp_path):
    """100 Hz AX6: ActiLife's resampler (imulog.process.counts_resample) gives agcounts' counts, every 10-s epoch
    and axis within 1 count (polyphase resampling was up to 109 counts off)."""
    ours, ref = _shared_counts("axivity_cwa/ax6_sample.cwa", "/imu/ax6_6011802", 100, tmp_path)
    assert len(ref) == 10 and len(ours) >= len(ref)
    assert np.abs(ours[: len(ref)] - ref).max() <= 1.0


@pytest.mark.parametrize(
    "name, imu, declared",
    [("axivity_cwa/ax6_sample.cwa", "ax6_6011802", 100.0), ("axivity_cwa/ax3_sample.cwa", "ax3_51888", 200.0)],
)
def test_epochs_of_a_real_cwa_count_at_its_declared_rate(tmp_path, name, imu, declared):
    """The shared .cwa files' stamps run 1.6 % (AX6: 98.4 Hz) and 1.4 % (AX3: 197.2 Hz) off the declared rate, so
    the converter keeps the declaration as ``declared_rate_hz``; ``imulog process epochs`` counts at it (it
    stopped with "not a whole number of samples at 98.4135 Hz"). The AX6's 10-s counts from the command equal
    agcounts' (ActiGraph's reference, run at 100 Hz) within 1 count."""
    from click.testing import CliRunner

    from imulog.archive import TrialReader
    from imulog.cli import cli as main

    src = Path(__file__).parent.parent / ".." / "shared" / "data" / "devices" / name
    if not src.exists():
        pytest.skip(f"{src} not available")
    trial = tmp_path / "t.mcap"
    _convert(src, trial)
    r = CliRunner().invoke(main, ["process", "epochs", str(trial), "--epoch-s", "10"])
    assert r.exit_code == 0, r.output
    with TrialReader(trial) as t:
        assert json.loads(t.channel(f"/imu/{imu}").metadata["meta"])["declared_rate_hz"] == declared
        assert t.metadata["imulog.epochs"]["rate_hz"] == declared
        epochs = t.read(f"/derived/epochs/10s/{imu}")
        t_imu = t.read(f"/imu/{imu}").t_ns
    # an epoch is 10 s of samples at the declared rate, stamped at its first sample's own time (docs/epochs.md)
    np.testing.assert_array_equal(epochs.t_ns, t_imu[:: int(10 * declared)])
    ours = epochs.values[:, [epochs.columns.index(c) for c in ("counts_x", "counts_y", "counts_z")]]
    _, ref = _shared_counts(name, f"/imu/{imu}", int(declared), tmp_path / "ref")
    if len(ref):
        assert np.abs(ours[: len(ref)] - ref).max() <= 1.0


def _synthetic_reference() -> dict[int, np.ndarray]:
    import csv

    with open(Path(__file__).parent / "data" / "agcounts_10s.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["file"] == "synthetic"]
    out: dict[int, list[list[float]]] = {}
    for r in rows:
        out.setdefault(int(r["rate_hz"]), []).append([float(r[c]) for c in ("counts_x", "counts_y", "counts_z")])
    return {k: np.array(v) for k, v in out.items()}


def _synthetic_acc(rate_hz: int) -> np.ndarray:
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "agcounts_signals", Path(__file__).parent / "data" / "agcounts_signals.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.synthetic_acc(rate_hz)


@pytest.mark.parametrize("rate", [30, 40, 50, 60, 70, 80, 90, 100])
def test_counts_equal_agcounts_on_closed_form_signals(rate):
    """Every rate agcounts takes from 30 to 100 Hz: a closed-form 5-min signal with 7-18 Hz content (what the
    resampler aliases), each 10-s epoch and axis within 1 count of agcounts' stored output."""
    ref = _synthetic_reference()[rate]
    ours = ep.counts_per_epoch(ep.CountsFilter()(ep.to_30hz(_synthetic_acc(rate), rate)), 10.0)
    assert len(ref) == 30 and len(ours) == len(ref)
    assert ref.sum() > 10000  # the signal moves: polyphase resampling is 4-85 counts off per epoch here
    assert np.abs(ours - ref).max() <= 1.0


def test_actilife_resampler_keeps_gravity_and_starts_from_rest():
    """Unit mean gain at rest once settled (with the ripple of its one-pole interpolation), the first output is the low-pass's first step from zero (as ActiLife),
    and the output length is ceil(N L / M)."""
    from imulog.process.counts_resample import actilife_lowpass_coefficients, actilife_to_30hz

    x = np.tile([0.0, 0.0, 1.0], (1000, 1))
    y = actilife_to_30hz(x, 3, 10)
    assert len(y) == 300
    settled = y[21:, 2].reshape(-1, 3)  # the picked phase cycles through the L = 3 zero-stuffed slots
    np.testing.assert_allclose(settled.mean(axis=1), 1.0, atol=1e-12)  # gain 1 over each cycle
    assert np.ptp(settled[-1]) > 0.5  # and a 10 Hz ripple a proper interpolator would not leave
    b, _ = actilife_lowpass_coefficients(3)
    assert y[0, 2] == pytest.approx(b[0]) and abs(b[0] - 1.0) > 0.02  # g x[0], not x[0]
    assert len(actilife_to_30hz(x[:7], 3, 4)) == 6


def test_windows_give_the_whole_computation_at_100hz(tmp_path):
    """At 100 Hz (ActiLife's resampler, carried through 60-s margins) 30-min cores, one 2-h window and the pure
    functions on the whole signal give the same counts."""
    from imulog.archive import TrialReader
    from imulog.simulate.home import HomeParams, write_home_cwa

    p = HomeParams(days=2.0 / 24, rate_hz=100.0, seed=11, day_move_probability=0.8)
    write_home_cwa(tmp_path / "h.cwa", p)
    trial = tmp_path / "h.mcap"
    _convert(tmp_path / "h.cwa", trial)
    results = []
    for core_s in (1800.0, 7200.0):
        run_epochs(trial, params=EpochParams(epochs_s=(10.0,), calibrate=False, core_s=core_s), force=True)
        e, _ = _epochs(trial, "/derived/epochs/10s/ax6_4321")
        k = e.columns.index("counts_x")
        results.append(e.values[:, k : k + 3])
    with TrialReader(trial) as t:
        g = np.asarray(t.read("/imu/ax6_4321").acc, dtype=np.float64) / G0
    whole = ep.counts_per_epoch(ep.CountsFilter()(ep.to_30hz(g, 100.0)), 10.0)
    assert results[0].sum() > 1000
    assert np.abs(results[0] - results[1]).max() <= 1.0
    assert np.abs(results[1] - whole[: len(results[1])]).max() <= 1.0


def test_catalog_gathers_epochs_into_one_study_table(half_day, tmp_path):
    import shutil

    import pyarrow.parquet as pq
    from click.testing import CliRunner

    from imulog.cli import cli as main

    trial, _, _ = half_day
    run_epochs(trial, params=EpochParams(), force=False)
    folder = tmp_path / "study"
    folder.mkdir()
    for k in range(2):
        shutil.copy(trial, folder / f"s{k}.mcap")
    out, cat = tmp_path / "epochs.parquet", tmp_path / "catalog.parquet"
    r = CliRunner().invoke(main, ["catalog", str(folder), "-o", str(cat), "-q", "--epochs", str(out)])
    assert r.exit_code == 0, r.output
    table = pq.read_table(out).to_pandas()
    one, record = _epochs(trial, "/derived/epochs/60s/ax6_4321")
    assert len(table) == 2 * len(one) and table["path"].nunique() == 2
    assert {"time", "t[s]", "t_ns", "enmo_g[g]", "nonwear"} <= set(table.columns)
    np.testing.assert_array_equal(table["t_ns"].to_numpy()[: len(one)], one.t_ns)
    rows = pq.read_table(cat).to_pandas()
    assert (rows["valid_days"] == record["valid_days"]).all()
    assert rows["wear_h"].iloc[0] == pytest.approx(sum(d["wear_h"] for d in record["by_day"]))


def test_missing_samples_are_left_out(tmp_path):
    """NaN samples (lost packets): ENMO over the recorded samples, valid_fraction says how many, counts finite."""
    from imulog.archive import write_trial
    from imulog.model import ImuStream, Recording

    rate, n = 25.0, 25 * 60 * 90  # 90 min
    rng = np.random.default_rng(4)
    t = np.arange(n, dtype=np.int64) * 40_000_000
    g = np.column_stack([np.sin(np.arange(n) / 40) * 0.3, np.zeros(n), np.ones(n)]) + rng.normal(0, 0.01, (n, 3))
    g[3000:3100] = np.nan  # 4 s missing inside one 60-s epoch
    trial = tmp_path / "gap.mcap"
    write_trial(trial, Recording(imus=[ImuStream("w", t, acc=g * G0, meta={"rate_hz": rate})]))
    run_epochs(trial, params=EpochParams(epochs_s=(60.0,), calibrate=False))
    stream, _ = _epochs(trial, "/derived/epochs/60s/w")
    c = stream.columns
    per = 1500
    e = 3000 // per
    r = np.linalg.norm(g[e * per : (e + 1) * per], axis=1)
    assert stream.values[e, c.index("valid_fraction")] == pytest.approx(1 - 100 / per)
    assert stream.values[e, c.index("enmo_g")] == pytest.approx(np.nanmean(np.clip(r - 1, 0, None)), abs=1e-12)
    assert np.isfinite(stream.values[:, c.index("counts_vm")]).all()
    assert (stream.values[np.arange(len(stream)) != e, c.index("valid_fraction")] == 1).all()


def test_choi_rule_on_built_minute_counts():
    """Choi 2011: >= 90 zero minutes, interruptions of <= 2 min allowed with 30 zero minutes on each side."""
    worn = np.full(60, 50.0)
    c = np.concatenate([worn, np.zeros(89), worn])  # 89 min: too short
    assert not ep.choi_nonwear(c).any()
    c = np.concatenate([worn, np.zeros(90), worn])
    assert ep.choi_nonwear(c).sum() == 90 and ep.choi_nonwear(c)[60:150].all()
    # a 2-min interruption with 40 and 50 zero minutes around it: one 92-min period
    c = np.concatenate([worn, np.zeros(40), [5.0, 7.0], np.zeros(50), worn])
    flags = ep.choi_nonwear(c)
    assert flags.sum() == 92 and flags[60:152].all()
    # a 3-min interruption, or one with only 20 zero minutes before it, splits the run: nothing reaches 90
    for before, burst, after in ((45, 3, 45), (20, 2, 69)):
        c = np.concatenate([worn, np.zeros(before), np.full(burst, 5.0), np.zeros(after), worn])
        assert not ep.choi_nonwear(c).any(), (before, burst, after)
    # missing minutes count as zero; an empty input is no non-wear
    c = np.concatenate([worn, np.full(100, np.nan), worn])
    assert ep.choi_nonwear(c).sum() == 100
    assert ep.choi_nonwear(np.zeros(0)).shape == (0,)


def test_choi_nonwear_finds_each_simulated_removal(half_day):
    trial, truth, _ = half_day
    run_epochs(trial, params=EpochParams(), force=True)
    _, record = _epochs(trial, "/derived/epochs/60s/ax6_4321")
    minutes = np.array(record["nonwear_choi"], dtype=np.int64).reshape(-1, 2) / 60e9
    # Choi's rule needs 90 zero minutes: each removal at least that long is one period, within one 60-s epoch at
    # each end; a shorter removal is (by the rule) worn; nothing else is flagged
    long_ones = [(a, b) for a, b in truth if b - a >= 90]
    assert long_ones and len(long_ones) < len(truth), truth  # the fixture holds both kinds
    assert len(minutes) == len(long_ones), (minutes, truth)
    np.testing.assert_allclose(minutes, np.array(long_ones, dtype=float), atol=1.0)


@pytest.mark.slow  # 25 s of CPU: a week at 12.5 Hz simulated, converted and summarised
def test_nonwear_on_a_simulated_week_finds_each_removal(tmp_path):
    """Issue 28's done-when on its own terms: a simulated week (12.5 Hz, the lowest AX6 rate, to keep the test to
    seconds; the rule works on 15-min block statistics, not on the rate) with one removal a day of 1-3 h: every
    removal found within one 15-min window at each end (van Hees), each of 90 min or more within one 60-s epoch
    (Choi), nothing else flagged, and the days' wear hours add up to the recording less the removals."""
    from imulog.simulate.home import HomeParams, removals, write_home_cwa

    p = HomeParams(days=7.0, rate_hz=12.5, removals_per_day=1, seed=11)
    truth = np.array(removals(p), dtype=float)
    assert len(truth) >= 6  # about one a day (a removal cut by the recording's end is left out)
    write_home_cwa(tmp_path / "w.cwa", p)
    trial = tmp_path / "w.mcap"
    _convert(tmp_path / "w.cwa", trial)
    run_epochs(trial, params=EpochParams(epochs_s=(10.0, 60.0), calibrate=False))  # 5 s is 62.5 samples
    _, record = _epochs(trial, "/derived/epochs/60s/ax6_4321")
    found = np.array(record["nonwear"], dtype=np.int64).reshape(-1, 2) / 60e9
    assert len(found) == len(truth), (found, truth)
    np.testing.assert_allclose(found, truth, atol=15.0)
    long_ones = truth[truth[:, 1] - truth[:, 0] >= 90]
    choi = np.array(record["nonwear_choi"], dtype=np.int64).reshape(-1, 2) / 60e9
    assert len(long_ones) and len(choi) == len(long_ones), (choi, truth)
    np.testing.assert_allclose(choi, long_ones, atol=1.0)
    assert len(record["by_day"]) >= 7
    worn = sum(d["wear_h"] for d in record["by_day"])
    recorded = sum(d["recorded_h"] for d in record["by_day"])
    assert worn == pytest.approx(recorded - (found[:, 1] - found[:, 0]).sum() / 60, abs=1e-2)
