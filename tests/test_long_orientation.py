"""Orientation of long recordings window by window: the same result as at once, in bounded memory."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from converters import axivity
from imulog.archive import TrialReader
from imulog.archive.doctor import check_file
from imulog.archive.streaming import write_trial_streaming
from imulog.process import quaternion as qmath
from imulog.simulate.home import HomeParams, write_home_cwa
from imulog.steps.long_orientation import WindowParams
from imulog.steps.orientation import run_orientation


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
    outcome = run_orientation(windowed, windowed=WindowParams(window_s=300.0, overlap_s=20.0))
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
        assert info.sample_count == len(qa) and info.metadata["sha256"] == b.compute_channel_hash(info.topic)
        assert b.runs()[max(b.runs())]["params"]["windows"] == {"window_s": 300.0, "overlap_s": 20.0}
        assert any(c.topic == "/derived/viewer/orientation/ax6_4321" for c in b.channels)
    assert not check_file(windowed).problems
    again = run_orientation(windowed, windowed=WindowParams(window_s=300.0, overlap_s=20.0))
    assert again.skipped
