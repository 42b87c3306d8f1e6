"""The default Rerun blueprint of an imulog trial (or of several overlaid trials).

Layout (views only appear when the trial has data for them)::

    +-------------------------------------+------------------------------+
    | |ω|: IMU gyroscope vs Vicon (rad/s) |                              |
    | acceleration (m/s²)                 |  3D: markers, cluster frame, |
    | orientation quaternion (1)          |  trajectories + cursors      |
    +-------------------------------------+------------------------------+
    | state timeline: phases (reach 3, rep 3)               | phase log  |
    | state timeline: static/moving, movements, activity    | (coloured) |
    +-------------------------------------------------------+------------+
    tabs beside the overview: raw IMU, derived signals, errors & metrics, trial info
"""

from __future__ import annotations

from collections.abc import Sequence

import rerun as rr
import rerun.blueprint as rrb

from imulog.view import layout as L
from imulog.view.streams import LoggedTrial


def _paths(trials: Sequence[LoggedTrial], *roles: str) -> list[str]:
    return [e.path for t in trials for e in t.by_role(*roles)]


def _time_axis(trials: Sequence[LoggedTrial]) -> rrb.TimeAxis | None:
    """X axis over the whole trial, linked across all time-series views."""
    lo = [e.t_min_ns for t in trials for e in t.entities if e.t_min_ns is not None]
    hi = [e.t_max_ns for t in trials for e in t.entities if e.t_max_ns is not None]
    if not lo:
        return None
    view = rr.TimeRange(
        start=rr.TimeRangeBoundary.absolute(nanos=int(min(lo))), end=rr.TimeRangeBoundary.absolute(nanos=int(max(hi)))
    )
    return rrb.TimeAxis(view_range=view)


def _series(
    name: str, paths: list[str], axis: rrb.TimeAxis | None, axis_y: rrb.ScalarAxis | None = None
) -> rrb.TimeSeriesView | None:
    if not paths:
        return None
    return rrb.TimeSeriesView(origin="/", contents=paths, name=name, axis_x=axis, axis_y=axis_y)


def large_error_topics_of(trials: Sequence[LoggedTrial]) -> set[str]:
    """Trajectory topics whose error would flatten the centimetre methods (see :func:`layout.large_error_topics`)."""
    hidden: set[str] = set()
    for t in trials:
        hidden |= L.large_error_topics({e.topic: e.scale for e in t.by_role("error") if e.scale is not None})
    return hidden


def _stack(views: list, kind: type = rrb.Vertical, **kwargs) -> rrb.Container | None:
    views = [v for v in views if v is not None]
    if not views:
        return None
    return kind(*views, **kwargs)


def _state_views(trials: Sequence[LoggedTrial], axis: rrb.TimeAxis | None) -> rrb.Container | rrb.View | None:
    """Phases in their own state timeline (lanes ``reach 3`` and ``rep 3``) beside the phase log, above the
    static/moving, movement and activity lanes, so phases are never scrolled out of sight."""
    phases = _paths(trials, "phases")
    others = _paths(trials, "static_state", "intervals")
    logs = _paths(trials, "phase_log")
    shares = _series(
        "Time in intervals per bucket (%): long recording overview", _paths(trials, "interval_share"), axis
    )
    if shares is not None:  # thousands of intervals: their share per bucket, lanes only inside the window
        lanes = [v for v in (_state_views_of(phases, others, logs, axis), shares) if v is not None]
        return lanes[0] if len(lanes) == 1 else rrb.Vertical(*lanes)
    return _state_views_of(phases, others, logs, axis)


def _state_views_of(
    phases: list[str], others: list[str], logs: list[str], axis: rrb.TimeAxis | None
) -> rrb.Container | rrb.View | None:
    """The state lanes: phases (and their log) above the other interval lanes; only the others without phases."""
    if not phases:
        return (
            rrb.StateTimelineView(origin="/", contents=others, name="Static intervals", time_view=axis)
            if others
            else None
        )
    lanes: list = [
        rrb.StateTimelineView(origin="/", contents=phases, name="Phases: label and repetition", time_view=axis)
    ]
    if others:
        lanes.append(
            rrb.StateTimelineView(
                origin="/", contents=others, name="Static intervals, movements, activity", time_view=axis
            )
        )
    left = lanes[0] if len(lanes) == 1 else rrb.Vertical(*lanes, row_shares=[1, 1])
    if not logs:
        return left
    columns = rrb.TextLogColumns(
        timeline_columns=[rrb.encodings.TimelineColumn(timeline=L.TIMELINE)],
        text_log_columns=[
            rrb.encodings.TextLogColumn("body"),
            rrb.encodings.TextLogColumn("entitypath", visible=False),
            rrb.encodings.TextLogColumn("loglevel", visible=False),
        ],
    )
    log = rrb.TextLogView(origin="/", contents=logs, name="Phase log (colour = phase)", columns=columns)
    return rrb.Horizontal(left, log, column_shares=[3, 1])


def build_blueprint(trials: LoggedTrial | Sequence[LoggedTrial]) -> rrb.Blueprint:
    """Default blueprint for what :func:`imulog.view.streams.log_streams` sent (one or several trials)."""
    if isinstance(trials, LoggedTrial):
        trials = [trials]
    axis = _time_axis(trials)

    omega = _series(
        "|ω| IMU gyroscope vs Vicon angular velocity (rad/s)", _paths(trials, "gyr_norm", "vicon_omega_norm"), axis
    )
    acc_global = _paths(trials, "acc_global")  # gravity-free, global frame: preferred over raw when present
    acc = (
        _series("Acceleration, gravity removed, global frame (m/s²)", acc_global, axis)
        if acc_global
        else _series("Acceleration, sensor frame (m/s²)", _paths(trials, "imu_acc"), axis)
    )
    orientation = _series("Orientation quaternion w,x,y,z (1)", _paths(trials, "orientation"), axis)
    signals = _stack([omega, acc, orientation])

    hidden = large_error_topics_of(trials)
    spatial_paths = _paths(trials, "markers", "pose", "imu_frame", "path", "cursor")
    spatial = None
    if spatial_paths:
        contents = [f"{t.prefix}/world/**" for t in trials]
        overrides = {
            e.path: rrb.EntityBehavior(visible=False)
            for t in trials
            for e in t.by_role("path", "cursor")
            if e.topic in hidden
        }
        spatial = rrb.Spatial3DView(
            origin="/",
            contents=contents,
            name="3D: markers, cluster, IMU frames, trajectories (m)",
            overrides=overrides or None,
        )
        legend = _paths(trials, "legend")
        if legend:
            spatial = rrb.Vertical(
                spatial, rrb.TextDocumentView(origin="/", contents=legend, name="Legend"), row_shares=[4, 1]
            )

    states = _state_views(trials, axis)

    top = _stack([signals, spatial], rrb.Horizontal, column_shares=[3, 2] if signals and spatial else None)
    overview = _stack([top, states], rrb.Vertical, row_shares=[3, 1.6] if top and states else None, name="Overview")

    tabs: list = []
    if overview is not None:
        tabs.append(overview)
    raw = [
        _series("Accelerometer (m/s²)", _paths(trials, "imu_acc"), axis) if acc_global else None,
        _series("Gyroscope (rad/s)", _paths(trials, "imu_gyr"), axis),
        _series("Magnetometer (µT)", _paths(trials, "imu_mag"), axis),
        _series("Temperature (°C)", _paths(trials, "imu_temperature"), axis),
        _series("Analog channels", _paths(trials, "analog"), axis),
    ]
    raw_tab = _stack(raw, rrb.Vertical, name="Raw IMU & analog")
    if raw_tab is not None:
        tabs.append(raw_tab)
    derived = [
        _series("Vicon angular velocity (rad/s)", _paths(trials, "vicon_angular_velocity"), axis),
        _series("Trajectories x,y,z (m)", _paths(trials, "trajectory_signal"), axis),
        _series("Static mask (1 = static)", _paths(trials, "static_signal"), axis),
        *[_series(e.topic, [e.path], axis) for t in trials for e in t.by_role("signal")],
    ]
    derived_tab = _stack(derived, rrb.Vertical, name="Derived signals")
    if derived_tab is not None:
        tabs.append(derived_tab)
    error_views: list = []
    if any(t.has_evaluation for t in trials):
        error_views.append(rrb.TextDocumentView(origin="/", contents=_paths(trials, "evaluation"), name="Errors"))
    if _paths(trials, "clinical_metrics"):
        error_views.append(
            rrb.TextDocumentView(origin="/", contents=_paths(trials, "clinical_metrics"), name="Clinical metrics")
        )
    errors = [e for t in trials for e in t.by_role("error")]
    readable = [e for e in errors if e.topic not in hidden]
    top_cm = max((e.scale for e in readable if e.scale is not None), default=None)
    error_series = [
        _series(
            "IMU trajectory error vs Vicon (cm)",
            [e.path for e in readable],
            axis,
            rrb.ScalarAxis(range=(0.0, 1.25 * top_cm)) if top_cm else None,
        ),
        _series("Uncorrected methods: error vs Vicon (cm)", [e.path for e in errors if e.topic in hidden], axis),
        _series("Metrics", _paths(trials, "metric"), axis),
    ]
    error_views.append(_stack(error_series, rrb.Vertical))
    error_tab = _stack(error_views, rrb.Horizontal, name="Errors & metrics")
    if error_tab is not None:
        tabs.append(error_tab)
    events = _paths(trials, "events")
    if events:
        tabs.append(rrb.TextLogView(origin="/", contents=events, name="Events"))
    tabs.append(rrb.TextDocumentView(origin="/", contents=_paths(trials, "info"), name="Trial info"))

    return rrb.Blueprint(
        rrb.Tabs(*tabs, active_tab=0),
        rrb.TimePanel(timeline=L.TIMELINE),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        auto_views=False,
        auto_layout=False,
    )
