"""The four unused candidates of the repetition flags' ``drift`` reason (``start_zupt_cm``, ``zupt_reference_cm``,
``anchored_reference_cm``, ``closure_mps``: docs/accuracy.md, "a drift feature for the robust bias fit") are computed
only when asked (``benchmarks/confidence_calibration.py``), not on every trajectory run; asking for them changes no
trajectory, no other feature and no flag."""

from __future__ import annotations

import shutil

import numpy as np

from imulog.archive import TrialReader
from imulog.process import repetition_flags, trajectory_opt
from imulog.process.repetition_flags import flagged_repetitions, repetition_features

CANDIDATES = {"start_zupt_cm", "zupt_reference_cm", "anchored_reference_cm", "closure_mps"}


def test_the_step_computes_no_candidate_and_asking_changes_nothing_else(processed_r2g, tmp_path, monkeypatch):
    """The trajectory step on the simulated R2G trial: its record holds no candidate and its flags are the ones the
    features give with the candidates computed too; the reconstruction with the candidates is the same."""
    from imulog.steps import trajectory as step

    seen: list[tuple[tuple, dict, dict, dict]] = []
    real = trajectory_opt.reconstruct_repetitions

    def spy(*args, **kwargs):
        out = real(*args, **kwargs)  # what the step computes (its info is the record's)
        info: dict = {}
        asked = real(*args, **{**kwargs, "info": info, "drift_candidates": True})
        seen.append((args, kwargs, out, {"info": info, "recon": asked}))
        return out

    monkeypatch.setattr(step, "reconstruct_repetitions", spy)
    trial = tmp_path / "trial.mcap"
    shutil.copy(processed_r2g, trial)
    step.run_trajectory(trial)
    with TrialReader(trial) as t:
        record = t.metadata["imulog.trajectory"]
    assert not CANDIDATES & set(record), sorted(CANDIDATES & set(record))

    (args, kwargs, recon, asked) = seen[0]
    assert asked["recon"].keys() == recon.keys()
    for m in recon:
        np.testing.assert_array_equal(asked["recon"][m], recon[m], err_msg=m)
    step_info, cand_info = kwargs["info"], asked["info"]
    assert "closure_mps" not in step_info and len(cand_info["closure_mps"]) == len(args[3])
    assert {k: v for k, v in cand_info.items() if k != "closure_mps"}.keys() <= step_info.keys()

    t_s, acc, static, reps = args[:4]
    plain = repetition_features(t_s, acc, static, reps, recon, (), trajectory_info=step_info)
    full = repetition_features(t_s, acc, static, reps, recon, (), trajectory_info=cand_info, candidates=True)
    assert plain.keys() == full.keys() and plain
    found = set().union(*(set(f) for f in full.values()))
    assert {"start_zupt_cm", "zupt_reference_cm", "closure_mps"} <= found, found
    assert not CANDIDATES & set().union(*(set(f) for f in plain.values()))
    for k in plain:  # every other feature the same, hence the same flags
        assert {n: v for n, v in full[k].items() if n not in CANDIDATES} == plain[k], k
    assert flagged_repetitions(full) == flagged_repetitions(plain)


def test_candidates_of_a_built_repetition_only_when_asked():
    """The reference distance is computed either way; the three reference-based candidates and ``closure_mps``
    (from the trajectory info) only with ``candidates``."""
    from types import SimpleNamespace

    from test_repetition_flags import built_r2g

    t, bounds, wp, ref, static = built_r2g()
    start = ref + np.where(t >= bounds[0, 0], 1.0, 0.0)[:, None] * [0.0, 0.04, 0.01]  # 4 cm off in y
    zupt = ref + np.where(t >= bounds[0, 0], 1.0, 0.0)[:, None] * [0.01, 0.0, 0.0]  # 1 cm off in x
    rep = SimpleNamespace(index=1, start=0, stop=len(t), phase_bounds_s=bounds)
    info = {"waypoints_m": {"bottle": list(wp.bottle_m), "mouth": list(wp.mouth_m)}, "closure_mps": [0.07]}
    acc = np.zeros((len(t), 3))
    trajectories = {"zupt": zupt, "zupt_bias": start}
    (plain,) = repetition_features(t, acc, static, [rep], trajectories, (), info).values()
    (full,) = repetition_features(t, acc, static, [rep], trajectories, (), info, candidates=True).values()
    assert plain["reference_cm"] == full["reference_cm"] > 3.0
    assert not CANDIDATES & set(plain)
    assert set(full) >= CANDIDATES
    assert full["closure_mps"] == 0.07
    assert abs(full["zupt_reference_cm"] - 1.0) < 0.05  # ZUPT's own 1 cm in x at the rests
    assert full["start_zupt_cm"] > 3.0  # the two estimates disagree by 4 cm in y
    assert repetition_flags.flag_repetition(plain) == repetition_flags.flag_repetition(full) == ["drift"]
