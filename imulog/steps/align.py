"""Reprocessing step ``align``: IMU and Vicon on one clock and one frame.

Reads ``/imu/{imu}`` (gyroscope, device clock), ``/markers/{markers}`` (cluster markers, reference
clock) and, when present, ``/derived/orientation/{imu}`` and ``/derived/acc_global/{imu}``. Writes

* metadata ``imulog.alignment`` (reference, imu, offset_ns, drift_ppm, t0_ns,
  rotation_imu_to_cluster, rotation_global_to_world, method, score, plus diagnostics);
* ``/derived/vicon/cluster_pose`` (PoseStream: origin marker O (or the SVD fit's origin) in m,
  cluster-to-world orientation), reference clock;
* ``/derived/vicon/angular_velocity`` (``wx,wy,wz`` rad/s in the cluster frame), reference clock;
* with ``resample`` (default on), the IMU-derived channels on the Vicon clock and rate, anti-aliased:
  ``/derived/reference/gyr/{imu}`` (rad/s, sensor frame), ``/derived/reference/orientation/{imu}``
  and ``/derived/reference/acc_global/{imu}`` (when the orientation step has run).
"""

from __future__ import annotations

import dataclasses
import os
from typing import TYPE_CHECKING

import numpy as np

from imulog.model import PoseStream, SignalStream
from imulog.process import alignment as al
from imulog.process.resample import resample_quaternions, resample_signal
from imulog.steps.align_summary import alignment_summary  # noqa: F401  (imulog.steps.align API)
from imulog.steps.common import alignment_result, mean_rate_hz, missing_gyroscope, names_trial, pick_imu

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

# the Vicon-derived and resampled channels are stored as float32 (issue 28; docs/schemas.md: 6e-8 relative, far
# below the accuracy of a marker cluster or a resampled IMU signal); a copy per stream: attrs become metadata
F32 = {"precision": "float32"}

STEP = "align"


def pick_markers(topics: list[str], markers: str | None) -> str:
    names = [t.split("/", 2)[2] for t in topics if t.startswith("/markers/")]
    if markers is not None:
        markers = markers.removeprefix("/markers/")  # the channel's topic names it too
        if markers not in names:
            raise ValueError(
                f"no channel /markers/{markers} in the trial (marker channels: {', '.join(names) or 'none'})"
            )
        return markers
    if len(names) == 1:
        return names[0]
    if "vicon" in names:
        return "vicon"
    if not names:
        raise ValueError(
            "no /markers/* channel in the trial: align needs an optical reference recorded with the IMU, markers (a "
            "Vicon, C3D, Motive export) or a rigid body's poses (/poses/*); convert it together with the IMU's "
            "export: imulog convert IMU_FILE OPTICAL_FILE -o trial.mcap"
        )
    raise ValueError(f"choose a marker channel with --markers among: {', '.join(names)}")


def _search_summary(res, chosen: tuple[str, ...]) -> tuple[dict | None, dict | None]:
    """(best, runner-up) candidate dicts of a cluster search; the runner-up shares < 2 markers with the choice."""
    best = next((c for c in res.candidates if tuple(c.markers) == tuple(chosen)), None)
    runner = next((c for c in res.candidates if len(set(c.markers) & set(chosen)) < 2), None)
    return (None if best is None else best.as_dict()), (None if runner is None else runner.as_dict())


def _marker_alignment(
    t_imu_ns: np.ndarray,
    acc: np.ndarray | None,
    t_vic_ns: np.ndarray,
    labels: list[str],
    pos_m: np.ndarray,
    vic_rate: float,
    params: al.AlignmentParams,
    acc_global: tuple[np.ndarray, np.ndarray] | None,
    only: list[int] | None = None,
) -> tuple[dict, dict]:
    """Align on the acceleration of the marker (among ``only``, default all) that matches the IMU best."""
    from imulog.process import alignment_search as search

    if acc is None and acc_global is None:
        raise ValueError("no rigid marker cluster moves with the IMU, and the IMU has no accelerometer to align on")
    idx = list(range(len(labels))) if only is None else only
    filt, missing = al.lowpass_markers(np.asarray(pos_m, dtype=np.float64)[:, idx], vic_rate, params.filter)
    if acc_global is not None:
        t_a, a = np.asarray(acc_global[0], dtype=np.int64), acc_global[1]
    else:
        t_a, a = np.asarray(t_imu_ns, dtype=np.int64), acc
    rate_a = mean_rate_hz(t_a)
    a_norm = np.linalg.norm(search.lowpass_vector(a, rate_a, params.filter.cutoff_hz, params.filter.order), axis=1)
    ranked = search.rank_markers(
        t_a,
        a_norm,
        t_vic_ns,
        filt,
        [labels[i] for i in idx],
        vic_rate,
        gravity_free=acc_global is not None,
        max_lag_s=params.max_lag_s,
        params=params.search,
        missing=missing,
    )
    if not ranked:
        raise ValueError("no marker is visible long enough to align on its acceleration")
    best = ranked[0]
    j = labels.index(best.markers[0])
    vertical = None if acc_global is not None else search.VERTICALS[best.extra["vertical"]]
    record = al.align_marker(
        t_imu_ns,
        acc,
        t_vic_ns,
        np.asarray(pos_m)[:, j],
        vic_rate,
        params,
        vertical=vertical,
        acc_global=acc_global,
        coarse_offset_ns=best.offset_ns,
    )
    info = {
        "markers": [best.markers[0]],
        "ncc": round(float(best.ncc), 4),
        "vector_match": None,
        "runner_up": ranked[1].as_dict() if len(ranked) > 1 else None,
    }
    return record, info


def compute_alignment(
    imu_name: str,
    t_imu_ns: np.ndarray,
    gyr: np.ndarray,
    marker_topic: str,
    t_vic_ns: np.ndarray,
    labels: list[str],
    pos_m: np.ndarray,
    params: al.AlignmentParams,
    orientation: tuple[np.ndarray, np.ndarray] | None = None,
    acc_global: tuple[np.ndarray, np.ndarray] | None = None,
    resample: bool = True,
    acc: np.ndarray | None = None,
) -> tuple[list, dict]:
    """Pure part of the step: streams and the ``imulog.alignment`` record (no I/O); see :func:`_compute`.

    The lag is first searched within +-``params.max_lag_s`` of the recordings' starts (the usual case: both
    started within a minute); when nothing matches there or the score is poor, once more over every overlap
    of the two recordings (an IMU that logged minutes before the Vicon started), and the more convincing
    result is kept (the wide one records ``max_lag_s_used``).
    """
    args = (imu_name, t_imu_ns, gyr, marker_topic, t_vic_ns, labels, pos_m)
    return with_wide_search(
        lambda p: _compute(*args, p, orientation, acc_global, resample, acc),
        t_imu_ns,
        t_vic_ns,
        params,
        gyr is not None,
    )


def with_wide_search(compute, t_imu_ns: np.ndarray, t_ref_ns: np.ndarray, params: al.AlignmentParams, wide_ok: bool):
    """``compute(params)`` (streams, record) within +-``params.max_lag_s`` of the recordings' starts; when that
    fails or scores poorly (and ``wide_ok``), once more over every overlap of the two recordings, keeping the more
    convincing result (the wide one records ``max_lag_s_used``)."""
    first, error = None, None
    try:
        first = compute(params)
    except ValueError as exc:
        error = exc
    if first is not None and _rank(first[1], params) >= 1.0:  # a correlation score that is not poor
        return first
    t_i, t_v = np.asarray(t_imu_ns, dtype=np.int64), np.asarray(t_ref_ns, dtype=np.int64)
    wide = float(np.ceil(((t_i[-1] - t_i[0]) + (t_v[-1] - t_v[0])) / al.NS)) if len(t_i) > 1 and len(t_v) > 1 else 0
    if not wide_ok or wide <= params.max_lag_s:
        if first is None:
            raise error
        return first
    try:
        second = compute(dataclasses.replace(params, max_lag_s=wide))
    except ValueError:
        if first is None:
            raise error from None
        return first
    second[1]["max_lag_s_used"] = wide
    return second if first is None or _rank(second[1], params) > _rank(first[1], params) else first


def _rank(record: dict, params: al.AlignmentParams) -> float:
    """How convincing an alignment is: 2 + score for a cluster that reproduces the gyroscope with a good
    correlation, 1 + score for a good single-marker one, the score alone otherwise."""
    score = float(record.get("score") or 0.0)
    if score < params.poor_score:
        return score
    return (2.0 if record.get("signal") != "marker-acceleration" else 1.0) + score


def _compute(
    imu_name: str,
    t_imu_ns: np.ndarray,
    gyr: np.ndarray,
    marker_topic: str,
    t_vic_ns: np.ndarray,
    labels: list[str],
    pos_m: np.ndarray,
    params: al.AlignmentParams,
    orientation: tuple[np.ndarray, np.ndarray] | None = None,
    acc_global: tuple[np.ndarray, np.ndarray] | None = None,
    resample: bool = True,
    acc: np.ndarray | None = None,
) -> tuple[list, dict]:
    """Streams and the ``imulog.alignment`` record for one lag search range.

    ``params.cluster="auto"`` without ``params.markers`` searches the rigid marker set that moves with the
    IMU (:func:`imulog.process.alignment_find.find_cluster`); when none reproduces the gyroscope, the
    marker whose acceleration matches the accelerometer (``acc``, or ``acc_global`` when the orientation
    step has run) is used instead. One marker in ``params.markers`` aligns on that marker's acceleration.
    """
    from imulog.process import alignment_find as find
    from imulog.process import alignment_search as search

    if gyr is None:
        raise missing_gyroscope(f"/imu/{imu_name}", "aligning compares angular velocities")
    labels = list(labels)
    vic_rate = mean_rate_hz(t_vic_ns)
    q_s2g = orientation_at(orientation, t_imu_ns)
    ck = None
    try:
        if params.cluster == "auto" and not params.markers:
            res, ck, record = find.find_cluster(t_imu_ns, gyr, t_vic_ns, labels, pos_m, vic_rate, params)
            if record is not None and record["vector_match"] >= params.search.min_vector_match:
                best, runner = _search_summary(res, ck.markers)
                info = {**(best or {}), "markers": list(ck.markers), "runner_up": runner}
                if q_s2g is not None:
                    record = al.align(t_imu_ns, gyr, ck, params, q_imu_s2g=q_s2g, coarse_offset_ns=record["offset_ns"])
            else:
                ck = None
                rejected = res.candidates[0].as_dict() if res.candidates else None
                record, info = _marker_alignment(t_imu_ns, acc, t_vic_ns, labels, pos_m, vic_rate, params, acc_global)
                info["rejected_cluster"] = rejected
            info.update(selection="search", triads_found=res.n_triads, triads_scored=res.n_scored)
        elif params.cluster != "oxy" and len(params.markers) == 1:
            only = search.resolve_markers(labels, params.markers)
            record, info = _marker_alignment(
                t_imu_ns, acc, t_vic_ns, labels, pos_m, vic_rate, params, acc_global, only=only
            )
            info.update(selection="given", runner_up=None)
        else:
            fixed = params if params.cluster != "auto" else dataclasses.replace(params, cluster="svd")
            ck = al.cluster_kinematics(t_vic_ns, labels, pos_m, vic_rate, fixed)
            record = al.align(t_imu_ns, gyr, ck, params, q_imu_s2g=q_s2g)
            info = {"markers": list(ck.markers), "selection": "given", "runner_up": None}
            info["vector_match"] = round(float(record["vector_match"]), 4)
    except ValueError as exc:
        hint = (
            "; name the IMU's markers: --cluster-markers A,B,C (or one marker)"
            if params.cluster != "auto" or params.markers
            else ""
        )
        raise ValueError(f"{marker_topic}: {exc}{hint}") from None
    if float(record.get("score") or 0.0) < params.min_valid_score:
        best = info.get("rejected_cluster") or {}
        tried = (
            f"best rigid set {','.join(best['markers'])} (vector match {best.get('vector_match')}), " if best else ""
        )
        raise ValueError(
            f"{marker_topic}: no marker moves like /imu/{imu_name} ({tried}{','.join(info['markers'])}: correlation "
            f"{float(record.get('score') or 0):.2f} < {params.min_valid_score:g}); did the IMU move? "
            "name its markers with --cluster-markers"
        )
    if ck is None:
        record["reference_marker"] = info["markers"][0]
    record = {"reference": marker_topic, "imu": f"/imu/{imu_name}", **record, "cluster": info}
    record["quality"], record["quality_reasons"] = al.assess_quality(record, params)
    streams = alignment_streams(
        imu_name, ck, record, t_imu_ns, gyr, t_vic_ns, vic_rate, orientation, acc_global, resample
    )
    return streams, _jsonable(record)


def alignment_streams(
    imu_name: str,
    ck,
    record: dict,
    t_imu_ns: np.ndarray,
    gyr: np.ndarray,
    t_vic_ns: np.ndarray,
    vic_rate: float,
    orientation: tuple[np.ndarray, np.ndarray] | None,
    acc_global: tuple[np.ndarray, np.ndarray] | None,
    resample: bool,
    suffix: str = "",
) -> list:
    """The step's streams for one IMU: its cluster's pose and angular velocity (``/derived/vicon/cluster_pose``
    and ``/derived/vicon/angular_velocity``, plus ``suffix``, e.g. ``/left_foot`` in a trial of several IMUs)
    when it has a cluster, and with ``resample`` the IMU-derived channels on the reference clock."""
    streams: list = []
    if ck is not None:
        ok = ~ck.missing
        streams += [
            PoseStream(
                "/derived/vicon/cluster_pose" + suffix,
                ck.t_ns[ok],
                ck.origin_m[ok],
                ck.quat_c2w[ok],
                frame_id="world",
                precision=F32.get("precision", ""),
            ),
            SignalStream(
                "/derived/vicon/angular_velocity" + suffix,
                ck.t_ns,
                ["wx", "wy", "wz"],
                ["rad/s"] * 3,
                ck.omega_local_rad_s,
                frame_id="cluster",
                attrs=dict(F32),
            ),
        ]
    if resample:
        t_vic = np.asarray(t_vic_ns, dtype=np.int64)
        t_ref_imu = al.device_to_reference(t_imu_ns, record)
        inside = (t_vic >= t_ref_imu[0]) & (t_vic <= t_ref_imu[-1])
        t_dst = t_vic[inside]
        streams.append(
            SignalStream(
                f"/derived/reference/gyr/{imu_name}",
                t_dst,
                ["gx", "gy", "gz"],
                ["rad/s"] * 3,
                resample_signal(t_ref_imu, gyr, t_dst, dst_rate_hz=vic_rate),
                frame_id=imu_name,
                attrs=dict(F32),
            )
        )
        if orientation is not None:
            t_o = al.device_to_reference(orientation[0], record)
            streams.append(
                SignalStream(
                    f"/derived/reference/orientation/{imu_name}",
                    t_dst,
                    ["qw", "qx", "qy", "qz"],
                    ["1"] * 4,
                    resample_quaternions(t_o, orientation[1], t_dst, dst_rate_hz=vic_rate),
                    frame_id=f"{imu_name}_global",
                    attrs=dict(F32),
                )
            )
        if acc_global is not None:
            t_a = al.device_to_reference(acc_global[0], record)
            streams.append(
                SignalStream(
                    f"/derived/reference/acc_global/{imu_name}",
                    t_dst,
                    ["ax", "ay", "az"],
                    ["m/s^2"] * 3,
                    resample_signal(t_a, acc_global[1], t_dst, dst_rate_hz=vic_rate),
                    frame_id=f"{imu_name}_global",
                    attrs=dict(F32),
                )
            )
    return streams


def _jsonable(value):
    """Numpy scalars and tuples in the record as plain JSON types; NaN as None."""
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def params_dict(params: al.AlignmentParams) -> dict:
    d = dataclasses.asdict(params)
    d["markers"] = list(params.markers)
    return d


MARGIN_S = 600.0  # IMU samples read beyond the markers' span on either side, besides the lag search's range


def imu_span(trial, imu_topic: str, marker_topic: str, max_lag_s: float) -> tuple[int | None, int | None]:
    """(start_ns, end_ns) of the IMU samples the alignment reads (device clock). The lag search starts from the
    two recordings starting together (:func:`imulog.process.alignment_lag`) and looks ``max_lag_s`` either way,
    so the IMU is read from its start to as long after it as the markers last, plus ``max_lag_s`` and
    :data:`MARGIN_S`; (None, None), the whole channel, when the IMU ends within that or a span is unknown. A lab
    trial's IMU is read whole, as before; a week's wrist with an hour of markers (a lab session at the start)
    only over that hour and the margin, in bounded memory (issue 24)."""
    mk, imu = trial.channel(marker_topic), trial.channel(imu_topic)
    if None in (mk.start_ns, mk.end_ns, imu.start_ns, imu.end_ns):
        return None, None
    hi = int(imu.start_ns) + (int(mk.end_ns) - int(mk.start_ns)) + int((max_lag_s + MARGIN_S) * 1e9)
    return (None, None) if imu.end_ns < hi else (None, hi)


def read_derived_pair(trial, topics: list[str], lo: int | None, hi: int | None) -> tuple:
    """``(orientation, acc_global)`` as ``(t_ns, values)`` pairs (None when not in ``topics``) from an open trial,
    read over ``[lo, hi)`` on the device clock: the inputs ``/derived/orientation/{imu}`` and
    ``/derived/acc_global/{imu}`` an alignment uses when the orientation step ran first."""
    out = []
    for kind in ("/derived/orientation/", "/derived/acc_global/"):
        topic = next((t for t in topics if t.startswith(kind)), None)
        s = trial.read(topic, lo, hi) if topic else None
        out.append(None if s is None else (s.t_ns, s.values))
    return tuple(out)


def orientation_at(orientation: tuple[np.ndarray, np.ndarray] | None, t_imu_ns: np.ndarray) -> np.ndarray | None:
    """The orientation step's quaternions at the IMU's samples (resampled when its time stamps differ)."""
    if orientation is None:
        return None
    t_o, q_o = orientation
    return q_o if np.array_equal(t_o, t_imu_ns) else resample_quaternions(t_o, q_o, t_imu_ns)


@names_trial
def run_align(
    path: str | os.PathLike[str],
    *,
    imu: str | None = None,
    markers: str | None = None,
    params: al.AlignmentParams | None = None,
    resample: bool = True,
    force: bool = False,
) -> StepOutcome:
    """Run the step for one IMU of a trial file; returns the :func:`imulog.steps.base.run_step` outcome.
    Every IMU of a trial at once: :func:`imulog.steps.align_setup.run_align_setup`."""
    params = params or al.AlignmentParams()
    from imulog.archive import TrialReader
    from imulog.steps.base import StepResult, run_step

    with TrialReader(path) as trial:
        topics = trial.topics()
    name = pick_imu(topics, imu)
    mname = pick_markers(topics, markers)
    imu_topic, marker_topic = f"/imu/{name}", f"/markers/{mname}"
    o_topic, a_topic = f"/derived/orientation/{name}", f"/derived/acc_global/{name}"
    inputs = [imu_topic, marker_topic] + [t for t in (o_topic, a_topic) if t in topics]

    def compute(trial) -> StepResult:
        lo, hi = imu_span(trial, imu_topic, marker_topic, params.max_lag_s)
        imu_stream = trial.read(imu_topic, lo, hi)
        mk = trial.read(marker_topic)
        orientation, acc_global = read_derived_pair(trial, [t for t in (o_topic, a_topic) if t in inputs], lo, hi)
        streams, record = compute_alignment(
            name,
            imu_stream.t_ns,
            imu_stream.gyr,
            marker_topic,
            mk.t_ns,
            mk.labels,
            mk.pos,
            params,
            orientation,
            acc_global,
            resample,
            acc=imu_stream.acc,
        )
        return alignment_result(trial, name, streams, record)

    return run_step(
        path,
        step=STEP,
        algorithm="imulog.alignment.xcorr_wahba",
        params={"imu": name, "markers": mname, "resample": resample, **params_dict(params)},
        inputs=inputs,
        compute=compute,
        force=force,
    )


def alignment_problem(metadata: dict, imu_topic: str | None = None) -> str | None:
    """Why the trial has no usable ``imulog.alignment`` record (for ``imu_topic`` when given), else None."""
    from imulog.steps.common import alignment_for

    record = metadata.get("imulog.alignment")
    if imu_topic is not None:
        record = alignment_for(metadata, imu_topic) or record
    if not record or "offset_ns" not in record:
        return "no IMU-to-Vicon alignment"
    if imu_topic is not None and record.get("imu") not in (None, "", imu_topic):
        return f"the alignment is for {record.get('imu')}, not {imu_topic}"
    if record.get("quality") == "failed":
        return "the alignment failed"
    return None


def require_alignment(metadata: dict, path, imu_topic: str | None = None, *, needed_for: str = "this step") -> dict:
    """The trial's valid ``imulog.alignment`` record, else a one-line ValueError naming the command to run."""
    problem = alignment_problem(metadata, imu_topic)
    if problem is not None:
        imu = f" --imu {imu_topic.rsplit('/', 1)[-1]}" if imu_topic else ""
        raise ValueError(
            f"{problem}: {needed_for} needs the IMU on the Vicon clock; run `imulog process align {path}{imu}` first"
        )
    from imulog.steps.common import alignment_for

    own = alignment_for(metadata, imu_topic) if imu_topic else None
    return dict(own or metadata["imulog.alignment"])
