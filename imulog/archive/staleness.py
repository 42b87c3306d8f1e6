"""Which derived channels and steps are out of date against a trial's current inputs (from the summary and the
metadata records: no data read)."""

from __future__ import annotations

import json
from typing import Any

from imulog.archive import _mcap as m
from imulog.archive.metadata import record_hash


def stale_channels(channels: dict[int, m.ChannelRec], metadata: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Derived channels out of date against the trial's current inputs, by topic (no data read).

    A channel is stale when an input channel's recorded content hash or a metadata record it read
    (``metadata:NAME`` in its ``inputs``) differs from what its provenance recorded, when an input is
    gone, or when an input is itself stale. Values: ``{"step": ..., "reasons": [one line each]}``.
    """
    chans = {c.topic: c for c in channels.values()}
    stale: dict[str, dict[str, Any]] = {}
    deps: dict[str, list[str]] = {}
    for topic, c in chans.items():
        if not topic.startswith("/derived/") or "inputs" not in c.metadata:
            continue
        try:
            inputs = json.loads(c.metadata["inputs"])
        except ValueError:
            inputs = None
        reasons = _changed_inputs(inputs, chans, metadata)
        if isinstance(inputs, dict):
            deps[topic] = [k for k in inputs if k in chans]
        if reasons:
            stale[topic] = {"step": c.metadata.get("step", ""), "reasons": reasons}
    changed = True
    while changed:  # an input that is itself out of date makes its users out of date
        changed = False
        for topic, used in deps.items():
            if topic in stale:
                continue
            late = [t for t in used if t in stale]
            if late:
                step = chans[topic].metadata.get("step", "")
                stale[topic] = {"step": step, "reasons": [f"input {t} is out of date" for t in late]}
                changed = True
    return dict(sorted(stale.items()))


def stale_steps(
    channels: dict[int, m.ChannelRec], metadata: dict[str, Any], runs: dict[int, dict[str, Any]]
) -> dict[str, dict[str, Any]]:
    """Steps whose latest run is out of date (its recorded inputs changed, or an output is stale), by step.

    Covers steps that write only metadata records (``evaluate``: ``imulog.evaluation``) as well as
    channels. Values: ``{"run": n, "reasons": [...]}``. No data is read.
    """
    chans = {c.topic: c for c in channels.values()}
    stale_topics = stale_channels(channels, metadata)
    latest: dict[str, tuple[int, dict[str, Any]]] = {}
    for n, rec in runs.items():
        if rec.get("step"):
            latest[rec["step"]] = (n, rec)
    out = {}
    for step, (n, rec) in latest.items():
        reasons = _changed_inputs(rec.get("inputs", {}), chans, metadata)
        reasons += [f"input {t} is out of date" for t in rec.get("inputs", {}) if t in stale_topics]
        if reasons:
            out[step] = {"run": n, "reasons": reasons}
    return dict(sorted(out.items()))


def _changed_inputs(inputs: Any, chans: dict[str, m.ChannelRec], metadata: dict[str, Any]) -> list[str]:
    """Why recorded provenance ``inputs`` ({topic or metadata:NAME: hash}) no longer match the trial."""
    if not isinstance(inputs, dict):
        return ["unreadable inputs in its provenance"]
    reasons = []
    for key, digest in inputs.items():
        if key.startswith("metadata:"):
            name = key[len("metadata:") :]
            if record_hash(metadata.get(name)) != digest:
                reasons.append(f"metadata record {name} changed")
        elif key not in chans:
            reasons.append(f"input {key} is gone")
        else:
            recorded = chans[key].metadata.get("sha256")
            if recorded and recorded != digest:
                reasons.append(f"input {key} changed")
    return reasons
