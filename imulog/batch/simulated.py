"""A simulated archive for tests, benchmarks and demos: ``subjects x trials`` R2G trials as MCAP files.

    paths = simulate_archive("archive/", subjects=11, trials=3, repetitions=25)   # the thesis's 825 movements

Files are ``{out}/S{subject:02d}/S{subject:02d}_T{trial}.mcap`` written with :func:`imulog.archive.write_trial`
from :func:`imulog.simulate.simulate` (no source attachments), one at a time (memory stays flat).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any


def simulate_archive(
    out_dir: str | os.PathLike[str],
    *,
    subjects: int = 2,
    trials: int = 1,
    repetitions: int = 3,
    protocol: str = "r2g",
    seed: int = 0,
    overwrite: bool = False,
    **overrides: Any,
) -> list[Path]:
    """Simulate and write the archive; return the trial paths (existing files are kept unless ``overwrite``)."""
    from imulog.archive import write_trial
    from imulog.simulate import simulate

    out = Path(out_dir)
    paths = []
    for s in range(1, subjects + 1):
        for k in range(1, trials + 1):
            path = out / f"S{s:02d}" / f"S{s:02d}_T{k}.mcap"
            if overwrite or not path.exists():
                kw = dict(overrides)
                if protocol == "r2g":
                    kw.setdefault("repetitions", repetitions)
                sim = simulate(protocol, subject=s, trial=k, seed=seed, **kw)
                write_trial(path, sim.recording, attach_sources=False, overwrite=overwrite)
                del sim
            paths.append(path)
    return paths
