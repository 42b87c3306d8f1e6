"""Entity layout of an imulog trial in Rerun: which topic goes to which entity path, names and colours.

Time-series entities keep the archive topic as their path (``/imu/wrist/gyr`` for the gyroscope columns of
``/imu/wrist``, ``/derived/orientation/wrist`` for a derived signal), so what a user sees in the viewer is
named like what ``imulog info`` lists. Everything drawn in 3D lives under ``/world`` (the Vicon lab frame,
z up, metres):

========================================  ===================================================================
``/world/markers/{name}``                  marker positions (Points3D, one row per sample, labelled markers)
``/world/derived/vicon/cluster_pose``      cluster frame (Transform3D + axes, one row per sample)
``/world/imu_frames/{orientation topic}``  each orientation as a moving frame beside the cluster (Transform3D)
``/world/paths/{source}``                  whole trajectory as a line strip (static)
``/world/cursors/{source}``                current-sample cursor (Points3D, one row per sample)
========================================  ===================================================================

``{source}`` is ``vicon`` for the cluster origin and ``trajectory/{method}`` for IMU reconstructions.
With ``--overlay`` every path above is prefixed by ``/{trial label}``.
"""

from __future__ import annotations

import re

#: Name of the one timeline: reference (Vicon) clock, alignment applied, as a duration in ns.
TIMELINE = "reference_time"

#: Topics with a fixed meaning (docs/architecture.md).
CLUSTER_POSE_TOPIC = "/derived/vicon/cluster_pose"
VICON_ANGULAR_VELOCITY_TOPIC = "/derived/vicon/angular_velocity"
TRAJECTORY_PREFIX = "/derived/trajectory/"
ORIENTATION_PREFIX = "/derived/orientation/"
ACC_GLOBAL_PREFIX = "/derived/acc_global/"
STATIC_PREFIX = "/derived/static/"
STATIC_PREFIXES = (STATIC_PREFIX, "/derived/orientation_static/")
DERIVED = "/derived/"

INTERVAL_SHARE_SUFFIX = "/share"  # overview of a long interval channel: % of each time bucket it covers
PHASES_PREFIX = "/derived/phases/"
MOVEMENTS_PREFIX = "/derived/movements/"
METRICS_PREFIX = "/derived/metrics/"

#: R2G phase colours (reach, lift, return_bottle, return_hand), RGBA.
PHASE_COLORS: dict[str, int] = {
    "reach": 0x4C9BE8FF,
    "lift": 0xE8A33CFF,
    "return_bottle": 0x59B36BFF,
    "return_hand": 0xC35BD1FF,
    "static": 0x9E9E9EFF,
    "moving": 0xE5533DFF,
    "movement": 0xE5533DFF,
}

#: Distinct colours for trajectories, markers and overlaid trials, RGB.
PALETTE: list[tuple[int, int, int]] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (188, 189, 34),
    (23, 190, 207),
]
VICON_COLOR = (20, 20, 20)
AXIS_COLORS = [(230, 60, 60), (60, 180, 60), (60, 100, 230), (120, 120, 120)]

#: IMU sensor quantities: attribute of ImuStream -> (entity leaf, unit, column names).
IMU_QUANTITIES: dict[str, tuple[str, str, list[str]]] = {
    "acc": ("acc", "m/s²", ["x", "y", "z"]),
    "gyr": ("gyr", "rad/s", ["x", "y", "z"]),
    "mag": ("mag", "µT", ["x", "y", "z"]),
    "temperature": ("temperature", "°C", ["T"]),
}

_UNIT_PRETTY = {"m/s^2": "m/s²", "uT": "µT", "degC": "°C", "deg C": "°C", "": "1"}


def pretty_unit(unit: str) -> str:
    """Display form of a unit string (``m/s^2`` -> ``m/s²``; empty -> ``1``)."""
    return _UNIT_PRETTY.get(unit, unit)


def color(index: int) -> tuple[int, int, int]:
    """The ``index``-th palette colour (cycles)."""
    return PALETTE[index % len(PALETTE)]


def slug(text: str) -> str:
    """A safe single entity-path part for ``text`` (trial labels, method names)."""
    cleaned = re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_")
    return cleaned or "trial"


def join(prefix: str, path: str) -> str:
    """``prefix`` + ``path`` as an entity path (prefix is ``""`` or ``/label``)."""
    return f"{prefix}{path}" if prefix else path


def imu_entity(name: str, quantity: str, prefix: str = "") -> str:
    """Entity of one IMU quantity, e.g. ``/imu/wrist/gyr``."""
    return join(prefix, f"/imu/{name}/{IMU_QUANTITIES[quantity][0]}")


def imu_gyr_norm_entity(name: str, prefix: str = "") -> str:
    """Entity of the IMU gyroscope norm (rad/s)."""
    return join(prefix, f"/imu/{name}/gyr_norm")


def norm_entity(topic: str, prefix: str = "") -> str:
    """Entity of the Euclidean norm of a vector signal, e.g. ``/derived/vicon/angular_velocity/norm``."""
    return join(prefix, f"{topic}/norm")


def signal_entity(topic: str, prefix: str = "") -> str:
    """Entity of a generic signal / analog / interval channel: the topic itself."""
    return join(prefix, topic)


def state_entity(topic: str, prefix: str = "") -> str:
    """Entity of the state lane derived from a 0/1 mask signal such as ``/derived/static/{imu}``."""
    return join(prefix, f"{topic}/state")


def marker_entity(name: str, prefix: str = "") -> str:
    """Entity of a marker set in the 3D view."""
    return join(prefix, f"/world/markers/{name}")


def pose_entity(topic: str, prefix: str = "") -> str:
    """Entity of a rigid pose (Transform3D) in the 3D view, e.g. ``/world/derived/vicon/cluster_pose``."""
    return join(prefix, f"/world{topic}")


def imu_frame_entity(topic: str, prefix: str = "") -> str:
    """Entity of an orientation drawn as a moving frame, e.g. ``/world/imu_frames/derived/orientation/wrist``."""
    return join(prefix, f"/world/imu_frames{topic}")


def path_source(topic: str) -> str:
    """Short name of the trajectory source: ``vicon`` for the cluster pose, else ``trajectory/{method}``."""
    if topic == CLUSTER_POSE_TOPIC:
        return "vicon"
    if topic.startswith(TRAJECTORY_PREFIX):
        return "trajectory/" + topic[len(TRAJECTORY_PREFIX) :]
    return topic.strip("/").replace("/", "_")


def path_entity(topic: str, prefix: str = "") -> str:
    """Entity of the whole trajectory line strip (static)."""
    return join(prefix, f"/world/paths/{path_source(topic)}")


def cursor_entity(topic: str, prefix: str = "") -> str:
    """Entity of the current-sample cursor point of a trajectory."""
    return join(prefix, f"/world/cursors/{path_source(topic)}")


def error_entity(topic: str, prefix: str = "") -> str:
    """Entity of a trajectory's position error vs the Vicon reference (cm), e.g. ``/errors/trajectory/zupt``."""
    return join(prefix, f"/errors/{path_source(topic)}")


def phase_log_entity(topic: str, prefix: str = "") -> str:
    """Entity of the text log of a phases channel: one coloured row per phase, e.g. ``/derived/phases/wrist/log``."""
    return join(prefix, f"{topic}/log")


def evaluation_entity(prefix: str = "") -> str:
    """Entity of the evaluation (error) report text document."""
    return join(prefix, "/evaluation/report")


def metrics_entity(prefix: str = "") -> str:
    """Entity of the clinical metrics report text document (the ``imulog.metrics`` record)."""
    return join(prefix, "/metrics/report")


def info_entity(prefix: str = "") -> str:
    """Entity of the trial description text document."""
    return join(prefix, "/trial/info")


#: An error series counts as "large" (drawn on its own axis and hidden in 3D by default) when its 95th percentile
#: exceeds both this many times the best method's and :data:`LARGE_ERROR_MIN_CM`.
LARGE_ERROR_FACTOR = 10.0
LARGE_ERROR_MIN_CM = 10.0


def large_error_topics(scales_cm: dict[str, float]) -> set[str]:
    """Topics whose error (95th percentile, cm) would flatten the others' plot: e.g. DDI's metres of drift.

    The centimetre methods (ZUPT, optimized, ...) stay on one readable axis; uncorrected double integration, whose
    error grows without bound, goes to its own plot and is hidden in the 3D view until toggled on.
    """
    finite = {t: v for t, v in scales_cm.items() if v == v}
    if len(finite) < 2:
        return set()
    best = min(finite.values())
    limit = max(LARGE_ERROR_FACTOR * best, LARGE_ERROR_MIN_CM)
    return {t for t, v in finite.items() if v > limit}


def legend_entity(prefix: str = "") -> str:
    """Markdown legend of the 3D view: colour, error and default visibility of every trajectory."""
    return join(prefix, "/legend")
