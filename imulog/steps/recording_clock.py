"""The clock an IMU takes from its recording when nothing optical turns like it: one record for the marker setup
(:mod:`imulog.steps.align_setup`) and the rigid-body setup (:mod:`imulog.steps.align_pose_setup`), and what tells
which IMUs share a recording's time stamps (:func:`channel_span`)."""

from __future__ import annotations

CLOCK_KEYS = (
    "offset_ns",
    "drift_ppm",
    "t0_ns",
    "offset_uncertainty_ns",
    "drift_uncertainty_ppm",
    "drift_estimated",
    "drift_note",
    "residual_spread_ns",
    "score",
)


def recording_clock_record(base: dict, clock: dict, paired: list[str], why: str) -> dict:
    """The alignment record of an IMU that nothing optical turns like (``why``), in a recording whose IMUs ``paired``
    are aligned: their pooled ``clock`` (:func:`imulog.process.alignment_setup.pooled_clock`; offset ns, drift ppm),
    no frame alignment, graded poor, and named as such (``signal`` ``clock of the recording``, ``clock`` ``shared``,
    ``clock_of`` the IMUs whose windows made it, ``method``): never an alignment of its own."""
    return {
        **base,
        **{k: clock[k] for k in CLOCK_KEYS if k in clock},
        "signal": "clock of the recording",
        "clock": "shared",
        "clock_of": list(paired),
        "frame_alignment": False,
        "rotation_imu_to_cluster": None,
        "rotation_global_to_world": None,
        "cluster": None,
        "windows": [],
        "method": f"clock shared with {', '.join(paired)}",
        "quality": "poor",
        "quality_reasons": [f"{why}: its clock is its recording's ({', '.join(paired)}), no frame alignment"],
    }


def channel_span(trial, topic: str) -> tuple[int, int, int]:
    """(sample count, first ns, last ns) of a whole channel from the archive's summary (no data read): what
    :func:`imulog.process.alignment_setup.recording_groups` compares, not the stretch read around the optical data."""
    c = trial.channel(topic)
    return int(c.sample_count), int(c.start_ns or 0), int(c.end_ns or 0)
