"""Xsens MVN ``.mvnx`` (XML, version 4): segment poses, per-sensor orientation and free acceleration, joint angles.

Layout (namespace ``http://www.xsens.com/mvn/mvnx``)::

    <mvnx version="4">
      <mvn version="2021.0.1" build="..."/>
      <subject label="..." frameRate="60" segmentCount="23" recDate="Tue Mar 03 14:08:49.271 2020"
               recDateMSecsSinceEpoch="1583240929271" configuration="FullBody" ...>
        <segments><segment label="Pelvis" id="1"><points>...</points></segment>...</segments>
        <sensors><sensor label="Pelvis"/>...</sensors>
        <joints><joint label="jL5S1"><connector1>Pelvis/jL5S1</connector1>...</joint>...</joints>
        <frames segmentCount="23" sensorCount="17" jointCount="22">
          <frame time="0" tc="..." ms="..." type="identity|tpose|tpose-isb">...</frame>   (calibration poses)
          <frame time="0" index="0" tc="00:00:00:00" ms="1583240929271" type="normal">
            <orientation>q0 q1 q2 q3 ... (4 per segment, scalar first)</orientation>
            <position>x y z ... (3 per segment, m)</position>
            <sensorFreeAcceleration>... (3 per sensor, m/s^2, global frame, gravity removed)</sensorFreeAcceleration>
            <sensorMagneticField>... (3 per sensor, a.u.)</sensorMagneticField>
            <sensorOrientation>... (4 per sensor)</sensorOrientation>
            <jointAngle>... (3 per joint, deg, ZXY Euler)</jointAngle>
            ...

Becomes ``/poses/mvn_<segment>`` (position m + orientation), ``/orientation/mvn_<sensor>`` (sensor orientation) and
``/signals/mvn_<sensor>`` (free acceleration m/s^2, magnetic field a.u.), ``/signals/mvn_joint_angles`` (deg,
``<joint>_x,y,z``; ``jointAngleXZY`` -> ``/signals/mvn_joint_angles_xzy``). MVNX carries no raw accelerometer or
gyroscope samples, so there is no ``/imu`` stream (free acceleration is gravity-free and global: not a specific
force). Clock: the frame ``time`` attribute (ms from the start); ``recDateMSecsSinceEpoch`` (UTC) is the trial's
start, with the local offset found by comparing it with ``recDate`` (local time) when both are present.

Memory: in pieces of :data:`PIECE_FRAMES` frames (:func:`iter_mvnx`; the whole file is the one-piece case):
``xml.etree.ElementTree.iterparse`` streams the XML and each frame element is cleared and removed from ``<frames>``
once read, so memory holds one piece's arrays, not the document. XML safety: the standard library's expat parser
(2.4 or later: its amplification limit refuses "billion laughs" entity expansion with an XML error) never fetches
external entities or DTDs.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
from imulog.converters._binary import concat_chunks
from imulog.converters._common import sanitize_name
from imulog.converters._lab import orientation_stream, trial_start
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import PoseStream, Recording, SignalStream

# frame element -> (per what, width)
FRAME_FIELDS = {
    "orientation": ("segment", 4),
    "position": ("segment", 3),
    "sensorFreeAcceleration": ("sensor", 3),
    "sensorMagneticField": ("sensor", 3),
    "sensorOrientation": ("sensor", 4),
    "jointAngle": ("joint", 3),
    "jointAngleXZY": ("joint", 3),
}


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def local_offset(rec_date: str, utc: datetime) -> timezone | None:
    """The UTC offset of ``recDate`` (local time, ``Tue Mar 03 14:08:49.271 2020``) against the UTC epoch time."""
    for fmt in ("%a %b %d %H:%M:%S.%f %Y", "%a %b %d %H:%M:%S %Y"):
        try:
            local = datetime.strptime(rec_date.strip(), fmt)
        except ValueError:
            continue
        minutes = round((local - utc.replace(tzinfo=None)).total_seconds() / 900) * 15
        if abs(minutes) <= 14 * 60:
            return timezone(timedelta(minutes=minutes))
    return None


#: frames per piece when a file is converted in pieces (a full-body suit's frame holds about 460 values: ~15 MiB)
PIECE_FRAMES = 4096


@dataclass
class _Header:
    """What precedes the frames: root, ``<mvn>`` and ``<subject>`` attributes, segment/sensor/joint labels."""

    root: dict[str, str] = field(default_factory=dict)
    subject: dict[str, str] = field(default_factory=dict)
    mvn: dict[str, str] = field(default_factory=dict)
    labels: dict[str, list[str]] = field(default_factory=lambda: {"segment": [], "sensor": [], "joint": []})


@dataclass
class _Frames:
    """The frames read so far: the current piece's times and values, and what the whole file's checks need."""

    times: list[float] = field(default_factory=list)
    data: dict[str, list[np.ndarray]] = field(default_factory=lambda: {k: [] for k in FRAME_FIELDS})
    present: dict[str, int] = field(default_factory=dict)  # frames holding each field, over the file
    n: int = 0  # normal frames over the file
    last_ns: int | None = None
    bad_time: tuple[int, float] | None = None  # the first frame whose time does not increase
    fields: set[str] | None = None  # the fields of the first piece (every piece must hold the same)
    held: bool = False  # a whole-file check will fail: no more pieces, read on to the file's end for its error
    empty: bool = False


def read_mvnx(path: Path, *, names: dict[str, str] | None = None) -> Recording:
    """The whole file: :func:`iter_mvnx` in one piece."""
    return concat_chunks(iter_mvnx(path, names=names, piece_frames=None))


def iter_mvnx(
    path: Path, *, names: dict[str, str] | None = None, piece_frames: int | None = PIECE_FRAMES
) -> Iterator[Recording]:
    """The frames of an MVNX file in pieces of ``piece_frames`` (None: one piece), streamed by ``iterparse``: each
    frame element is cleared and dropped from ``<frames>`` once read, so memory holds one piece. Errors are the whole
    file's, in its order: a frame's own (values, time attribute) and XML errors where they occur; a time that does
    not increase, a field missing from some frames or frames without data stop the pieces and fail at the end."""
    path = Path(path)
    names = {k.upper(): v for k, v in (names or {}).items()}
    head, fr = _Header(), _Frames()
    stack: list[str] = []
    frames_el: ET.Element | None = None
    try:
        for event, el in ET.iterparse(path, events=("start", "end")):
            tag = _local(el.tag)
            if event == "start":
                stack.append(tag)
                if tag == "mvnx":
                    head.root = dict(el.attrib)
                elif tag == "subject":
                    head.subject = dict(el.attrib)
                elif tag == "mvn":
                    head.mvn = dict(el.attrib)
                elif tag == "frames":
                    frames_el = el
                continue
            stack.pop()
            parent = stack[-1] if stack else ""
            if tag in ("segment", "sensor", "joint") and parent in ("segments", "sensors", "joints"):
                head.labels[tag].append(el.get("label", f"{tag}{len(head.labels[tag]) + 1}"))
                el.clear()
            elif tag == "frame":
                if el.get("type", "normal") == "normal":
                    _read_frame(path, el, fr.n, head.labels, fr.times, fr.data, fr.present)
                    fr.n += 1
                    if piece_frames is not None and len(fr.times) >= piece_frames:
                        piece = _piece(path, head, fr, names)
                        if piece is not None:
                            yield piece
                el.clear()
                if frames_el is not None and parent == "frames":
                    frames_el.remove(el)  # the cleared frame too: <frames> never holds more than one
    except ET.ParseError as e:
        line = e.position[0] if getattr(e, "position", None) else None
        raise ConversionError(path, f"XML error: {e.msg if hasattr(e, 'msg') else e}", line=line) from None
    piece = _piece(path, head, fr, names) if fr.times else None
    if not head.subject:
        raise ConversionError(path, "no <mvnx> root with a <subject>: not an MVNX file")
    if fr.n == 0:
        raise ConversionError(path, 'no <frame type="normal"> elements')
    if fr.bad_time is not None:
        raise ConversionError(path, f"frame {fr.bad_time[0]}: time {fr.bad_time[1]} ms does not increase")
    for k in FRAME_FIELDS:
        if 0 < fr.present.get(k, 0) != fr.n:
            raise ConversionError(path, f"<{k}> is missing in {fr.n - fr.present[k]} of {fr.n} frames")
    if fr.empty or fr.held:
        raise ConversionError(path, "frames hold no position, orientation, sensor or joint data")
    if piece is not None:
        yield piece


def _piece(path: Path, head: _Header, fr: _Frames, names: dict[str, str]) -> Recording | None:
    """The frames gathered since the last piece as a Recording (None once a whole-file check is known to fail:
    the caller reads on for the file's first error); the piece's frames are dropped."""
    times, n = fr.times, len(fr.times)
    t_ns = np.round(np.asarray(times) * 1e6).astype(np.int64)
    full = t_ns if fr.last_ns is None else np.concatenate([[fr.last_ns], t_ns])
    bad = np.nonzero(np.diff(full) <= 0)[0]
    if len(bad) and fr.bad_time is None:
        i = int(bad[0]) + (0 if fr.last_ns is None else -1)  # index in this piece of the frame before
        fr.bad_time = (fr.n - n + i + 1, times[i + 1])
    fr.last_ns = int(t_ns[-1])
    fields = {k for k, v in fr.data.items() if v}
    if any(len(fr.data[k]) != n for k in fields) or (fr.fields is not None and fields != fr.fields):
        fr.held = True  # a field missing from some frames: the whole file's error names how many, at the end
    fr.fields = fields if fr.fields is None else fr.fields
    if not head.subject or fr.bad_time is not None:
        fr.held = True
    arrays = {k: np.stack(v) for k, v in fr.data.items() if v} if not fr.held else {}
    fr.times = []
    fr.data = {k: [] for k in FRAME_FIELDS}
    if fr.held:
        return None
    rec = _recording(path, head, t_ns, arrays, names)
    if not rec.streams():
        fr.empty = fr.held = True
        return None
    return rec


def _recording(
    path: Path, head: _Header, t_ns: np.ndarray, arrays: dict[str, np.ndarray], names: dict[str, str]
) -> Recording:
    """The streams and records of ``len(t_ns)`` frames (``arrays``: field -> (frames, values))."""
    labels, subject, n_frames = head.labels, head.subject, len(t_ns)
    rec = Recording(sources=[str(path)])

    def stream_name(label: str) -> str:
        return sanitize_name(names.get(label.upper(), f"mvn_{label}"))

    if "position" in arrays:
        pos = arrays["position"].reshape(n_frames, -1, 3)
        ori = arrays["orientation"].reshape(n_frames, -1, 4) if "orientation" in arrays else None
        for i, seg in enumerate(labels["segment"]):
            rec.poses.append(
                PoseStream(f"/poses/mvn_{sanitize_name(seg)}", t_ns, pos[:, i], None if ori is None else ori[:, i])
            )
    for i, sensor in enumerate(labels["sensor"]):
        name = stream_name(sensor)
        cols, units, vals = [], [], []
        for key, prefix, unit in (
            ("sensorFreeAcceleration", "free_acc", "m/s^2"),
            ("sensorMagneticField", "mag", "a.u."),
        ):
            if key in arrays:
                cols += [f"{prefix}_{a}" for a in "xyz"]
                units += [unit] * 3
                vals.append(arrays[key].reshape(n_frames, -1, 3)[:, i])
        if vals:
            rec.signals.append(SignalStream(f"/signals/{name}", t_ns, cols, units, np.hstack(vals)))
        if "sensorOrientation" in arrays:
            rec.signals.append(
                orientation_stream(name, t_ns, arrays["sensorOrientation"].reshape(n_frames, -1, 4)[:, i])
            )
        rec.metadata[f"imulog.device.{name}"] = {
            "format": "mvnx",
            "model": "Xsens MVN sensor",
            "label": sensor,
            "rate_hz": float(subject["frameRate"]) if subject.get("frameRate") else None,
            "source": path.name,
            "units": {"free_acc": "m/s^2 (global frame, gravity removed)", "mag": "a.u.", "orientation": "w,x,y,z"},
        }
    for key, topic in (("jointAngle", "/signals/mvn_joint_angles"), ("jointAngleXZY", "/signals/mvn_joint_angles_xzy")):
        if key in arrays and labels["joint"]:
            cols = [f"{j}_{a}" for j in labels["joint"] for a in "xyz"]
            rec.signals.append(SignalStream(topic, t_ns, cols, ["deg"] * len(cols), arrays[key]))
    rec.metadata["imulog.device.mvn"] = {
        "format": "mvnx",
        "model": "Xsens MVN",
        "mvnx_version": head.root.get("version", ""),
        "mvn_version": head.mvn.get("version", ""),
        "subject": {k: v for k, v in subject.items() if k != "originalFilename"},
        "segments": labels["segment"],
        "sensors": labels["sensor"],
        "joints": labels["joint"],
        "rate_hz": float(subject["frameRate"]) if subject.get("frameRate") else None,
        "time": "frame time attribute (ms from the start)",
        "joint_angles": "deg, ZXY Euler (jointAngle) and XZY (jointAngleXZY)",
        "source": path.name,
    }
    epoch = subject.get("recDateMSecsSinceEpoch", "")
    if re.fullmatch(r"\d+", epoch):
        utc = datetime.fromtimestamp(int(epoch) // 1000, tz=UTC) + timedelta(milliseconds=int(epoch) % 1000)
        zone = local_offset(subject.get("recDate", ""), utc)
        start = utc.astimezone(zone) if zone is not None else utc
        rec.metadata["imulog.trial"] = trial_start(start, f"{path.name}: subject recDateMSecsSinceEpoch and recDate")
    return rec


def _read_frame(
    path: Path,
    el: ET.Element,
    index: int,
    labels: dict[str, list[str]],
    times: list[float],
    data: dict[str, list[np.ndarray]],
    present: dict[str, int],
) -> None:
    where = f"frame {index} (time {el.get('time')!r})"
    try:
        times.append(float(el.get("time", "")))
    except ValueError:
        raise ConversionError(path, f"{where}: time attribute is not a number") from None
    for child in el:
        key = _local(child.tag)
        if key not in FRAME_FIELDS:
            continue
        per, width = FRAME_FIELDS[key]
        try:
            v = np.array((child.text or "").split(), dtype=np.float64)
        except ValueError:
            raise ConversionError(path, f"{where}: <{key}> holds a value that is not a number") from None
        expected = width * len(labels[per])
        if len(v) != expected:
            raise ConversionError(
                path, f"{where}: <{key}> has {len(v)} values, expected {expected} ({width} per {per})"
            )
        data[key].append(v)
        present[key] = present.get(key, 0) + 1


class MvnxConverter(Converter):
    name = "mvnx"
    description = "Xsens MVN .mvnx (XML v4): segment poses, sensor orientation + free acceleration, joint angles"
    extensions = (".mvnx",)
    example = "imulog convert walk.mvnx -o walk.mcap"
    fixed_pieces = True  # pieces of PIECE_FRAMES frames: freed temporaries are reused

    def sniff(self, path: Path, head: bytes) -> float:
        text = head[:4096].decode("utf-8", "replace")
        return 0.95 if "<mvnx" in text else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        return read_mvnx(Path(path), names=options.extra.get("names"))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of :data:`PIECE_FRAMES` frames (see :func:`iter_mvnx`)."""
        options = options or ConvertOptions()
        return iter_mvnx(Path(path), names=options.extra.get("names"), piece_frames=PIECE_FRAMES)


CONVERTER = MvnxConverter()
