"""Write a simulated trial as raw export files plus ground truth; simulate whole folders."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from imulog.simulate import writers
from imulog.simulate.core import SimulatedTrial, simulate
from imulog.simulate.truth import save_truth


def write_trial_files(
    sim: SimulatedTrial, out_dir: Path | str, stem: str | None = None, *, compact_truth: bool = False
) -> dict[str, Path]:
    """Write ``<stem>_imu.csv`` + ``<stem>_imu.mapping.json``, ``<stem>_vicon.csv``, ``<stem>_meta.json``
    (the ``imulog.trial`` and ``imulog.anthropometrics`` records for ``imulog convert --meta-file``), ``<stem>_truth.npz`` + ``<stem>_truth.json`` and,
    for ``adl``, ``<stem>_adc.txt``. Returns the paths by kind; sets ``sim.recording.sources``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = stem or sim.stem
    raw = sim.raw
    paths: dict[str, Path] = {}
    paths["imu"], paths["mapping"] = writers.write_imu_text(
        out / f"{stem}_imu.csv", raw["imu_t_dev_ns"], raw["imu_channels"], raw["device"]
    )
    vicon = sim.recording.markers[0]
    paths["vicon"] = writers.write_nexus_csv(
        out / f"{stem}_vicon.csv",
        vicon.pos,
        [lab.rsplit(":", 1)[-1] for lab in vicon.labels],
        float(vicon.meta["rate_hz"]),
        raw["vicon_subject"],
        raw["vicon_decimals"],
    )
    if sim.adc is not None:
        paths["adc"] = writers.write_adc_text(out / f"{stem}_adc.txt", sim.adc["counts"])
        # what the lab knows about its board: the sampling rate (the file has no time stamps) and the
        # nominal calibration (the true per-axis zero levels and sensitivities stay in the truth)
        paths["adc_mapping"] = out / f"{stem}_adc.mapping.json"
        sidecar = {"format": "imulog.mapping/1", "device": {"name": "acc", "rate_hz": float(sim.adc["rate_hz"])}}
        paths["adc_mapping"].write_text(json.dumps(sidecar, indent=1) + "\n")
    meta = out / f"{stem}_meta.json"
    records = {k: v for k, v in sim.recording.metadata.items() if k in ("imulog.trial", "imulog.anthropometrics")}
    meta.write_text(json.dumps(records, indent=1) + "\n")
    paths["meta"] = meta
    paths["truth_npz"], paths["truth"] = save_truth(sim.truth, out / stem, compact=compact_truth)
    sim.recording.sources = [str(paths[k]) for k in ("imu", "mapping", "vicon", "adc", "adc_mapping") if k in paths]
    return paths


def simulate_to_folder(
    protocol: str,
    out_dir: Path | str,
    subjects: int = 1,
    trials: int = 1,
    seed: int = 0,
    progress: Callable[[int, int, str], Any] | None = None,
    **overrides: Any,
) -> list[dict[str, Path]]:
    """Simulate ``subjects`` x ``trials`` trials and write each with :func:`write_trial_files`.

    ``progress(done, total, stem)`` is called after every trial (e.g. to advance a progress bar).
    Returns one dict of written paths per trial, in (subject, trial) order.
    """
    written = []
    total = subjects * trials
    for s in range(subjects):
        for t in range(trials):
            sim = simulate(protocol, subject=s, trial=t, seed=seed, **overrides)
            written.append(write_trial_files(sim, out_dir))
            if progress is not None:
                progress(len(written), total, sim.stem)
    return written
