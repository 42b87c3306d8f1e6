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
The file is parsed incrementally (``iterparse``), frames are cleared once read.

Memory: one piece; ``xml.etree.ElementTree.iterparse`` streams the XML and clears each frame, so memory holds the
arrays, not the document (an MVN capture is a lab session).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
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


def read_mvnx(path: Path, *, names: dict[str, str] | None = None) -> Recording:
    path = Path(path)
    names = {k.upper(): v for k, v in (names or {}).items()}
    root_attrs: dict[str, str] = {}
    subject: dict[str, str] = {}
    mvn: dict[str, str] = {}
    labels: dict[str, list[str]] = {"segment": [], "sensor": [], "joint": []}
    times: list[float] = []
    data: dict[str, list[np.ndarray]] = {k: [] for k in FRAME_FIELDS}
    present: dict[str, int] = {}
    n_frames = 0
    stack: list[str] = []
    try:
        for event, el in ET.iterparse(path, events=("start", "end")):
            tag = _local(el.tag)
            if event == "start":
                stack.append(tag)
                if tag == "mvnx":
                    root_attrs = dict(el.attrib)
                elif tag == "subject":
                    subject = dict(el.attrib)
                elif tag == "mvn":
                    mvn = dict(el.attrib)
                continue
            stack.pop()
            parent = stack[-1] if stack else ""
            if tag in ("segment", "sensor", "joint") and parent in ("segments", "sensors", "joints"):
                labels[tag].append(el.get("label", f"{tag}{len(labels[tag]) + 1}"))
                el.clear()
            elif tag == "frame":
                if el.get("type", "normal") == "normal":
                    _read_frame(path, el, n_frames, labels, times, data, present)
                    n_frames += 1
                el.clear()
    except ET.ParseError as e:
        line = e.position[0] if getattr(e, "position", None) else None
        raise ConversionError(path, f"XML error: {e.msg if hasattr(e, 'msg') else e}", line=line) from None
    if not subject:
        raise ConversionError(path, "no <mvnx> root with a <subject>: not an MVNX file")
    if n_frames == 0:
        raise ConversionError(path, 'no <frame type="normal"> elements')
    t_ns = np.round(np.asarray(times) * 1e6).astype(np.int64)
    bad = np.nonzero(np.diff(t_ns) <= 0)[0]
    if len(bad):
        raise ConversionError(path, f"frame {int(bad[0]) + 1}: time {times[int(bad[0]) + 1]} ms does not increase")
    rec = Recording(sources=[str(path)])
    arrays = {k: np.stack(v) for k, v in data.items() if v and len(v) == n_frames}
    for k, v in data.items():
        if v and len(v) != n_frames:
            raise ConversionError(path, f"<{k}> is missing in {n_frames - len(v)} of {n_frames} frames")

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
    if not rec.streams():
        raise ConversionError(path, "frames hold no position, orientation, sensor or joint data")
    rec.metadata["imulog.device.mvn"] = {
        "format": "mvnx",
        "model": "Xsens MVN",
        "mvnx_version": root_attrs.get("version", ""),
        "mvn_version": mvn.get("version", ""),
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

    def sniff(self, path: Path, head: bytes) -> float:
        text = head[:4096].decode("utf-8", "replace")
        return 0.95 if "<mvnx" in text else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        return read_mvnx(Path(path), names=options.extra.get("names"))


CONVERTER = MvnxConverter()
