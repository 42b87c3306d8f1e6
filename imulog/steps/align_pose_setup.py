"""Step ``align`` on several rigid bodies: every IMU of the trial against the pose channels (``/poses/*``), paired
one to one by the data, whatever the names.

The pairing (:func:`imulog.steps.align_pose_search.search_pose_setup`) ranks the bodies of each IMU by a cheap
coarse score (the angular-velocity norms' correlation) and runs the full alignment
(:func:`imulog.steps.align_pose.align_on_body`: the clock fit over windows, the IMU-to-body rotation) for each IMU's
best ``params.search.refine`` bodies only (every body for an IMU left without one); IMUs and bodies are then paired
by the assignment that maximises the summed vector match (:func:`imulog.process.alignment_setup.pair_one_to_one`,
pairs under ``params.search.min_vector_match`` not made), so two IMUs never share a body. Each paired IMU keeps the
alignment on its body (its own clock: the windows of one body), written by the per-IMU rule of every alignment path
(:func:`imulog.steps.common.alignment_writes`): ``imulog.alignment.{imu}``, ``/derived/vicon/cluster_pose/{imu}``...;
an IMU no body turns like gets no record, and the step says why. Cost: one coarse score per IMU and body, one full
alignment per IMU and each of its ``refine`` best bodies.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from imulog.process import alignment as al
from imulog.steps.align import STEP, imu_span, params_dict, read_derived_pair
from imulog.steps.align_pose import PoseBody, pose_body, pose_channels, pose_streams
from imulog.steps.align_pose_search import ImuInput, search_pose_setup
from imulog.steps.common import names_trial

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome


def recording_clocks(
    names: list[str],
    pairs: dict[str, str],
    records: dict[str, dict],
    why: dict[str, str],
    device_meta: dict[str, dict],
    times: dict[str, np.ndarray | tuple[int, int, int]],
    params: al.AlignmentParams,
) -> dict[str, dict]:
    """IMU -> record for each IMU no body turns like (``why``) whose recording shares one clock with IMUs paired
    with a body (:func:`imulog.process.alignment_setup.recording_groups`: the same ``recording``/``master`` or
    ``source`` in their device records, or identical time stamps ``times``: each whole channel's, or its (count,
    first ns, last ns)): the clock pooled over those IMUs' windows,
    as the marker setup gives an IMU without a cluster (:func:`imulog.steps.recording_clock.recording_clock_record`).
    An IMU of a recording without a paired IMU gets nothing (no clock is guessed)."""
    from imulog.process.alignment_setup import pooled_clock, recording_groups
    from imulog.steps.recording_clock import recording_clock_record

    out: dict[str, dict] = {}
    for group in recording_groups(names, device_meta, times):
        paired = [n for n in group if n in pairs]
        lone = [n for n in group if n not in pairs]
        if not paired or not lone:
            continue
        try:
            clock = pooled_clock([{**records[p], "imu": p} for p in paired], params)
        except ValueError:  # no usable window in the paired IMUs' records: their clocks stay their own
            continue
        for n in lone:
            base = {"reference": None, "imu": f"/imu/{n}", "clock_group": list(group)}
            out[n] = recording_clock_record(base, clock, paired, f"no rigid body turns like this IMU ({why[n]})")
    return out


@names_trial
def run_align_pose_setup(
    path: str | os.PathLike[str],
    *,
    imus: list[str] | None = None,
    params: al.AlignmentParams | None = None,
    resample: bool = True,
    force: bool = False,
) -> StepOutcome:
    """Align every IMU of the trial (or those named) with the trial's rigid bodies, paired one to one; returns the
    :func:`imulog.steps.base.run_step` outcome. The pairs and the IMUs left without a body are in the main record's
    ``setup`` and ``unpaired``."""
    from imulog.archive import TrialReader
    from imulog.steps.align_summary import setup_summary
    from imulog.steps.base import StepResult, run_step
    from imulog.steps.common import alignment_writes, imu_names, renamed

    params = params or al.AlignmentParams()
    with TrialReader(path) as trial:
        topics = trial.topics()
    all_imus = imu_names(topics)
    names = list(imus) if imus else all_imus
    missing = [n for n in names if n not in all_imus]
    if missing:
        raise ValueError(f"no channel /imu/{missing[0]} in the trial (IMUs: {', '.join(all_imus) or 'none'})")
    bodies = pose_channels(topics)
    if not bodies:
        raise ValueError("no /poses/* channel in the trial")
    inputs = [f"/imu/{n}" for n in names] + bodies
    inputs += [
        f"/derived/{k}/{n}" for n in names for k in ("orientation", "acc_global") if f"/derived/{k}/{n}" in topics
    ]

    def compute(trial) -> StepResult:
        found: dict[str, PoseBody | str] = {}
        for b in bodies:
            pose = trial.read(b)
            try:
                found[b] = pose_body(b, pose.t_ns, pose.position, pose.orientation, params)
            except ValueError as exc:
                found[b] = str(exc)
        data: dict[str, ImuInput] = {}
        for n in names:
            lo, hi = imu_span(trial, f"/imu/{n}", bodies[0], params.max_lag_s)
            s = trial.read(f"/imu/{n}", lo, hi)
            derived = [t for t in (f"/derived/orientation/{n}", f"/derived/acc_global/{n}") if t in inputs]
            data[n] = ImuInput(s.t_ns, s.gyr, *read_derived_pair(trial, derived, lo, hi))
        from imulog.steps.recording_clock import channel_span

        times = {n: channel_span(trial, f"/imu/{n}") for n in names}
        pairs, why, search = search_pose_setup(data, found, params)
        candidates = search.candidates
        if not pairs:
            raise ValueError(
                "no IMU turns like any rigid body (" + "; ".join(f"{n}: {w}" for n, w in why.items()) + ")"
            )
        records = {n: candidates[n][b] for n, b in pairs.items()}
        device_meta = {n: dict(trial.metadata.get(f"imulog.device.{n}") or {}) for n in names}
        records.update(recording_clocks(names, pairs, records, why, device_meta, times, params))
        streams: list = []
        metadata: dict = {}
        for n in names:
            if n in pairs:
                written, suffix = alignment_writes(topics, trial.metadata, n, records[n])
                d = data[n]
                made = pose_streams(
                    n, found[pairs[n]], records[n], d.t_ns, d.gyr, d.orientation, d.acc_global, resample
                )
                streams += renamed(made, suffix)
                metadata.update({k: v for k, v in written.items() if k != "imulog.alignment"})
            elif n in records:  # no body, but the clock of its recording's aligned IMUs: named as such
                metadata[f"imulog.alignment.{n}"] = records[n]
            else:  # no body: a record without a clock replaces any older one, so no stale alignment stays
                metadata[f"imulog.alignment.{n}"] = {
                    "imu": f"/imu/{n}",
                    "quality": "failed",
                    "quality_reasons": [why[n]],
                }
        primary = next(n for n in names if n in pairs)
        owner = str((trial.metadata.get("imulog.alignment") or {}).get("imu") or "").removeprefix("/imu/")
        if owner in ("", *pairs) or owner not in all_imus:  # the main record: kept when another IMU owns it
            main = records[owner] if owner in pairs else records[primary]
            metadata["imulog.alignment"] = {
                **main,
                "setup": setup_summary(records),
                "unpaired": why,
                "search": search.summary(),
            }
        return StepResult(streams=streams, metadata=metadata)

    return run_step(
        path,
        step=STEP,
        algorithm="imulog.alignment.xcorr_wahba.pose_setup",
        params={"imus": names, "poses": bodies, "resample": resample, **params_dict(params)},
        inputs=inputs,
        compute=compute,
        force=force,
    )
