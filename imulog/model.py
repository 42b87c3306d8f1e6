"""In-memory trial model shared by converters, the archive, the simulator and the steps.

Everything here is plain numpy in SI units on a device clock. Converters produce these objects
(without any MCAP knowledge); :mod:`imulog.archive` writes and reads them; :mod:`imulog.process`
functions take their arrays.

Conventions
-----------
* time stamps: ``t_ns`` int64 nanoseconds on the device's own clock, strictly increasing;
* accelerometer m/s^2, gyroscope rad/s, magnetometer uT, temperature degC, positions m;
* quaternions are scalar-first ``(w, x, y, z)`` and rotate sensor-frame vectors into the global frame;
* missing samples are NaN (never zero), with an explicit validity mask where the schema has one.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, TypeVar

from imulog._lazy import LazyModule

np = LazyModule("numpy", __name__)  # imported on first use: imulog info never needs numpy

SCHEMA_VERSION = 1

# Topic prefixes used by converters and the archive.
IMU_TOPIC = "/imu/{name}"
MARKER_TOPIC = "/markers/{name}"
ANALOG_TOPIC = "/analog/{name}"
DERIVED_PREFIX = "/derived/"


def _as_time(t_ns: Any) -> np.ndarray:
    t = np.ascontiguousarray(t_ns, dtype=np.int64)
    if t.ndim != 1:
        raise ValueError(f"t_ns must be 1-D, got shape {t.shape}")
    return t


def _as_columns(values: Any, n: int, width: int | None, what: str) -> np.ndarray:
    a = np.ascontiguousarray(values, dtype=np.float64)
    if a.ndim == 1 and width in (None, 1):
        a = a.reshape(-1, 1)
    if a.ndim != 2 or a.shape[0] != n or (width is not None and a.shape[1] != width):
        expected = f"({n}, {width if width is not None else 'C'})"
        raise ValueError(f"{what} must have shape {expected}, got {a.shape}")
    return a


@dataclass
class ImuStream:
    """One inertial sensor. ``acc``/``gyr``/``mag`` are (N, 3) or None; ``temperature`` (N,) or None."""

    name: str
    t_ns: np.ndarray
    acc: np.ndarray | None = None  # m/s^2
    gyr: np.ndarray | None = None  # rad/s
    mag: np.ndarray | None = None  # uT
    temperature: np.ndarray | None = None  # degC
    frame_id: str = ""
    meta: dict[str, Any] = field(default_factory=dict)  # model, serial, rate_hz, ranges, source

    def __post_init__(self) -> None:
        self.t_ns = _as_time(self.t_ns)
        n = len(self.t_ns)
        for attr in ("acc", "gyr", "mag"):
            value = getattr(self, attr)
            if value is not None:
                setattr(self, attr, _as_columns(value, n, 3, f"ImuStream {self.name!r} {attr}"))
        if self.temperature is not None:
            self.temperature = _as_columns(self.temperature, n, 1, "temperature")[:, 0].copy()
        if self.frame_id == "":
            self.frame_id = self.name

    @property
    def topic(self) -> str:
        return IMU_TOPIC.format(name=self.name)

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass
class MarkerStream:
    """Optical markers: ``pos`` (N, M, 3) in m, NaN where ``valid`` (N, M) is False."""

    name: str
    t_ns: np.ndarray
    labels: list[str]
    pos: np.ndarray
    valid: np.ndarray | None = None
    frame_id: str = "world"
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t_ns = _as_time(self.t_ns)
        self.labels = [str(label) for label in self.labels]
        pos = np.ascontiguousarray(self.pos, dtype=np.float64)
        if pos.shape != (len(self.t_ns), len(self.labels), 3):
            raise ValueError(
                f"MarkerStream {self.name!r} pos must have shape (N, M, 3) = "
                f"({len(self.t_ns)}, {len(self.labels)}, 3), got {pos.shape}"
            )
        if len(set(self.labels)) != len(self.labels):
            raise ValueError(f"MarkerStream {self.name!r} has duplicated marker labels")
        if self.valid is None:
            self.valid = np.all(np.isfinite(pos), axis=2)
        self.valid = np.ascontiguousarray(self.valid, dtype=bool)
        pos[~self.valid] = np.nan
        self.pos = pos

    @property
    def topic(self) -> str:
        return MARKER_TOPIC.format(name=self.name)

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass
class AnalogStream:
    """Analog device channels (EMG, force plates...): ``values`` (N, C) with one unit per channel."""

    name: str
    t_ns: np.ndarray
    channel_names: list[str]
    units: list[str]
    values: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t_ns = _as_time(self.t_ns)
        self.values = _as_columns(self.values, len(self.t_ns), len(self.channel_names), f"AnalogStream {self.name!r}")
        if len(self.units) != len(self.channel_names):
            raise ValueError(
                f"AnalogStream {self.name!r}: {len(self.units)} units for {len(self.channel_names)} channels"
            )

    @property
    def topic(self) -> str:
        return ANALOG_TOPIC.format(name=self.name)

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass
class SignalStream:
    """Generic named scalar columns (derived signals): ``values`` (N, C), one unit per column."""

    topic: str
    t_ns: np.ndarray
    columns: list[str]
    units: list[str]
    values: np.ndarray
    frame_id: str = ""
    attrs: dict[str, str] = field(default_factory=dict)  # extra channel metadata (e.g. a trajectory's checks)

    def __post_init__(self) -> None:
        self.t_ns = _as_time(self.t_ns)
        self.values = _as_columns(self.values, len(self.t_ns), len(self.columns), f"SignalStream {self.topic!r}")
        if len(self.units) != len(self.columns):
            raise ValueError(f"SignalStream {self.topic!r}: {len(self.units)} units for {len(self.columns)} columns")

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass
class Intervals:
    """Labelled intervals or instantaneous events (start == end), e.g. phases or C3D events."""

    topic: str
    start_ns: np.ndarray
    end_ns: np.ndarray
    labels: list[str]
    task_index: np.ndarray | None = None  # e.g. repetition number, -1 when not applicable

    def __post_init__(self) -> None:
        self.start_ns = _as_time(self.start_ns)
        self.end_ns = _as_time(self.end_ns)
        n = len(self.start_ns)
        if len(self.end_ns) != n or len(self.labels) != n:
            raise ValueError(f"Intervals {self.topic!r}: start, end and labels differ in length")
        if np.any(self.end_ns < self.start_ns):
            raise ValueError(f"Intervals {self.topic!r}: an interval ends before it starts")
        self.labels = [str(label) for label in self.labels]
        if self.task_index is None:
            self.task_index = np.full(n, -1, dtype=np.int64)
        self.task_index = np.ascontiguousarray(self.task_index, dtype=np.int64)

    def __len__(self) -> int:
        return len(self.start_ns)


@dataclass
class PoseStream:
    """Rigid poses for 3D views: ``position`` (N, 3) m, ``orientation`` (N, 4) w,x,y,z."""

    topic: str
    t_ns: np.ndarray
    position: np.ndarray
    orientation: np.ndarray | None = None
    frame_id: str = "world"
    precision: str = ""  # "float32": stored at float32 (derived poses, docs/schemas.md); "" at the source's resolution

    def __post_init__(self) -> None:
        self.t_ns = _as_time(self.t_ns)
        n = len(self.t_ns)
        self.position = _as_columns(self.position, n, 3, f"PoseStream {self.topic!r} position")
        if self.orientation is None:
            self.orientation = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        self.orientation = _as_columns(self.orientation, n, 4, f"PoseStream {self.topic!r} orientation")

    def __len__(self) -> int:
        return len(self.t_ns)


Stream = ImuStream | MarkerStream | AnalogStream | SignalStream | Intervals | PoseStream


@dataclass
class Recording:
    """Everything a converter read from one set of source files: the raw content of one trial.

    ``metadata`` maps MCAP metadata record names (``imulog.trial``, ``imulog.device.<name>``,
    ``imulog.anthropometrics``) to flat string->JSON-able dicts. ``sources`` are the original files
    to attach byte for byte.
    """

    imus: list[ImuStream] = field(default_factory=list)
    markers: list[MarkerStream] = field(default_factory=list)
    analogs: list[AnalogStream] = field(default_factory=list)
    signals: list[SignalStream] = field(default_factory=list)
    events: list[Intervals] = field(default_factory=list)
    poses: list[PoseStream] = field(default_factory=list)
    metadata: dict[str, dict[str, Any]] = field(default_factory=dict)
    sources: list[str] = field(default_factory=list)
    # one-line notes for the user: rows dropped, units assumed, implausible values (``imulog convert`` prints them
    # and records them in ``imulog.conversion``); never errors, which are raised as ConversionError
    warnings: list[str] = field(default_factory=list)

    def streams(self) -> list[Stream]:
        return [*self.imus, *self.markers, *self.analogs, *self.signals, *self.events, *self.poses]

    def merge(self, other: Recording) -> Recording:
        """Combine two recordings of one trial (e.g. an IMU file and a Vicon file); topics must not clash."""
        merged = Recording(
            imus=[*self.imus, *other.imus],
            markers=[*self.markers, *other.markers],
            analogs=[*self.analogs, *other.analogs],
            signals=[*self.signals, *other.signals],
            events=[*self.events, *other.events],
            poses=[*self.poses, *other.poses],
            metadata={**self.metadata},
            sources=[*self.sources, *other.sources],
            warnings=[*self.warnings, *other.warnings],
        )
        for key, value in other.metadata.items():
            merged.metadata[key] = {**merged.metadata.get(key, {}), **value}
        topics = [s.topic for s in merged.streams()]
        clashes = sorted({t for t in topics if topics.count(t) > 1})
        if clashes:
            raise ValueError(f"two inputs provide the same channel(s): {', '.join(clashes)}")
        return merged


def concat_samples(parts: list[Any]) -> Any:
    """Consecutive pieces of one stream as one: per-sample arrays joined in order, the rest from the last piece."""
    last = parts[-1]
    fields = {}
    for f in dataclasses.fields(last):
        value = getattr(last, f.name)
        if isinstance(value, np.ndarray) and value.ndim >= 1 and len(value) == len(last.t_ns):
            value = np.concatenate([getattr(p, f.name) for p in parts])
        fields[f.name] = value
    return type(last)(**fields)


P = TypeVar("P")


def first_pieces(pieces: Iterator[P], rows: int, size: Callable[[P], int]) -> tuple[list[P], int]:
    """Read ahead: the first pieces of ``pieces`` that hold at least ``rows`` rows (all of them, when they hold
    fewer; ``size`` counts a piece's rows), and how many rows they hold. The rest stays in ``pieces``."""
    ahead: list[P] = []
    count = 0
    for piece in pieces:
        ahead.append(piece)
        count += size(piece)
        if count >= rows:
            break
    return ahead, count


def take_samples(stream: Any, index: np.ndarray) -> Any:
    """The samples ``index`` of a stream with per-sample ``t_ns`` (every per-sample array indexed; the same type,
    names and metadata), e.g. to decimate a channel or keep part of it."""
    fields = {}
    for f in dataclasses.fields(stream):
        value = getattr(stream, f.name)
        if isinstance(value, np.ndarray) and value.ndim >= 1 and len(value) == len(stream.t_ns):
            value = value[index]
        fields[f.name] = value
    return type(stream)(**fields)


#: reserved ``Recording.metadata`` name in the first piece of a recording given in pieces (``Converter.iter_chunks``):
#: what the whole recording holds, known before its first piece is written, so that the streaming writer's time axis
#: and channel records equal the whole-file ones: ``{"spans": {topic: [first_ns, last_ns]}, "meta": {topic: meta}}``
#: (docs/converters.md, "Piece-wise conversion"); never written as a record, dropped when pieces are joined
PIECES_RECORD = "imulog.pieces"
