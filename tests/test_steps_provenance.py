"""Provenance of reprocessing steps: metadata a step reads is part of its inputs."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from imulog.archive import ArchiveError, TrialReader, append_derived, write_trial
from imulog.cli import cli
from imulog.model import ImuStream, Recording, SignalStream
from imulog.simulate import simulate
from imulog.steps.base import StepResult, run_step
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


# ---------------------------------------------------------------------------------------------- races and staleness


def _small_trial(path: Path) -> Path:
    t = np.arange(2000, dtype=np.int64) * 10_000_000
    imu = ImuStream("wrist", t, acc=np.zeros((2000, 3)) + [0, 0, 9.81], gyr=np.zeros((2000, 3)))
    write_trial(path, Recording(imus=[imu]), attach_sources=False)
    append_derived(path, [], run={"step": "test-align"}, metadata={"imulog.alignment": {"offset_ns": 0}})
    return path


def _signal(trial: TrialReader, topic: str, source: str, value: float) -> StepResult:
    s = trial.read(source)
    return StepResult(streams=[SignalStream(topic, s.t_ns, ["v"], ["1"], np.full(len(s), value))])


def test_a_step_refuses_to_write_when_a_metadata_record_it_read_changed_meanwhile(tmp_path: Path) -> None:
    trial = _small_trial(tmp_path / "t.mcap")

    def compute(reader: TrialReader) -> StepResult:
        # another process re-aligns the trial while this step computes from the old alignment
        append_derived(trial, [], run={"step": "test-align"}, metadata={"imulog.alignment": {"offset_ns": 5}})
        return _signal(reader, "/derived/a", "/imu/wrist", 1.0)

    before = trial.read_bytes()
    with pytest.raises(ArchiveError, match="metadata record imulog.alignment changed while the step ran"):
        run_step(
            trial,
            step="a",
            algorithm="x",
            params={},
            inputs=["/imu/wrist"],
            compute=compute,
            metadata_inputs=["imulog.alignment"],
        )
    with TrialReader(trial) as reader:
        assert "/derived/a" not in reader.topics() and reader.metadata["imulog.alignment"] == {"offset_ns": 5}
    assert trial.read_bytes() != before  # (the re-alignment itself was written)


def _race(path: str, barrier, results, marker: str) -> None:
    def compute(reader: TrialReader) -> StepResult:
        with open(marker, "a") as f:
            f.write(f"{os.getpid()}\n")
        time.sleep(0.8)  # long enough for the other process to arrive while this one computes
        return _signal(reader, "/derived/a", "/imu/wrist", 1.0)

    barrier.wait()
    out = run_step(path, step="a", algorithm="x", params={}, inputs=["/imu/wrist"], compute=compute)
    results.put(out.skipped)


def test_two_processes_running_the_same_step_compute_it_once(tmp_path: Path) -> None:
    trial = _small_trial(tmp_path / "t.mcap")
    marker = tmp_path / "computed.txt"
    ctx = mp.get_context("fork")
    barrier, results = ctx.Barrier(2), ctx.Queue()
    procs = [ctx.Process(target=_race, args=(str(trial), barrier, results, str(marker))) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
        assert p.exitcode == 0
    assert sorted(results.get(timeout=5) for _ in procs) == [False, True]  # one computed, one found it done
    assert len(marker.read_text().split()) == 1
    with TrialReader(trial) as reader:
        assert [r["step"] for r in reader.runs().values()].count("a") == 1


def test_info_marks_out_of_date_channels_and_the_step_to_rerun(tmp_path: Path) -> None:
    trial = _small_trial(tmp_path / "t.mcap")

    def step_a(value: float) -> None:
        run_step(
            trial,
            step="phases",
            algorithm="x",
            params={},
            inputs=["/imu/wrist"],
            compute=lambda r: _signal(r, "/derived/a", "/imu/wrist", value),
            metadata_inputs=["imulog.alignment"],
        )

    def step_b(value: float) -> None:
        run_step(
            trial,
            step="orientation:wrist",
            algorithm="x",
            params={"v": value},
            inputs=["/derived/a"],
            compute=lambda r: _signal(r, "/derived/b", "/derived/a", value),
        )

    def stale() -> dict:
        res = CliRunner().invoke(cli, ["info", "--json", str(trial)])
        assert res.exit_code == 0, res.output
        return {c["topic"]: c["out_of_date"] for c in json.loads(res.output)["channels"] if c["out_of_date"]}

    step_a(1.0)
    step_b(1.0)
    assert stale() == {}
    append_derived(trial, [], run={"step": "test-align"}, metadata={"imulog.alignment": {"offset_ns": 7}})
    now = stale()
    assert now["/derived/a"]["reasons"] == ["metadata record imulog.alignment changed"]
    assert now["/derived/a"]["rerun"] == "imulog process phases"
    assert now["/derived/b"]["reasons"] == ["input /derived/a is out of date"]  # transitively
    assert now["/derived/b"]["rerun"] == "imulog process orientation"
    text = CliRunner().invoke(cli, ["info", str(trial)]).output
    assert "/derived/a [out of date]" in text and "-> rerun imulog process phases" in text
    step_a(1.0)  # recomputed with the same content: /derived/b's recorded input hash still holds
    assert stale() == {}
    append_derived(trial, [], run={"step": "test-align"}, metadata={"imulog.alignment": {"offset_ns": 9}})
    step_a(2.0)  # new content: /derived/b was computed from the old one
    assert set(stale()) == {"/derived/b"} and stale()["/derived/b"]["reasons"] == ["input /derived/a changed"]
    step_b(1.0)
    assert stale() == {}
    # a step that writes only a metadata record is tracked by its run record
    run_step(
        trial,
        step="evaluate",
        algorithm="x",
        params={},
        inputs=["/derived/b"],
        compute=lambda r: StepResult(metadata={"imulog.evaluation": {"n": 1}}),
        metadata_inputs=["imulog.alignment"],
    )
    steps = json.loads(CliRunner().invoke(cli, ["info", "--json", str(trial)]).output)["out_of_date_steps"]
    assert steps == {}
    append_derived(trial, [], run={"step": "test-align"}, metadata={"imulog.alignment": {"offset_ns": 11}})
    steps = json.loads(CliRunner().invoke(cli, ["info", "--json", str(trial)]).output)["out_of_date_steps"]
    assert steps["evaluate"]["reasons"][0] == "metadata record imulog.alignment changed"
    assert steps["evaluate"]["rerun"] == "imulog evaluate" and set(steps) == {"evaluate", "phases", "orientation:wrist"}
    assert "step evaluate (run #" in CliRunner().invoke(cli, ["info", str(trial)]).output
