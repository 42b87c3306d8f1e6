"""The anthropometric reference of the R2G optimisation (h1-h3, thesis 3.3.7): its axes, its signs and what the
user measures, checked by moving the bottle and the mouth in the simulator (issue 19, part 3)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from truth_repetitions import true_repetitions

from imulog.process.minjerk import r2g_waypoints_from_anthropometrics
from imulog.process.trajectory_opt import trial_waypoints
from imulog.simulate import simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

BOTTLE_SHIFT = (0.08, -0.10)  # bottle 8 cm further away and 10 cm to the subject's right
MOUTH_SHIFT = (0.03, -0.04, 0.05)


def _true_waypoints(sim) -> tuple[np.ndarray, np.ndarray]:
    """Median over repetitions of the true displacement from the reach's start to the end of reach (bottle) and
    of lift (mouth), m, world frame."""
    t = sim.truth.t_ns
    ph = sim.truth.phases

    def at(t_ns: int) -> np.ndarray:
        return np.array([np.interp(t_ns, t, sim.truth.position[:, j]) for j in range(3)])

    bottles, mouths = [], []
    for rep in sorted(set(ph.task_index.tolist())):
        idx = {lab: i for i, (lab, k) in enumerate(zip(ph.labels, ph.task_index, strict=True)) if k == rep}
        start = at(ph.start_ns[idx["reach"]])
        bottles.append(at(ph.end_ns[idx["reach"]]) - start)
        mouths.append(at(ph.end_ns[idx["lift"]]) - start)
    return np.median(bottles, axis=0), np.median(mouths, axis=0)


def test_h1_h2_h3_are_the_bottle_and_mouth_displacements_with_their_signs():
    """h1 = +x to the bottle (forward), h2 = +y (towards the midline, the subject's left for the right hand),
    h3 = +z up to the mouth; moving the bottle and the mouth moves the recorded measurements and the waypoints
    by exactly that much."""
    base = simulate("r2g", subject=3, seed=4, repetitions=4, noise_free=True)
    moved = simulate(
        "r2g",
        subject=3,
        seed=4,
        repetitions=4,
        noise_free=True,
        bottle_offset_m=BOTTLE_SHIFT,
        mouth_offset_m=MOUTH_SHIFT,
    )
    for sim in (base, moved):
        anth = sim.recording.metadata["imulog.anthropometrics"]
        bottle, mouth = _true_waypoints(sim)
        assert anth["h1_m"] > 0.1 and anth["h2_m"] > 0.05 and anth["h3_m"] > 0.2  # forward, left, up
        assert bottle[0] == pytest.approx(anth["h1_m"], abs=0.015)
        assert mouth[1] == pytest.approx(anth["h2_m"], abs=0.015)
        assert mouth[2] == pytest.approx(anth["h3_m"], abs=0.015)
        assert mouth[0] == pytest.approx(anth["mouth_dx_m"], abs=0.015)
        # the waypoints the optimisation uses: measured coordinates from the record, the rest from a trajectory
        # (here the truth itself, so only the anthropometric coordinates are under test)
        t, rel, _, reps = true_repetitions(sim)
        wp = trial_waypoints(anth, t, rel, reps)
        assert np.allclose(wp.bottle_m[:2], bottle[:2], atol=0.015)
        assert np.allclose(wp.mouth_m, mouth, atol=0.015)
    a0 = base.recording.metadata["imulog.anthropometrics"]
    a1 = moved.recording.metadata["imulog.anthropometrics"]
    assert a1["h1_m"] - a0["h1_m"] == pytest.approx(BOTTLE_SHIFT[0], abs=1e-6)
    assert a1["bottle_dy_m"] - a0["h2_m"] == pytest.approx(BOTTLE_SHIFT[1], abs=1e-6)
    assert a1["h2_m"] - a0["h2_m"] == pytest.approx(MOUTH_SHIFT[1], abs=1e-6)
    assert a1["h3_m"] - a0["h3_m"] == pytest.approx(MOUTH_SHIFT[2], abs=1e-6)
    w0 = r2g_waypoints_from_anthropometrics(a0)
    assert w0.bottle_m[1] == pytest.approx(a0["h2_m"])  # without bottle_dy_m the bottle is in front of the shoulder


def test_optimisation_follows_the_moved_bottle_and_needs_the_right_measurements():
    from trajectory_accuracy import evaluate_trial, simulated_inputs

    inputs = simulated_inputs(3, seed=4, repetitions=4, bottle_offset_m=BOTTLE_SHIFT, mouth_offset_m=MOUTH_SHIFT)
    right, _, _ = evaluate_trial(inputs, ["zupt", "optimized"])
    stale = dict(inputs, anthropometrics=simulate("r2g", subject=3, seed=4, repetitions=1).truth.anthropometrics)
    wrong, _, _ = evaluate_trial(stale, ["optimized"])

    def mae(records):
        return np.mean([[r[a]["mae_cm"] for a in "xyz"] for r in records], axis=0)

    ok, bad, zupt = mae(right["optimized"]), mae(wrong["optimized"]), mae(right["zupt"])
    assert np.all(ok <= 1.0) and np.all(ok <= zupt)
    assert bad[0] > ok[0] + 1.0 and bad[1] > ok[1] + 1.0  # the unmoved bottle's h1/h2 pull it the wrong way
