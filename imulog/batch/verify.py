"""Checks over an archive after a batch: file integrity and the content of derived results.

from imulog.batch.verify import check_archive, derived_digests
bad = check_archive(paths)          # {path: [problems]} for files that fail `imulog doctor`
derived_digests("trial.mcap")       # {topic or record: sha256} of derived channels and result records
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable
from typing import Any

RESULT_RECORDS = (
    "imulog.alignment",
    "imulog.timing",
    "imulog.trajectory",
    "imulog.evaluation",
    "imulog.orientation_evaluation",
    "imulog.metrics",
)


def check_archive(paths: Iterable[str | os.PathLike[str]]) -> dict[str, list[str]]:
    """Run the archive doctor on every file (one at a time); return the problems of the files that fail."""
    from imulog.archive.doctor import check_file

    bad = {}
    for p in paths:
        report = check_file(p)
        if not report.ok:
            bad[str(p)] = list(report.problems)
    return bad


def derived_digests(path: str | os.PathLike[str], records: tuple[str, ...] = RESULT_RECORDS) -> dict[str, str]:
    """Content hashes of every ``/derived/...`` channel and of the result metadata ``records``.

    Two runs of the same steps on the same raw data agree exactly when these dicts are equal (run numbers,
    times and versions are not part of them).
    """
    from imulog.archive import TrialReader

    out: dict[str, str] = {}
    with TrialReader(path) as trial:
        for c in trial.channels:
            if c.derived:
                out[c.topic] = trial.compute_channel_hash(c.topic)
        meta = trial.metadata
        for name in records:
            if name in meta:
                out[name] = _digest(meta[name])
    return out


def _digest(value: Any) -> str:
    text = json.dumps(value, sort_keys=True, separators=(",", ":"), default=str, allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()
