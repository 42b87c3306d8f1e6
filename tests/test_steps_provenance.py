"""Provenance of reprocessing steps: metadata a step reads is part of its inputs."""

from __future__ import annotations

from pathlib import Path

from imulog.archive import TrialReader, append_derived, write_trial
from imulog.simulate import simulate
from imulog.steps.phases import run_phases


def test_changing_the_alignment_makes_phases_out_of_date(tmp_path: Path) -> None:
    sim = simulate("r2g", seed=4, repetitions=2, opening_static_s=5.0)
    trial = write_trial(tmp_path / "t.mcap", sim.recording, attach_sources=False)
    append_derived(
        trial, [], run={"step": "test-align", "algorithm": "truth"}, metadata={"imulog.alignment": sim.truth.alignment}
    )

    first = run_phases(trial)
    assert not first.skipped and first.input_hashes.keys() >= {"/imu/wrist", "metadata:imulog.alignment"}
    assert run_phases(trial).skipped  # same inputs: nothing to do

    shifted = {**sim.truth.alignment, "offset_ns": int(sim.truth.alignment["offset_ns"]) + 250_000_000}
    append_derived(trial, [], run={"step": "test-align", "algorithm": "truth"}, metadata={"imulog.alignment": shifted})
    again = run_phases(trial)
    assert not again.skipped  # the phase times depend on the alignment: recomputed
    with TrialReader(trial) as reader:
        phases = reader.read("/derived/phases/wrist")
        run = reader.runs()[again.run]
    assert run["inputs"]["metadata:imulog.alignment"] != first.input_hashes["metadata:imulog.alignment"]
    # the phases moved with the clock by the 250 ms of the new offset
    assert abs((phases.start_ns[0] - sim.truth.phases.start_ns[0]) - 250_000_000) < 0.1e9
