"""Log imulog streams to a Rerun recording with the columnar API (``send_columns``), never per sample.

:func:`log_streams` takes the in-memory streams of one trial (:mod:`imulog.model`), maps every channel to the
reference clock (:class:`imulog.archive.clocks.ClockMap`), and sends each channel as one columnar batch on the
``reference_time`` timeline. It returns a :class:`LoggedTrial` describing what went where, from which
:mod:`imulog.view.blueprint` builds the default layout.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import rerun as rr

from imulog.archive.clocks import ClockMap, device_imu_of
from imulog.model import AnalogStream, ImuStream, Intervals, MarkerStream, PoseStream, SignalStream
from imulog.process.repetition_flags import trial_flags
from imulog.view import layout as L
from imulog.view import rates
from imulog.view.anchor import anchor_repetitions, position_error_cm
from imulog.view.columns import ColumnLogger, Entity, LoggedTrial, _norm, scalar_column
from imulog.view.frames import AXIS_LENGTH_M as FRAME_AXIS_M
from imulog.view.frames import imu_frame, is_orientation
from imulog.view.phase_colors import (
    FORCED,
    FORCED_COLOR,
    LOW_CONFIDENCE_COLOR,
    MAX_LOGGED_PHASES,
    MAX_NUMBERED_REPETITIONS,
    REP_COLORS,
    known_phase_colors,
    numbered_phase_labels,
    phase_color,
    repetition_colors,
)
from imulog.view.report import evaluation_markdown, info_markdown, markdown_table, metrics_markdown
from imulog.view.source import logging_rank


class _Logger(ColumnLogger):
    def trajectory(self, topic: str, t_ref: np.ndarray, pos: np.ndarray, label: str) -> tuple[int, int, int]:
        colour = L.VICON_COLOR if topic == L.CLUSTER_POSE_TOPIC else L.color(self.n_paths)
        if topic != L.CLUSTER_POSE_TOPIC:
            self.n_paths += 1
        finite = np.isfinite(pos).all(axis=1)
        self.path_strip(topic, t_ref, pos, colour, label, finite)
        cursor = L.cursor_entity(topic, self.prefix)
        rows = rates.display_rows(t_ref)  # a cursor is only seen at the display's rate
        self.points(cursor, "cursor", topic, t_ref[rows], pos[rows, None, :], finite[rows, None], 0.007, colour)
        return colour

    def imu_trajectory(self, s: SignalStream, t_ref: np.ndarray) -> None:
        """An IMU trajectory in 3D (anchored per repetition on the Vicon path) and its error vs Vicon (cm)."""
        from imulog.steps.trajectory_topics import record_of_imu

        method, _, imu = s.topic[len(L.TRAJECTORY_PREFIX) :].partition("/")  # per IMU: METHOD/IMU
        record = record_of_imu(imu, self.metadata) if imu else self.trajectory_record
        reference = self.references.get(imu, self.reference) if imu else self.reference
        world = s.values[:, :3]
        in_world = record.get("frame", s.frame_id or "world") == "world"
        if reference is not None and in_world and record.get("origin") == "repetition_start":
            starts = np.array([r["start_ns"] for r in record.get("repetitions", []) if "start_ns" in r], np.int64)
            if record.get("clock") == "device" and record.get("imu"):
                starts = self.clocks.to_reference(str(record["imu"]), starts)
            world = anchor_repetitions(t_ref, world, starts, *reference)
        check = (record.get("checks") or {}).get(method) or {}
        flag = f" (assumptions failed: {', '.join(check.get('failed', []))})" if check.get("ok") is False else ""
        name = f"{imu} {method}" if imu else method
        colour = self.trajectory(s.topic, t_ref, world, f"IMU {name}{flag}")
        if reference is not None and in_world:
            error = position_error_cm(t_ref, world, *reference)
            names = [f"|{name} − Vicon| (cm){flag}"]
            self.scalars(L.error_entity(s.topic, self.prefix), "error", s.topic, t_ref, error, names, [colour])
            finite = np.asarray(error, dtype=np.float64)
            finite = finite[np.isfinite(finite)]
            if len(finite) and self.trial.entities and self.trial.entities[-1].role == "error":
                self.trial.entities[-1].scale = float(np.percentile(finite, 95))
                self.trial.entities[-1].color = colour

    # -- stream types ----------------------------------------------------------------------------
    def imu(self, s: ImuStream) -> None:
        t_ref = self.clocks.to_reference(s.topic, s.t_ns)
        for quantity, (_, unit, axes) in L.IMU_QUANTITIES.items():
            values = getattr(s, quantity)
            if values is None:
                continue
            names = [f"{s.name} {quantity} {a} ({unit})" for a in axes]
            self.scalars(L.imu_entity(s.name, quantity, self.prefix), f"imu_{quantity}", s.topic, t_ref, values, names)
        if s.gyr is not None:
            self.scalars(
                L.imu_gyr_norm_entity(s.name, self.prefix),
                "gyr_norm",
                s.topic,
                t_ref,
                _norm(s.gyr),
                [f"IMU {s.name} |gyr| (rad/s)"],
                [L.PALETTE[0]],
            )

    def markers(self, s: MarkerStream) -> None:
        t_ref = self.clocks.to_reference(s.topic, s.t_ns)
        self.points(
            L.marker_entity(s.name, self.prefix), "markers", s.topic, t_ref, s.pos, s.valid, 0.006, None, s.labels
        )

    def analog(self, s: AnalogStream) -> None:
        t_ref = self.clocks.to_reference(s.topic, s.t_ns)
        names = [f"{c} ({L.pretty_unit(u)})" for c, u in zip(s.channel_names, s.units, strict=True)]
        colors = [L.color(i) for i in range(len(names))]
        self.scalars(L.signal_entity(s.topic, self.prefix), "analog", s.topic, t_ref, s.values, names, colors)

    def signal(self, s: SignalStream) -> None:
        topic = s.topic
        t_ref = self.clocks.to_reference(topic, s.t_ns)
        short = topic[len(L.DERIVED) :] if topic.startswith(L.DERIVED) else topic.strip("/")
        names = [f"{short} {c} ({L.pretty_unit(u)})" for c, u in zip(s.columns, s.units, strict=True)]
        if topic.endswith(L.INTERVAL_SHARE_SUFFIX) and s.units == ["%"]:
            role = "interval_share"
        elif is_orientation(topic, s.columns) or topic.startswith(L.ORIENTATION_PREFIX):
            role = "orientation"
        elif topic.startswith(L.ACC_GLOBAL_PREFIX):
            role = "acc_global"
        elif topic.startswith(L.METRICS_PREFIX):
            role = "metric"
        elif topic.startswith(L.TRAJECTORY_PREFIX):
            role = "trajectory_signal"
        elif topic == L.VICON_ANGULAR_VELOCITY_TOPIC:
            role = "vicon_angular_velocity"
        elif topic.startswith(L.STATIC_PREFIXES):
            role = "static_signal"
        else:
            role = "signal"
        colors = None if s.values.shape[1] <= len(L.AXIS_COLORS) else [L.color(i) for i in range(s.values.shape[1])]
        self.scalars(L.signal_entity(topic, self.prefix), role, topic, t_ref, s.values, names, colors)

        if is_orientation(topic, s.columns) and len(s):
            self.orientation_frame(s, t_ref)
        if topic == L.VICON_ANGULAR_VELOCITY_TOPIC and s.values.shape[1] >= 3:
            self.scalars(
                L.norm_entity(topic, self.prefix),
                "vicon_omega_norm",
                topic,
                t_ref,
                _norm(s.values[:, :3]),
                ["Vicon |ω| (rad/s)"],
                [L.VICON_COLOR],
            )
        if topic.startswith(L.TRAJECTORY_PREFIX) and s.values.shape[1] >= 3:
            self.imu_trajectory(s, t_ref)
        if topic.startswith(L.STATIC_PREFIXES) and len(s):
            self.mask_states(topic, t_ref, s.values[:, 0])

    def orientation_frame(self, s: SignalStream, t_ref: np.ndarray) -> None:
        """The orientation as a moving frame (x red, y green, z blue) in 3D, beside the Vicon cluster."""
        name = s.topic.rstrip("/").rsplit("/", 1)[-1]
        derived = s.topic.startswith(L.ORIENTATION_PREFIX)
        rotation = (self.clocks.alignments.get(name) or {}).get("rotation_global_to_world") if derived else None
        index = sum(1 for e in self.trial.entities if e.role == "imu_frame")
        valid, pos, quat_xyzw = imu_frame(t_ref, s.values, rotation=rotation, cluster=self.reference, index=index)
        if not valid.any():
            return
        path = L.imu_frame_entity(s.topic, self.prefix)
        self.rec.log(path, rr.TransformAxes3D(FRAME_AXIS_M), static=True)
        cols = rr.Transform3D.columns(translation=pos, quaternion=quat_xyzw)
        self.rec.send_columns(path, indexes=[self._time(t_ref[valid])], columns=cols)
        self._record(path, "imu_frame", s.topic, t_ref[valid])

    def mask_states(self, topic: str, t_ref: np.ndarray, mask: np.ndarray) -> None:
        """A 0/1 static mask as state changes ``static``/``moving`` at its transitions (NaN = gap)."""
        state = np.where(np.isnan(mask), 0, np.where(mask > 0.5, 1, 2)).astype(np.int8)
        change = np.concatenate([[True], state[1:] != state[:-1]])
        names = np.array(["", "static", "moving"])[state[change]]
        self.states(L.state_entity(topic, self.prefix), "static_state", topic, t_ref[change], names, 1)

    def intervals(self, s: Intervals) -> None:
        t_start = self.clocks.to_reference(s.topic, s.start_ns)
        t_end = self.clocks.to_reference(s.topic, s.end_ns)
        labels = np.asarray(s.labels, dtype=object)
        instant = t_end == t_start
        role = "phases" if s.topic.startswith(L.PHASES_PREFIX) else "intervals"
        if (~instant).any():
            order = np.argsort(t_start[~instant], kind="stable")
            starts, ends = t_start[~instant][order], t_end[~instant][order]
            labs, tasks = labels[~instant][order], s.task_index[~instant][order]
            with_task = bool((tasks >= 0).any())
            lanes = 2 if with_task else 1
            times: list[np.ndarray] = []
            values: list[np.ndarray] = []
            # a reset at each end unless the next interval starts there (or earlier)
            next_start = np.concatenate([starts[1:], [np.iinfo(np.int64).max]])
            needs_reset = ends < next_start
            rep = np.array([f"rep {k}" if k >= 0 else "" for k in tasks], dtype=object)
            colors = None
            if role == "phases":  # forced phases and low-confidence repetitions visible as such (imulog.timing)
                labs, rep = self.phase_quality_labels(starts, labs, tasks, rep)
                self.phase_log(s.topic, starts, ends, labs, rep)
                if with_task and len(np.unique(tasks)) <= MAX_NUMBERED_REPETITIONS:
                    labs, colors = numbered_phase_labels(labs, tasks, rep)
            if colors is None and with_task:  # e.g. numbered activities: the number lane in greys, not rainbow
                colors = known_phase_colors(labs.tolist()) | repetition_colors(tasks, rep)
            start_states = np.stack([labs, rep], axis=1) if with_task else labs[:, None]
            reset_states = np.full((int(needs_reset.sum()), lanes), "", dtype=object)
            times = [starts, ends[needs_reset]]
            values = [start_states, reset_states]
            t_all = np.concatenate(times)
            v_all = np.concatenate(values, axis=0)
            order = np.argsort(t_all, kind="stable")
            self.states(
                L.signal_entity(s.topic, self.prefix),
                role,
                s.topic,
                t_all[order],
                v_all[order].reshape(-1),
                lanes,
                colors,
            )
        if instant.any():
            path = L.join(self.prefix, f"{s.topic}/events")
            t_ev = t_start[instant]
            self.rec.send_columns(
                path, indexes=[self._time(t_ev)], columns=rr.TextLog.columns(text=[str(x) for x in labels[instant]])
            )
            self._record(path, "events", s.topic, t_ev)

    def phase_quality_labels(self, starts, labs, tasks, rep):
        """Phase labels ``"<label> (forced)"`` for phases event correction made by cutting a movement, and the
        repetition lane ``"rep k (flagged: drift)"`` for a flagged repetition (``imulog.trajectory`` or
        ``imulog.timing``), else ``"rep k (confidence c)"`` below confidence 0.5, from ``imulog.timing``."""
        rows = self.timing_record.get("phases") or []
        forced = {(int(r["repetition"]), str(r["label"])) for r in rows if r.get("forced")}
        low = {
            int(q["repetition"]): float(q["confidence"])
            for q in self.timing_record.get("repetition_quality") or []
            if float(q.get("confidence", 1.0)) < 0.5
        }
        # the repetition flags (issue 31): the trajectory step's when it ran (it adds drift), else the phases step's
        found = trial_flags(self.timing_record, self.trajectory_record)
        flagged = {int(f["repetition"]): f.get("reasons") or [] for f in (found[0] if found else [])}
        if not forced and not low and not flagged:
            return labs, rep
        labs = np.array(
            [f"{lab}{FORCED}" if (int(k), str(lab)) in forced else lab for lab, k in zip(labs, tasks, strict=True)],
            dtype=object,
        )

        def lane(r: str, k: int) -> str:
            if k in flagged:
                return f"{r} (flagged: {', '.join(flagged[k])})"
            return f"{r} (confidence {low[k]:.2f})" if k in low else r

        rep = np.array([lane(r, int(k)) for r, k in zip(rep, tasks, strict=True)], dtype=object)
        return labs, rep

    def phase_log(self, topic: str, starts: np.ndarray, ends: np.ndarray, labs: np.ndarray, rep: np.ndarray) -> None:
        """One TextLog row per phase at its start, ``rep 3 · reach · 0.74 s``, coloured like its state lane."""
        if len(starts) > MAX_LOGGED_PHASES:
            return
        lines = [
            f"{r} · {lab} · {(e - b) / 1e9:.2f} s" if r else f"{lab} · {(e - b) / 1e9:.2f} s"
            for r, lab, b, e in zip(rep.tolist(), labs.tolist(), starts.tolist(), ends.tolist(), strict=True)
        ]
        palette = {lab: phase_color(lab) for lab in {str(x) for x in labs.tolist()}}
        colours = np.array([palette[str(lab)] for lab in labs.tolist()], dtype=np.uint32)
        path = L.phase_log_entity(topic, self.prefix)
        self.rec.send_columns(path, indexes=[self._time(starts)], columns=rr.TextLog.columns(text=lines, color=colours))
        self._record(path, "phase_log", topic, starts)

    def pose(self, s: PoseStream) -> None:
        t_ref = self.clocks.to_reference(s.topic, s.t_ns)
        valid = np.all(np.isfinite(s.position), axis=1) & np.all(np.isfinite(s.orientation), axis=1)
        quat_xyzw = s.orientation[valid][:, [1, 2, 3, 0]]
        cols = rr.Transform3D.columns(translation=s.position[valid], quaternion=quat_xyzw)
        if s.topic == L.CLUSTER_POSE_TOPIC:  # logged before the trajectories anchored on it (logging_rank)
            self.reference = (t_ref, s.position)
        elif s.topic.startswith(f"{L.CLUSTER_POSE_TOPIC}/"):  # an IMU's own cluster in a setup aligned as a whole
            self.references[s.topic.rsplit("/", 1)[1]] = (t_ref, s.position)
        path = L.pose_entity(s.topic, self.prefix)
        self.rec.log(path, rr.TransformAxes3D(0.08), static=True)
        self.rec.send_columns(path, indexes=[self._time(t_ref)], columns=cols.partition(valid.astype(np.int64)))
        self._record(path, "pose", s.topic, t_ref)
        label = "Vicon cluster" if s.topic == L.CLUSTER_POSE_TOPIC else s.topic
        self.trajectory(s.topic, t_ref, s.position, label)

    def log(self, stream: Any) -> None:
        if isinstance(stream, ImuStream):
            self.imu(stream)
        elif isinstance(stream, MarkerStream):
            self.markers(stream)
        elif isinstance(stream, AnalogStream):
            self.analog(stream)
        elif isinstance(stream, SignalStream):
            self.signal(stream)
        elif isinstance(stream, Intervals):
            self.intervals(stream)
        elif isinstance(stream, PoseStream):
            self.pose(stream)
        else:  # pragma: no cover - defensive
            raise TypeError(f"cannot view a {type(stream).__name__}")


def _logging_rank(stream: Any) -> int:
    """:func:`imulog.view.source.logging_rank` of an in-memory stream."""
    return logging_rank("intervals" if isinstance(stream, Intervals) else "", stream.topic)


def _log_legend(recording: rr.RecordingStream, trial: LoggedTrial, prefix: str) -> None:
    """A markdown legend for the 3D view: which colour is which method, its error, whether it starts hidden."""
    errors = trial.by_role("error")
    paths = [e for e in trial.by_role("path")]
    if not paths:
        return
    hidden = L.large_error_topics({e.topic: e.scale for e in errors if e.scale is not None})
    scale_of = {e.topic: e.scale for e in errors}
    rows = []
    for e in paths:
        colour = e.color or L.VICON_COLOR
        swatch = f"#{colour[0]:02x}{colour[1]:02x}{colour[2]:02x}"
        name = "Vicon cluster (reference)" if e.topic == L.CLUSTER_POSE_TOPIC else L.path_source(e.topic)
        err = scale_of.get(e.topic)
        rows.append(
            f"| {name} | `{swatch}` | {'' if err is None else f'{err:.1f}'} | {'hidden' if e.topic in hidden else 'shown'} |"
        )
    text = (
        "| trajectory | colour | error p95 (cm) | 3D view |\n|---|---|---|---|\n"
        + "\n".join(rows)
        + "\n\nHidden methods drift by metres (uncorrected double integration); show them with the eye icon in"
        " the blueprint panel (left, collapsed by default). Their error has its own plot in *Errors & metrics*."
    )
    recording.log(L.legend_entity(prefix), rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN), static=True)
    trial.entities.append(Entity(L.legend_entity(prefix), "legend", "", 0))


def log_streams(
    streams: Iterable[Any],
    metadata: Mapping[str, Mapping[str, Any]] | None = None,
    *,
    recording: rr.RecordingStream,
    label: str = "trial",
    prefix: str = "",
    channel_meta: Mapping[str, Mapping[str, Any]] | None = None,
    color_offset: int = 0,
) -> LoggedTrial:
    """Send every stream of one trial to ``recording`` columnarly on the reference-clock timeline.

    ``metadata`` are the trial's metadata records (``imulog.alignment`` is applied to IMU-clock channels,
    ``imulog.evaluation`` becomes the error report); ``channel_meta`` maps topic -> channel metadata (a
    ``clock`` key overrides the default clock rule, see :mod:`imulog.archive.clocks`). ``prefix`` (``/label``)
    places the whole trial under one entity subtree for overlays.
    """
    metadata = metadata or {}
    trial = LoggedTrial(label=label, prefix=prefix)
    imu_names = {t.split("/")[2] for t in (channel_meta or {}) if t.startswith("/imu/")}
    if getattr(streams, "ordered_for_viewer", False):  # read while logged (source.ArchiveStreams): keep it lazy
        ordered: Iterable[Any] = streams
    else:
        ordered = sorted(streams, key=_logging_rank)
        imu_names |= {s.name for s in ordered if isinstance(s, ImuStream)}
    clocks = ClockMap(metadata, channel_meta or {}, imu_names)
    logger = _Logger(
        recording,
        trial,
        clocks,
        color_offset,
        None,
        metadata.get("imulog.trajectory"),
        metadata.get("imulog.timing"),
        metadata=metadata,
    )
    recording.log(L.join(prefix, "/world"), rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for stream in ordered:  # intervals, then the cluster pose (the trajectories' reference), then the rest
        logger.log(stream)
    _log_legend(recording, trial, prefix)
    evaluations = [metadata[n] for n in ("imulog.evaluation", "imulog.orientation_evaluation") if n in metadata]
    if evaluations:  # the trajectories' and the orientation's (against poses): one report, both when both ran
        report = "\n\n".join(evaluation_markdown(record) for record in evaluations)
        recording.log(
            L.evaluation_entity(prefix), rr.TextDocument(report, media_type=rr.MediaType.MARKDOWN), static=True
        )
        trial.entities.append(Entity(L.evaluation_entity(prefix), "evaluation", "imulog.evaluation", 0))
        trial.has_evaluation = True
    if "imulog.metrics" in metadata:
        report = metrics_markdown(metadata["imulog.metrics"])
        recording.log(L.metrics_entity(prefix), rr.TextDocument(report, media_type=rr.MediaType.MARKDOWN), static=True)
        trial.entities.append(Entity(L.metrics_entity(prefix), "clinical_metrics", "imulog.metrics", 0))
    recording.log(
        L.info_entity(prefix),
        rr.TextDocument(info_markdown(label, metadata, clocks), media_type=rr.MediaType.MARKDOWN),
        static=True,
    )
    trial.entities.append(Entity(L.info_entity(prefix), "info", "", 0))
    trial.unaligned_imus = sorted(clocks.unaligned)
    return trial


__all__ = [
    "Entity",
    "LoggedTrial",
    "device_imu_of",
    "log_streams",
    "markdown_table",
    # moved to view/phase_colors.py and view/columns.py, importable here as before
    "FORCED",
    "FORCED_COLOR",
    "LOW_CONFIDENCE_COLOR",
    "MAX_LOGGED_PHASES",
    "MAX_NUMBERED_REPETITIONS",
    "REP_COLORS",
    "known_phase_colors",
    "numbered_phase_labels",
    "phase_color",
    "repetition_colors",
    "scalar_column",
]
