"""A simulated drinking trial segmented with the defaults and with step options (`HandParams`), for the tests of
step 7's flank options: one helper, not a copy per test file."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from imulog.process.segmentation.hand import HandParams
from imulog.process.segmentation.pipeline import PhaseParams, segment_phases
from imulog.process.segmentation.repetitions import RepetitionParams
from imulog.simulate import simulate
from imulog.simulate.grid import condition


def simulated_phases(cond: str, seed: int, subject: int, options: dict[str, HandParams]):
    """Truth, the default's phases, each option's phases (by name) and the sample times (s) of a simulated
    10-repetition trial of grid condition ``cond``."""
    sim = simulate("r2g", seed=seed, subject=subject, repetitions=10, **condition(cond))
    imu = sim.recording.imus[0]
    t = np.asarray(sim.truth.imu_t_ref_ns, dtype=np.int64) * 1e-9
    rate = (len(imu.t_ns) - 1) / ((imu.t_ns[-1] - imu.t_ns[0]) * 1e-9)
    p = PhaseParams(repetitions=RepetitionParams(n_repetitions=10))
    default = segment_phases(imu.gyr, rate, p, imu.acc).phases
    phases = {k: segment_phases(imu.gyr, rate, replace(p, hand=h), imu.acc).phases for k, h in options.items()}
    return sim.truth.phases, default, phases, t
