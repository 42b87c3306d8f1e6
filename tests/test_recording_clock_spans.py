"""Which IMUs share a recording's clock (:func:`imulog.process.alignment_setup.recording_groups`) compares each IMU's
whole channel, not the stretch the setup reads around the optical data. Before, two devices of different files whose
samples are time-stamped alike from their starts (their own clocks, the same nominal rate) read as "identical time
stamps" whenever both recordings outlast that stretch (the markers' span + ``max_lag_s`` + 600 s), so the second
device was put on the first one's clock. Trial: the simulated marker setup (:func:`imulog.simulate.setup.
simulate_setup`, 30 s) with the IMU recordings going on, still, after the markers (upper arm and trunk 700 s, the
forearm 800 s), the forearm from a file of its own whose clock runs 50 ms from the station's under time stamps
equal to the station's."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from imulog.archive import TrialReader, write_trial
from imulog.cli import cli
from imulog.process.alignment_clock import device_to_reference
from imulog.simulate.setup import simulate_setup

MS = 1_000_000


def longer(s, seconds: float) -> None:
    """Extend IMU stream ``s`` to ``seconds``, still (gravity on the last sample's axis, no turning)."""
    dt = int(np.median(np.diff(s.t_ns)))
    n = int(seconds * 1e9 / dt) - len(s.t_ns)
    s.t_ns = np.concatenate([s.t_ns, s.t_ns[-1] + dt * np.arange(1, n + 1)])
    s.acc = np.concatenate([s.acc, np.repeat(s.acc[-1:], n, axis=0)])
    s.gyr = np.concatenate([s.gyr, np.zeros((n, 3))])
    s.mag = None if s.mag is None else np.concatenate([s.mag, np.repeat(s.mag[-1:], n, axis=0)])
    s.temperature = None


def test_a_device_time_stamped_alike_from_its_start_keeps_its_own_clock(tmp_path):
    sim = simulate_setup(seed=0, duration_s=30.0)
    imus = {s.name: s for s in sim.recording.imus}
    dt = int(np.median(np.diff(imus["forearm"].t_ns)))
    shift = int(round(50 * MS / dt))  # samples in 50 ms
    fa = imus["forearm"]
    fa.acc, fa.gyr = np.roll(fa.acc, shift, axis=0), np.roll(fa.gyr, shift, axis=0)  # a clock 50 ms behind
    fa.mag = None if fa.mag is None else np.roll(fa.mag, shift, axis=0)
    sim.recording.metadata["imulog.device.forearm"]["source"] = fa.meta["source"] = "forearm.csv"
    for name, seconds in (("upper_arm", 700.0), ("trunk", 700.0), ("forearm", 800.0)):
        longer(imus[name], seconds)
    path = write_trial(tmp_path / "setup.mcap", sim.recording, attach_sources=False)
    result = CliRunner().invoke(cli, ["process", "align", str(path)])
    assert result.exit_code == 0, result.output
    with TrialReader(path) as t:
        meta = t.metadata
    groups = meta["imulog.alignment"]["search"]["recordings"]
    assert sorted(map(sorted, groups)) == [["forearm"], ["trunk", "upper_arm"]], groups
    fore = meta["imulog.alignment.forearm"]
    assert fore["clock"] == "own"
    t = imus["forearm"].t_ns[:3000]
    truth = device_to_reference(t, sim.alignment) - shift * dt  # its samples are 50 ms later than the station's
    err = np.max(np.abs(device_to_reference(t, fore) - truth))
    assert err < 3 * MS, err
