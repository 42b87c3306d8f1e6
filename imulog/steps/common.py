"""Helpers every step shares: choosing the IMU a step works on, and the alignment record that concerns it."""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Mapping
from typing import Any, Concatenate, ParamSpec, TypeVar

import numpy as np


def pick_imu(topics: list[str], imu: str | None, *, prefix: str = "/imu/", missing_hint: str = "") -> str:
    """The IMU name to process: ``imu`` if given (``wrist`` or ``/imu/wrist``; ``{prefix}{imu}`` must exist), else
    the only one, else ``wrist``.

    ``prefix`` is the channel family that must exist for the step (``/imu/`` for raw signals,
    ``/derived/acc_global/`` for steps that need the orientation step first); ``missing_hint`` is
    appended to the error when no such channel exists (e.g. which command to run first).
    """
    names = [t[len(prefix) :] for t in topics if t.startswith(prefix)]
    hint = f": {missing_hint}" if missing_hint else ""
    if imu is not None:
        imu = imu.removeprefix("/imu/")  # the channel as trial.topics() lists it names its IMU too
        if imu not in names:
            found = f" ({prefix}* channels: {', '.join(names)})" if names else hint
            raise ValueError(f"no channel {prefix}{imu} in the trial{found}")
        return imu
    if len(names) == 1:
        return names[0]
    if "wrist" in names:
        return "wrist"
    if not names:
        raise ValueError(f"no {prefix}* channel in the trial{hint or raw_channels_hint(topics, prefix)}")
    raise ValueError(f"choose an IMU with --imu (imu=NAME in Python) among: {', '.join(names)}")


def raw_channels_hint(topics: list[str], prefix: str, most: int = 4) -> str:
    """For a trial without ``/imu/*`` channels: what it holds instead and how a stream becomes an IMU (an XDF or
    delimited stream whose channels were not recognised as acc/gyro); empty for other prefixes."""
    if prefix != "/imu/":
        return ""
    raw = [t for t in topics if not t.startswith("/derived/")]
    shown = ", ".join(raw[:most]) + (f", ... ({len(raw) - most} more)" if len(raw) > most else "")
    return (
        f" (it has {shown or 'no channel'}): the processing steps need an IMU's accelerometer/gyroscope; a stream "
        "becomes /imu/NAME when its columns or channel labels name them (acc_x.., gyro_x..; docs/converters.md), "
        "or, for delimited text, with a mapping file (imulog convert --mapping)"
    )


def imu_names(topics: list[str], prefix: str = "/imu/") -> list[str]:
    """Names of the IMUs with a ``{prefix}NAME`` channel, in the trial's order."""
    return [t[len(prefix) :] for t in topics if t.startswith(prefix) and "/" not in t[len(prefix) :]]


def primary_imu(topics: list[str], metadata: Mapping[str, Mapping[str, Any]]) -> str | None:
    """The IMU whose results keep the trial-level record names (``imulog.timing``, ``imulog.metrics``,
    ``imulog.epochs``) whatever ran first: the one ``imulog.alignment`` names, else the only IMU, else ``wrist``;
    None when the trial names none of these (then the first IMU a step runs on keeps them)."""
    names = imu_names(topics)
    aligned = str((metadata.get("imulog.alignment") or {}).get("imu") or "").removeprefix("/imu/")
    for candidate in (aligned, names[0] if len(names) == 1 else "", "wrist"):
        if candidate and candidate in names:
            return candidate
    return None


def _owner(record: Mapping[str, Any] | None) -> str | None:
    imu = (record or {}).get("imu")
    return str(imu).removeprefix("/imu/") if imu else None


def record_for(base: str, imu: str, topics: list[str], metadata: Mapping[str, Mapping[str, Any]]) -> str:
    """The metadata record a per-IMU step writes for ``imu``: ``base`` for the trial's primary IMU
    (:func:`primary_imu`; without one, for the IMU that already owns ``base``, or the first to write it) and
    ``base.IMU`` for the others, so that several IMUs never overwrite each other."""
    primary = primary_imu(topics, metadata)
    if primary is not None:
        return base if imu == primary else f"{base}.{imu}"
    owner = _owner(metadata.get(base))
    return base if owner in (None, imu) else f"{base}.{imu}"


def record_of(base: str, imu: str, metadata: Mapping[str, Mapping[str, Any]]) -> str | None:
    """The name of the record a per-IMU step wrote for ``imu`` (``base`` when it names ``imu``, else
    ``base.IMU``), None when there is none. Records that name no IMU (older trials) count as the IMU's."""
    if base in metadata and _owner(metadata.get(base)) in (None, imu):
        return base
    return f"{base}.{imu}" if f"{base}.{imu}" in metadata else None


def cluster_pose_topic(name: str, topics: list[str], metadata: Mapping[str, Mapping[str, Any]]) -> str | None:
    """The cluster pose channel of IMU ``name``: ``/derived/vicon/cluster_pose/{name}`` (a setup), or the single
    ``/derived/vicon/cluster_pose`` when ``imulog.alignment`` names that IMU; None when it has none."""
    own = f"/derived/vicon/cluster_pose/{name}"
    if own in topics:
        return own
    record = metadata.get("imulog.alignment") or {}
    if record.get("imu") == f"/imu/{name}" and "/derived/vicon/cluster_pose" in topics:
        return "/derived/vicon/cluster_pose"
    return None


def missing_gyroscope(topic: str, needs: str) -> ValueError:
    """The one-line error of a step that reads the gyroscope of ``topic``, an accelerometer-only IMU: what it lacks,
    what ``needs`` it, and the command that works without it."""
    return ValueError(
        f"{topic} has no gyroscope (an accelerometer-only device?): {needs}; "
        "`imulog process epochs` works from acceleration alone"
    )


def alignment_note(record: Mapping[str, Any]) -> dict[str, Any]:
    """What the evaluation record keeps of the alignment: quality, reasons, score, offset, drift."""
    keys = ("quality", "quality_reasons", "score", "offset_ns", "drift_ppm", "signal", "residual_spread_ns")
    return {k: record[k] for k in keys if k in record}


def alignment_for(metadata: Mapping[str, Mapping[str, Any]], imu_topic: str) -> dict[str, Any] | None:
    """The alignment record of ``imu_topic``: ``imulog.alignment`` if it concerns ``imu_topic`` (or names no
    IMU), else ``imulog.alignment.{imu}`` (written when several IMUs are aligned together), else None."""
    name = alignment_record(metadata, imu_topic)
    record = metadata.get(name)
    if name != "imulog.alignment":
        return dict(record) if record and "offset_ns" in record else None
    return dict(record) if record else None


def alignment_record(metadata: Mapping[str, Mapping[str, Any]], imu_topic: str) -> str:
    """The name of the record :func:`alignment_for` reads for ``imu_topic`` (what a step lists among its
    ``metadata_inputs``, so re-aligning that IMU makes its results out of date): ``imulog.alignment`` when it
    concerns ``imu_topic`` or there is no per-IMU record, else ``imulog.alignment.{imu}``."""
    record = metadata.get("imulog.alignment")
    if not record or record.get("imu") not in (None, "", imu_topic):
        own = f"imulog.alignment.{imu_topic.rsplit('/', 1)[-1]}"
        if own in metadata or record:
            return own
    return "imulog.alignment"


def alignment_writes(
    topics: list[str], metadata: Mapping[str, Mapping[str, Any]], name: str, record: dict[str, Any]
) -> tuple[dict[str, dict[str, Any]], str]:
    """What an alignment of IMU ``name`` writes, whichever path made it (markers, a rigid body's poses, a whole
    setup): ``(records, suffix)``. A trial with one IMU: ``imulog.alignment`` and no suffix (as always). A trial with
    several: ``imulog.alignment.{name}``, plus ``imulog.alignment`` when it is absent, names no IMU or is this IMU's
    (the trial's main record stays the first IMU aligned, or a setup's primary), and the suffix ``/{name}`` for the
    cluster channels (``/derived/vicon/cluster_pose/{name}``), so aligning IMUs one at a time never replaces
    another IMU's record or cluster."""
    if len(imu_names(topics)) <= 1:
        return {"imulog.alignment": record}, ""
    records = {f"imulog.alignment.{name}": record}
    if _owner(metadata.get("imulog.alignment")) in (None, name):
        records["imulog.alignment"] = record
    return records, f"/{name}"


CLUSTER_TOPICS = ("/derived/vicon/cluster_pose", "/derived/vicon/angular_velocity")


def renamed(streams: list, suffix: str) -> list:
    """The cluster channels of one IMU's alignment under their per-IMU topics (``/derived/vicon/cluster_pose`` +
    ``suffix``, e.g. ``/left_foot``); the other streams, already per IMU, unchanged."""
    for stream in streams:
        if suffix and stream.topic in CLUSTER_TOPICS:
            stream.topic = f"{stream.topic}{suffix}"
    return streams


def alignment_result(trial, name: str, streams: list, record: dict):
    """The step's result for IMU ``name`` aligned alone (on markers or on a pose channel): the records and topics
    of :func:`imulog.steps.common.alignment_writes`, the one rule of every alignment path."""
    from imulog.steps.base import StepResult

    records, suffix = alignment_writes(trial.topics(), trial.metadata, name, record)
    return StepResult(streams=renamed(streams, suffix), metadata=records)


def error_line(path: Any, exc: BaseException) -> str:
    """``"PATH: message"`` for a step's error, without repeating the path when the message starts with it
    (archive errors already name their file)."""
    message, name = str(exc), str(path)
    return message if message.startswith(name) else f"{name}: {message}"


class StepError(ValueError):
    """A step cannot run on a trial: ``str()`` is one line starting with the trial's path (what ``imulog process``
    prints after ``Error:``); ``path`` is the trial, ``__cause__`` the original error."""

    def __init__(self, message: str, path: Any) -> None:
        super().__init__(message)
        self.path = path


_A = TypeVar("_A")
_P = ParamSpec("_P")
_R = TypeVar("_R")


def names_trial(run: Callable[Concatenate[_A, _P], _R]) -> Callable[Concatenate[_A, _P], _R]:
    """Decorate a step's public ``run_*(path, ...)``: a plain ValueError raised for the trial (a missing channel, an
    IMU without a gyroscope) becomes a :class:`StepError` whose message starts with the path, so a script looping
    over an archive knows which file failed; more specific errors (archive, parameter, clock) pass unchanged."""

    @functools.wraps(run)
    def wrapper(path: _A, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        for key in ("params", "options"):
            if isinstance(kwargs.get(key), Mapping):  # a dict where the parameter object goes: say how to make it
                kind = str(inspect.signature(run).parameters[key].annotation).split(" |")[0].split(".")[-1]
                raise TypeError(
                    f"{run.__name__}: {key} must be {kind} (a parameter object), got a dict; "
                    f"imulog.params.params_from_dict({kind}, {{...}}) makes one from it"
                )
        try:
            return run(path, *args, **kwargs)
        except ValueError as exc:
            if type(exc) is not ValueError:
                raise
            raise StepError(error_line(path, exc), path) from exc

    return wrapper


def mean_rate_hz(t_ns: np.ndarray) -> float:
    """Mean sampling rate (Hz) over the recording: (N - 1) / duration. Dropped samples lower it."""
    t = np.asarray(t_ns, dtype=np.int64)
    if len(t) < 2 or t[-1] <= t[0]:
        raise ValueError("need at least two increasing time stamps to know the sampling rate")
    return (len(t) - 1) / ((t[-1] - t[0]) * 1e-9)


def nominal_rate_hz(t_ns: np.ndarray) -> float:
    """Nominal sampling rate (Hz) from the median sample interval: insensitive to dropped samples and gaps. Where
    the intervals' median and the mean of the steady ones (:func:`imulog.numeric.step_rate_hz`) disagree by more
    than 0.5 %, the clock steps around its rate (Axivity block times at 12.5 Hz: 79, 81 and 82 ms) and the mean is
    the rate."""
    from imulog.numeric import step_rate_hz

    dt = np.diff(np.asarray(t_ns, dtype=np.int64))
    if len(dt) == 0 or np.median(dt) <= 0:
        raise ValueError("need at least 2 samples with increasing time stamps")
    median = 1e9 / float(np.median(dt))
    steady = step_rate_hz(dt)
    return steady if steady is not None and abs(steady - median) > 0.005 * steady else median
