"""Issue 19, part 4: what event correction did to each repetition (merged, dropped, split), a confidence, and the
forced phases shown as forced in ``imulog.timing``, ``imulog info``, the catalog, the viewer and ``evaluate``."""

from __future__ import annotations

import numpy as np
import pytest

from imulog.process.segmentation.repetitions import RepetitionParams, segment_repetitions

RATE = 100.0


def _bump(norm: np.ndarray, a: int, b: int, height: float) -> None:
    tau = np.linspace(0, 1, b - a)
    norm[a:b] = np.maximum(norm[a:b], height * 16 * tau**2 * (1 - tau) ** 2)


def _trial():
    """6 repetitions of 4 movements (1 s, gaps 1 s, rests 6 s); repetition 3 has phases 2+3 fused into one
    movement (a dip of the norm between them), repetition 5 an extra movement in the gap after its second phase,
    repetition 6 a corrective sub-movement 0.3 s after its first phase."""
    norm = np.full(int(120 * RATE), 0.01)
    starts, ends = [], []
    t = 2.0
    for rep in range(1, 7):
        rep_moves = []
        for k in range(4):
            a = int((t + 2.0 * k) * RATE)
            rep_moves.append((a, a + int(RATE)))
            _bump(norm, a, a + int(RATE), [1.0, 1.5, 1.4, 1.2][k])
        if rep == 3:  # fused: one detected movement from the start of phase 2 to the end of phase 3
            (a2, _), (_, b3) = rep_moves[1], rep_moves[2]
            norm[a2 + int(RATE) : a2 + int(2 * RATE)] = 0.3
            rep_moves = [rep_moves[0], (a2, b3), rep_moves[3]]
        if rep == 5:  # an extra movement between phases 2 and 3
            a = int((t + 3.3) * RATE)
            _bump(norm, a, a + 40, 0.9)
            rep_moves.insert(2, (a, a + 40))
        if rep == 6:  # a corrective sub-movement right after the reach
            a = rep_moves[0][1] + 30
            _bump(norm, a, a + 40, 0.3)
            rep_moves.insert(1, (a, a + 40))
        for a, b in rep_moves:
            starts.append(a)
            ends.append(b)
        t += 2.0 * 4 + 6.0
    return np.array(starts), np.array(ends), norm


def test_event_correction_reports_what_it_did_per_repetition():
    s, e, norm = _trial()
    params = RepetitionParams(n_repetitions=6, burst_min_movements=0, min_height_fraction=0.0)
    ph = segment_repetitions(s, e, norm, RATE, params)
    assert len(ph) == 24 and len(ph.quality) == 6
    q = {r["repetition"]: r for r in ph.quality}
    for rep in (1, 2, 4):  # untouched repetitions: nothing changed, full confidence
        assert (q[rep]["merged"], q[rep]["dropped"], q[rep]["split"], q[rep]["forced"]) == (0, 0, 0, 0)
        assert q[rep]["confidence"] > 0.9
    assert q[3]["movements"] == 3 and q[3]["split"] == 1 and q[3]["forced"] == 2  # lift and return_bottle invented
    assert q[3]["confidence"] <= 0.5
    for rep in (5, 6):  # an extra movement within 1 s of a phase is absorbed into it
        assert q[rep]["movements"] == 5 and q[rep]["merged"] == 1 and q[rep]["dropped"] == 0
        assert q[3]["confidence"] < q[rep]["confidence"] < 1.0
    forced = ph.forced.reshape(6, 4)
    assert forced[2].tolist() == [False, True, True, False] and forced.sum() == 2
    # without absorption (the thesis's event correction) the extras are dropped instead
    strict = segment_repetitions(s, e, norm, RATE, RepetitionParams(**{**params.__dict__, "continuation_gap_s": 0.0}))
    q = {r["repetition"]: r for r in strict.quality}
    assert [(q[r]["merged"], q[r]["dropped"]) for r in (5, 6)] == [(0, 1), (0, 1)]
    assert q[5]["confidence"] < 1.0 and q[3]["confidence"] < q[5]["confidence"]


@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    """A simulated 5-repetition trial with corrective sub-movements through orientation, align, phases,
    trajectory and evaluate (the CLI's own steps)."""
    from imulog.archive import write_trial
    from imulog.simulate import simulate
    from imulog.steps.align import run_align
    from imulog.steps.evaluate import run_evaluate
    from imulog.steps.orientation import run_orientation
    from imulog.steps.phases import run_phases
    from imulog.steps.trajectory import run_trajectory

    path = tmp_path_factory.mktemp("quality") / "trial.mcap"
    sim = simulate("r2g", subject=2, seed=5, repetitions=5, extra_submovement_probability=0.5)
    write_trial(path, sim.recording)
    run_orientation(path)
    run_align(path)
    run_phases(path)
    run_trajectory(path)
    _, record = run_evaluate(path)
    return path, record


def test_quality_is_stored_and_shown_in_info_catalog_and_evaluate(processed):
    from click.testing import CliRunner

    from imulog.archive import TrialReader
    from imulog.batch.catalog import trial_row
    from imulog.cli import cli as main

    path, record = processed
    with TrialReader(path) as trial:
        timing = trial.metadata["imulog.timing"]
    quality = timing["repetition_quality"]
    assert [q["repetition"] for q in quality] == [1, 2, 3, 4, 5]
    assert sum(q["merged"] for q in quality) >= 1  # p = 0.5 sub-movements: event correction absorbed some
    assert all(0.0 <= q["confidence"] <= 1.0 for q in quality)
    assert timing["low_confidence_repetitions"] == [q["repetition"] for q in quality if q["confidence"] < 0.5]
    assert all("forced" in row and "confidence" in row for row in timing["phases"])

    from imulog.commands.phases import format_summary

    summary = format_summary(timing)
    assert f"{timing['n_forced_phases']} forced phases" in summary and str(timing["mean_confidence"]) in summary

    info = CliRunner().invoke(main, ["info", str(path)])
    assert info.exit_code == 0, info.output
    merged = sum(q["merged"] for q in quality)
    assert f"merged {merged}" in info.output and "forced phases" in info.output

    row = trial_row(str(path))
    assert row["n_forced_phases"] == timing["n_forced_phases"]
    assert row["phases_confidence"] == pytest.approx(timing["mean_confidence"])

    out = CliRunner().invoke(main, ["evaluate", str(path), "--json"])
    assert out.exit_code == 0, out.output
    import json

    data = json.loads(out.output)
    assert data["phase_quality"]["low_confidence_repetitions"] == timing["low_confidence_repetitions"]
    n = sum(g["n"] for g in data["phase_quality"]["methods"]["zupt"].values())
    assert n == len(record["methods"]["zupt"]["repetitions"])


def test_viewer_labels_forced_phases_and_low_confidence_repetitions():
    import rerun as rr

    from imulog.archive.clocks import ClockMap
    from imulog.view.streams import FORCED, LoggedTrial, _Logger

    timing = {
        "phases": [
            {"repetition": 1, "label": "reach", "forced": False},
            {"repetition": 1, "label": "lift", "forced": True},
        ],
        "repetition_quality": [{"repetition": 1, "confidence": 0.3}, {"repetition": 2, "confidence": 0.9}],
    }
    rec = rr.RecordingStream("imulog-test")
    logger = _Logger(rec, LoggedTrial(label="t", prefix=""), ClockMap({}, {}, set()), 0, None, None, timing)
    labs, rep = logger.phase_quality_labels(
        None,
        np.array(["reach", "lift", "reach"], dtype=object),
        np.array([1, 1, 2]),
        np.array(["rep 1", "rep 1", "rep 2"], dtype=object),
    )
    assert labs.tolist() == ["reach", "lift" + FORCED, "reach"]
    assert rep.tolist() == ["rep 1 (confidence 0.30)", "rep 1 (confidence 0.30)", "rep 2"]
