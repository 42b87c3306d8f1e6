"""Reprocessing step ``orientation``: sensor orientation and gravity-free global acceleration of one IMU.

Reads ``/imu/{imu}`` (or ``/derived/calibrated/{imu}`` when present, see ``source``) and writes, on
the IMU device clock (the raw channel's ``t_ns``):

* ``/derived/orientation/{imu}``: ``qw,qx,qy,qz``, sensor-to-global (z up, heading arbitrary unless
  the magnetometer is fused);
* ``/derived/acc_global/{imu}``: ``ax,ay,az`` m/s^2 in the global frame, gravity removed;
* ``/derived/orientation_static/{imu}``: ``static`` (1 = gyro norm below the threshold), the mask
  used for initialisation and gravity magnitude (``/derived/static/{imu}`` belongs to the
  segmentation step).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.console import window_progress
from imulog.model import SignalStream
from imulog.numeric import finite_rows
from imulog.process.gaps import GapParams, GapReport, per_run, prepare
from imulog.process.orientation import OrientationParams, estimate_orientation, gravity_free_acceleration
from imulog.steps.common import mean_rate_hz, missing_gyroscope, names_trial, pick_imu
from imulog.steps.sample_window import SampleWindow
from imulog.steps.windows import Window, WindowParams, channel_rate_hz

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "orientation"
CALIBRATED_TOPIC = "/derived/calibrated/{imu}"
# Quaternions and global accelerations are stored as float32 (issue 28; docs/schemas.md: within 6e-8, far below
# any IMU orientation's accuracy). A copy per stream: attrs become the channel's metadata.
# counts on a binary grid far below what an IMU orientation resolves (docs/schemas.md): 2**-18 per quaternion
# component (a 0.0002 deg rotation at most, against errors of tenths of a degree) and 2**-12 m/s^2 of
# gravity-free acceleration (6 ug at most, against 1-3 mg of accelerometer noise): half of float32's bytes once
# compressed (7 + 5 bytes a sample instead of 13 + 11); tests/test_storage_float32.py measures the effect
QUAT_GRID = {"precision": "quantized", "quantum": repr(2.0**-18)}
ACC_GRID = {"precision": "quantized", "quantum": repr(2.0**-12)}


def source_topic(topics: list[str], imu: str, source: str) -> str:
    """Input topic for ``source`` ``auto`` (calibrated if present), ``raw`` or ``calibrated``."""
    cal = CALIBRATED_TOPIC.format(imu=imu)
    if source == "raw":
        return f"/imu/{imu}"
    if source == "calibrated":
        if cal not in topics:
            raise ValueError(f"no {cal} in the trial: run `imulog process calibrate` first or use --source raw")
        return cal
    if source != "auto":
        raise ValueError(f"source must be auto, raw or calibrated, got {source!r}")
    return cal if cal in topics else f"/imu/{imu}"


def read_imu_arrays(trial: Any, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(t_ns, acc, gyr, mag)`` from a raw ImuStream or a calibrated SignalStream topic."""
    return imu_arrays(trial.read(topic), topic)


def imu_arrays(stream: Any, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """``(t_ns, acc, gyr, mag)`` of a raw ImuStream or a calibrated SignalStream (or a piece of either)."""
    if topic.startswith("/imu/"):
        if stream.acc is None:
            raise ValueError(f"{topic} has no accelerometer: orientation needs accelerometer and gyroscope columns")
        if stream.gyr is None:
            raise missing_gyroscope(topic, "orientation needs accelerometer and gyroscope columns")
        return stream.t_ns, stream.acc, stream.gyr, stream.mag
    cols = {c: i for i, c in enumerate(stream.columns)}
    need = ["ax", "ay", "az", "gx", "gy", "gz"]
    if any(c not in cols for c in need):
        raise ValueError(f"{topic} lacks columns {', '.join(c for c in need if c not in cols)}")
    v = stream.values
    acc = v[:, [cols["ax"], cols["ay"], cols["az"]]]
    gyr = v[:, [cols["gx"], cols["gy"], cols["gz"]]]
    mag = v[:, [cols["mx"], cols["my"], cols["mz"]]] if all(c in cols for c in ("mx", "my", "mz")) else None
    return stream.t_ns, acc, gyr, mag


def compute_orientation(
    t_ns: np.ndarray,
    acc: np.ndarray,
    gyr: np.ndarray,
    mag: np.ndarray | None,
    imu: str,
    params: OrientationParams,
    gaps: GapParams | None = None,
) -> list[SignalStream]:
    """Pure part of the step: the three derived streams from IMU arrays (see :func:`orientation_with_gaps`)."""
    return orientation_with_gaps(t_ns, acc, gyr, mag, imu, params, gaps)[0]


def orientation_with_gaps(
    t_ns: np.ndarray,
    acc: np.ndarray,
    gyr: np.ndarray,
    mag: np.ndarray | None,
    imu: str,
    params: OrientationParams,
    gaps: GapParams | None = None,
    estimates: list[dict[str, Any]] | None = None,
) -> tuple[list[SignalStream], GapReport]:
    """The three derived streams and the gap report: missing samples (NaN) follow :mod:`imulog.process.gaps`
    (short gaps bridged, the filter restarted after long ones, NaN outputs inside them). ``estimates``, when
    given, receives what the backend estimated besides the orientation (``OrientationResult.estimates``, e.g.
    ``vqf_gyrocal``'s ``gyro_correction``), one entry per valid run it ran on: ``{"samples": [a, b], ...}``."""
    if params.use_mag and mag is None:
        raise ValueError(f"/imu/{imu} has no magnetometer: drop --mag")
    (acc, gyr, mag_used), report = prepare([acc, gyr, mag if params.use_mag else None], gaps)
    found: list[dict[str, Any]] = []  # per run, in report.runs order (per_run calls run once per run)

    def run(t, a, g, m):
        res = estimate_orientation(g, a, mean_rate_hz(t), m, params, t_ns=t)
        found.append(res.estimates)
        return res.quat, gravity_free_acceleration(res.quat, a, res.static), res.static.astype(np.float64)

    try:
        quat, lin, static = per_run(run, report, t_ns, acc, gyr, mag_used)
    except ValueError as exc:
        raise ValueError(f"/imu/{imu}: {exc}") from None
    if estimates is not None:
        estimates.extend(
            {"samples": [int(a), int(b)], **est} for (a, b), est in zip(report.runs, found, strict=True) if est
        )
    if not params.use_mag:
        _continue_heading(quat, lin, report.runs)
    frame = f"{imu}_global"
    return [
        SignalStream(
            f"/derived/orientation/{imu}",
            t_ns,
            ["qw", "qx", "qy", "qz"],
            ["1"] * 4,
            quat,
            frame_id=frame,
            attrs=dict(QUAT_GRID),
        ),
        SignalStream(
            f"/derived/acc_global/{imu}",
            t_ns,
            ["ax", "ay", "az"],
            ["m/s^2"] * 3,
            lin,
            frame_id=frame,
            attrs=dict(ACC_GRID),
        ),
        SignalStream(f"/derived/orientation_static/{imu}", t_ns, ["static"], ["1"], static[:, None], frame_id=imu),
    ], report


def _continue_heading(quat: np.ndarray, lin: np.ndarray, runs: tuple[tuple[int, int], ...]) -> None:
    """Without a magnetometer each restarted run has its own arbitrary heading: turn each run about the global z
    axis so that its first sample has the heading of the previous run's last one (in place). This assumes the
    heading did not change during the gap; the steps record ``gaps.runs`` so the assumption is visible."""
    from imulog.process import quaternion as qmath

    for (_, b0), (a1, b1) in zip(runs, runs[1:], strict=False):
        r = qmath.heading_offset(quat[a1 : a1 + 1], quat[b0 - 1 : b0])  # (1, 4), broadcast over the run
        quat[a1:b1] = qmath.multiply(r, quat[a1:b1])
        lin[a1:b1] = qmath.rotate(r, lin[a1:b1])


def params_dict(params: OrientationParams) -> dict:
    return dataclasses.asdict(params)


def global_frame(params: OrientationParams) -> str:
    """The orientation's global frame: ENU when the magnetometer is fused, else z-up with arbitrary heading."""
    from imulog.process.orientation import GLOBAL_FRAME_6D, GLOBAL_FRAME_9D

    return GLOBAL_FRAME_9D if params.use_mag else GLOBAL_FRAME_6D


def orientation_windows(
    blocks: Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]],
    total: int,
    plan: list[Window],
    imu: str,
    params: OrientationParams,
    gaps: GapParams | None = None,
    reports: list[tuple[Window, GapReport]] | None = None,
    estimates: list[dict[str, Any]] | None = None,
) -> Iterator[SignalStream]:
    """The three derived streams of an IMU given as ``(t_ns, acc, gyr, mag)`` blocks (``total`` samples), core
    by core over ``plan``; each window's gap report is appended to ``reports``, and what the backend estimated
    to ``estimates`` (:func:`orientation_with_gaps`; ``samples`` in whole-channel indices, with the window's
    ``core`` when there are several). One window: exactly :func:`orientation_with_gaps` on the whole."""
    from imulog.process import quaternion as qmath

    buf = SampleWindow(blocks, total)
    join: tuple[int, np.ndarray] | None = None  # (global sample, orientation there) the next window continues
    for w in window_progress(plan, f"orientation {imu}"):
        t, acc, gyr, mag = buf.take(w.lo, w.hi)
        found: list[dict[str, Any]] = []
        streams, report = orientation_with_gaps(t, acc, gyr, mag, imu, params, gaps, found)
        if reports is not None:
            reports.append((w, report))
        if estimates is not None:
            core = {"core": [w.core_lo, w.core_hi]} if len(plan) > 1 else {}
            estimates.extend({**e, "samples": [e["samples"][0] + w.lo, e["samples"][1] + w.lo], **core} for e in found)
        if len(plan) == 1:
            yield from streams
            return
        core = w.core_slice
        whole = streams[0].values
        quat, lin, static = (s.values[core] for s in streams)
        ok = finite_rows(quat)
        turn = None
        if join is not None and not params.use_mag and ok.any():
            at = join[0] - w.core_lo  # the join sample in this window's core; else its first valid sample
            k = at if 0 <= at < len(quat) and ok[at] else int(np.argmax(ok))
            turn = qmath.heading_offset(quat[k : k + 1], join[1])
            quat, lin = qmath.multiply(turn, quat), qmath.rotate(turn, lin)  # (1, 4) broadcast over the core
        k1 = w.core_hi - w.lo  # the next core's first sample, in this window's margin
        if k1 < len(whole) and np.isfinite(whole[k1]).all():
            join = (w.core_hi, whole[k1 : k1 + 1] if turn is None else qmath.multiply(turn, whole[k1 : k1 + 1]))
        elif ok.any():  # a gap at the join: the next window holds this core's last valid heading across it
            last = int(len(ok) - 1 - np.argmax(ok[::-1]))
            join = (w.core_lo + last, quat[last : last + 1].copy())
        for stream, values in zip(streams, (quat, lin, static), strict=True):
            yield SignalStream(
                stream.topic,
                t[core],
                stream.columns,
                stream.units,
                values,
                frame_id=stream.frame_id,
                attrs=dict(stream.attrs),
            )


def estimated(entries: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """The run record's entries of what the backend estimated: per name (``gyro_correction``), the list of
    ``{"samples": [a, b], "core": ..., **value}`` over the runs and windows it ran on; ``{}`` when none."""
    out: dict[str, list[dict[str, Any]]] = {}
    for entry in entries:
        where = {k: entry[k] for k in ("samples", "core") if k in entry}
        for key, value in entry.items():
            if key not in where:
                out.setdefault(key, []).append({**where, **value})
    return out


def windowed_gap_report(reports: list[tuple[Window, GapReport]]) -> dict[str, Any]:
    """The run's ``gaps`` entry of a recording computed in several windows: the windows that had missing
    samples, each with its read span and core (sample indices in the whole channel) and its own report, whose
    ``runs`` are shifted to whole-channel indices; ``{}`` when no window had a missing sample."""
    windows = []
    for w, report in reports:
        if not report.missing:
            continue
        entry = report.as_dict()
        entry["runs"] = [[a + w.lo, b + w.lo] for a, b in report.runs]
        windows.append({"read": [w.lo, w.hi], "core": [w.core_lo, w.core_hi], **entry})
    if not windows:
        return {}
    return {"counted_over": "each window read (core plus margins)", "windows": windows}


def read_orientation_windows(
    path: str | Path,
    topic: str,
    imu: str,
    params: OrientationParams,
    gaps: GapParams | None,
    plan: list[Window],
    total: int,
    reports: list[tuple[Window, GapReport]] | None = None,
    estimates: list[dict[str, Any]] | None = None,
) -> Iterator[SignalStream]:
    """:func:`orientation_windows` on ``topic`` of the trial at ``path``, read chunk by chunk."""
    from imulog.archive import TrialReader
    from imulog.heap import reuse_heap

    if len(plan) > 1:
        reuse_heap()  # the same temporaries core after core: reuse their pages (imulog.heap)
    with TrialReader(path) as trial:
        blocks = (imu_arrays(b, topic) for b in trial.iter_blocks(topic))
        yield from orientation_windows(blocks, total, plan, imu, params, gaps, reports, estimates)


@names_trial
def run_orientation(
    path: str | os.PathLike[str],
    *,
    imu: str | None = None,
    params: OrientationParams | None = None,
    source: str = "auto",
    force: bool = False,
    gaps: GapParams | None = None,
    windows: WindowParams | None = None,
) -> StepOutcome:
    """Orientation of one IMU of the trial at ``path`` (``imu``: its name, e.g. ``wrist``; default the trial's one
    IMU), appended as ``/derived/orientation/IMU`` (qw, qx, qy, qz: sensor to global, z up), ``/derived/acc_global/
    IMU`` (m/s^2, gravity removed, global frame) and ``/derived/orientation_static/IMU`` (1 where the gyroscope norm
    is static), all on the IMU's clock; ``imulog process orientation`` with ``params``. Returns the
    :class:`~imulog.steps.base.StepOutcome` (``skipped`` when the same run is recorded); a trial it cannot run on
    raises :class:`~imulog.steps.common.StepError` naming ``path``.

    >>> run_orientation("trial.mcap", params=OrientationParams(backend="madgwick", beta=0.03))  # doctest: +SKIP

    ``windows``: core and margin of the windows (default :class:`~imulog.steps.windows.WindowParams`, an hour
    with a minute each side); a recording within one core is computed at once, and only longer ones record the
    windows in the run's params (the result depends on them only then).

    ``gaps``: how missing IMU samples are treated (default :class:`~imulog.process.gaps.GapParams`); what was
    bridged or split is recorded in the run's ``gaps`` entry (one window: as a whole; several: per window with
    missing samples, :func:`windowed_gap_report`, filled by the pieces once written).

    What the backend estimated besides the orientation goes into the run's record under its name, one entry per
    valid run (and window) it ran on: ``vqf_gyrocal``'s ``gyro_correction`` (:func:`orientation_windows`).
    """
    params = params or OrientationParams()
    windows = windows or WindowParams()
    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step

    with TrialReader(path) as trial:
        topics = trial.topics()
        name = pick_imu(topics, imu)
        topic = source_topic(topics, name, source)
        info = trial.channel(topic)
        total = info.sample_count
        rate = channel_rate_hz(total, info.start_ns, info.end_ns, info.rate_hz)
    plan = windows.plan(total, rate)
    step_params = {"imu": name, **params_dict(params), "global_frame": global_frame(params)}
    if len(plan) > 1:
        step_params["windows"] = windows.to_dict()

    def compute(trial) -> StepResult:
        reports: list[tuple[Window, GapReport]] = []
        estimates: list[dict[str, Any]] = []
        if len(plan) == 1:  # one window: the streams at once, and the gap report with them
            streams = list(read_orientation_windows(path, topic, name, params, gaps, plan, total, reports, estimates))
            report = reports[0][1]
            provenance = {"gaps": report.as_dict()} if report.missing else {}
            return StepResult(streams=streams, provenance={**provenance, **estimated(estimates)})

        def produce() -> Iterator[SignalStream]:
            yield from read_orientation_windows(path, topic, name, params, gaps, plan, total, reports, estimates)
            gapped = windowed_gap_report(reports)
            if gapped:
                pieces.provenance["gaps"] = gapped
            pieces.provenance.update(estimated(estimates))

        pieces = StreamPieces(
            topics=[f"/derived/{kind}/{name}" for kind in ("orientation", "acc_global", "orientation_static")],
            pieces=produce,
            expected_duration_s=total / rate,  # the viewer twins keep their message budget
        )
        return StepResult(streams=[pieces])

    return run_step(
        path,
        step=f"{STEP}:{name}",
        algorithm=f"imulog.orientation.{params.backend}",
        # the global frame (ENU with the magnetometer fused) is recorded in every output channel's params
        params=step_params,
        inputs=[topic],
        compute=compute,
        force=force,
    )
