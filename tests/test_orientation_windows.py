"""Orientation of long recordings window by window: the same result as at once, in bounded memory."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from imulog.converters import axivity

from imulog.archive import TrialReader
from imulog.archive.doctor import check_file
from imulog.archive.streaming import write_trial_streaming
from imulog.process import quaternion as qmath
from imulog.simulate.home import HomeParams, write_home_cwa
from imulog.steps.orientation import run_orientation
from imulog.steps.windows import WindowParams


@pytest.fixture(scope="module")
def trial(tmp_path_factory):
    folder = tmp_path_factory.mktemp("longori")
    cwa = folder / "home.cwa"
    write_home_cwa(cwa, HomeParams(days=1 / 48, rate_hz=12.5, seed=9, start="2024-03-04T10:00:00"))
    return write_trial_streaming(folder / "home.mcap", axivity.iter_chunks(cwa, blocks_per_chunk=100))


def _tilt_deg(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Angle between the vertical seen in the sensor frame by two orientations (heading-free), degrees."""
    z = np.array([0.0, 0.0, 1.0])
    up_a = qmath.rotate(qmath.conjugate(q_a), np.tile(z, (len(q_a), 1)))
    up_b = qmath.rotate(qmath.conjugate(q_b), np.tile(z, (len(q_b), 1)))
    return np.degrees(np.arccos(np.clip((up_a * up_b).sum(axis=1), -1, 1)))


def test_windows_agree_with_the_whole(trial, tmp_path):
    windowed = tmp_path / "windowed.mcap"
    shutil.copy(trial, windowed)
    whole = tmp_path / "whole.mcap"
    shutil.copy(trial, whole)
    run_orientation(whole)
    outcome = run_orientation(windowed, windows=WindowParams(core_s=300.0, margin_s=20.0))
    assert sorted(outcome.topics) == sorted(
        f"/derived/{k}/ax6_4321" for k in ("orientation", "acc_global", "orientation_static")
    )
    with TrialReader(whole) as a, TrialReader(windowed) as b:
        qa = a.read("/derived/orientation/ax6_4321")
        qb = b.read("/derived/orientation/ax6_4321")
        np.testing.assert_array_equal(qa.t_ns, qb.t_ns)
        tilt = _tilt_deg(qa.values, qb.values)
        assert np.median(tilt) < 0.2 and np.percentile(tilt, 99) < 1.0, (np.median(tilt), tilt.max())
        # headings joined at the window boundaries: no jump in the gravity-free acceleration there
        la = a.read("/derived/acc_global/ax6_4321").values
        lb = b.read("/derived/acc_global/ax6_4321").values
        assert np.median(np.linalg.norm(la - lb, axis=1)) < 0.05  # m/s^2
        info = b.channel("/derived/orientation/ax6_4321")
        # stored at the precision the one-window path asks for (several windows used to write float64: 2-4x the bytes)
        for topic in ("/derived/orientation/ax6_4321", "/derived/acc_global/ax6_4321"):
            assert a.channel(topic).metadata.get("precision") == "quantized"
            assert b.channel(topic).metadata.get("precision") == "quantized", topic
        assert info.sample_count == len(qa) and info.metadata["sha256"] == b.compute_channel_hash(info.topic)
        assert b.runs()[max(b.runs())]["params"]["windows"] == {"core_s": 300.0, "margin_s": 20.0}
        assert any(c.topic == "/derived/viewer/orientation/ax6_4321" for c in b.channels)
    assert not check_file(windowed).problems
    again = run_orientation(windowed, windows=WindowParams(core_s=300.0, margin_s=20.0))
    assert again.skipped


def test_a_lab_trial_is_one_window_and_equals_the_whole_computation(processed_r2g):
    """The step's one implementation on a lab trial: exactly orientation_with_gaps on the whole channel."""
    from imulog.process.orientation import OrientationParams
    from imulog.steps.orientation import orientation_with_gaps, read_imu_arrays

    with TrialReader(processed_r2g) as trial:
        streams, _ = orientation_with_gaps(*read_imu_arrays(trial, "/imu/wrist"), "wrist", OrientationParams())
        for s in streams:
            got = trial.read(s.topic)
            np.testing.assert_array_equal(got.t_ns, s.t_ns)
            # quaternions and global accelerations are stored as counts on their grids (issue 28, docs/schemas.md)
            want = s.values
            if s.attrs.get("precision") == "quantized":
                step = float(s.attrs["quantum"])
                want = np.rint(s.values / step) * step
            np.testing.assert_array_equal(got.values, want)
        run = next(r for r in trial.runs().values() if r["step"] == "orientation:wrist")
        assert "windows" not in run["params"]  # one window: the result does not depend on the plan


def _blocks(t, acc, gyr, size):
    for a in range(0, len(t), size):
        yield t[a : a + size], acc[a : a + size], gyr[a : a + size], None


def test_windows_join_headings_and_hold_them_across_a_gap_at_the_join():
    """Several windows on synthetic blocks: tilt as the whole, no heading jump at a join, also when the join
    falls inside a long gap (the heading is held across it, as within one window)."""
    from imulog.process.orientation import OrientationParams
    from imulog.steps.orientation import orientation_windows, orientation_with_gaps
    from imulog.steps.windows import plan_windows

    rate, n = 50.0, 9000
    rng = np.random.default_rng(4)
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    gyr = np.column_stack([0.2 * np.sin(np.arange(n) / 97), 0.2 * np.cos(np.arange(n) / 131), np.full(n, 0.1)])
    gyr += rng.normal(0, 0.005, (n, 3))
    q = np.zeros((n, 4))
    q[0] = [1, 0, 0, 0]
    for k in range(1, n):  # exact integration of the body rate (sensor-to-global)
        w = gyr[k - 1] / rate
        ang = np.linalg.norm(w)
        dq = np.r_[np.cos(ang / 2), np.sin(ang / 2) * w / ang]
        q[k] = qmath.multiply(q[k - 1 : k], dq[None])[0]
    acc = qmath.rotate(qmath.conjugate(q), np.tile([0.0, 0.0, 9.81], (n, 1))) + rng.normal(0, 0.02, (n, 3))
    gap = slice(3000 - 40, 3000 + 40)  # a long gap across the first join
    acc[gap] = np.nan
    gyr[gap] = np.nan
    params = OrientationParams()
    whole, _ = orientation_with_gaps(t, acc, gyr, None, "imu", params)
    plan = plan_windows(n, rate, core_s=60.0, margin_s=10.0)
    assert len(plan) == 3
    reports = []
    pieces = list(orientation_windows(_blocks(t, acc, gyr, 700), n, plan, "imu", params, reports=reports))
    assert len(reports) == 3 and [p.topic for p in pieces[:3]] == [s.topic for s in whole]
    quat = np.concatenate([p.values for p in pieces if p.topic == "/derived/orientation/imu"])
    lin = np.concatenate([p.values for p in pieces if p.topic == "/derived/acc_global/imu"])
    np.testing.assert_array_equal(np.concatenate([p.t_ns for p in pieces[::3]]), t)
    ok = np.isfinite(quat).all(axis=1)
    np.testing.assert_array_equal(ok, np.isfinite(whole[0].values).all(axis=1))
    tilt = _tilt_deg(quat[ok], whole[0].values[ok])
    assert np.percentile(tilt, 99) < 1.0, tilt.max()
    # heading relative to the whole computation: constant across both joins (no jump), gap at the first included
    rel = qmath.multiply(quat[ok], qmath.conjugate(whole[0].values[ok]))
    yaw = np.degrees(np.unwrap(2 * np.arctan2(rel[:, 3], rel[:, 0])))
    assert np.ptp(yaw) < 3.0, np.ptp(yaw)
    assert np.nanmedian(np.linalg.norm(lin - whole[1].values, axis=1)) < 0.05


def test_several_windows_record_the_gap_report_of_each_window_with_a_gap(tmp_path):
    """With several windows the gap report is known only once the pieces are written: the run record still
    carries it, per window that had missing samples, with runs in whole-channel sample indices."""
    from imulog.archive import write_trial
    from imulog.model import ImuStream, Recording

    rate, n = 50.0, 9000
    rng = np.random.default_rng(5)
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    gyr = rng.normal(0, 0.01, (n, 3))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 0.02, (n, 3))
    acc[7000:7100] = np.nan  # a 2 s gap inside the third window's core (no other window reads it): not bridged
    gyr[7000:7100] = np.nan
    path = write_trial(tmp_path / "gap.mcap", Recording(imus=[ImuStream("wrist", t, acc=acc, gyr=gyr)]))
    run_orientation(path, windows=WindowParams(core_s=60.0, margin_s=10.0))
    with TrialReader(path) as trial:
        run = trial.runs()[max(trial.runs())]
        quat = trial.read("/derived/orientation/wrist").values
    assert run["params"]["windows"] == {"core_s": 60.0, "margin_s": 10.0}
    gapped = run["gaps"]["windows"]
    assert [w["core"] for w in gapped] == [[6000, 9000]]  # only the window whose read span holds the gap
    assert gapped[0]["missing_samples"] == 100
    assert gapped[0]["read"] == [5500, 9000] and gapped[0]["runs"] == [[5500, 7000], [7100, 9000]]  # whole-channel
    assert np.isnan(quat[7000:7100]).all() and np.isfinite(quat[:7000]).all() and np.isfinite(quat[7100:]).all()
