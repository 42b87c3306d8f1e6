"""BIDS-motion recordings (BIDS 1.9+ ``motion`` data type): one ``*_tracksys-<name>_motion.tsv`` per tracking system.

Each ``<base>_motion.tsv`` (no header row, ``n/a`` = missing) is described by ``<base>_channels.tsv`` (``name``,
``component``, ``type``, ``tracked_point``, ``units``, optional ``sampling_frequency``) and ``<base>_motion.json``
(``SamplingFrequency``, ``TrackingSystemName``, ...). Channels become, by ``type`` and ``tracked_point``:

* ``ACCEL``/``GYRO``/``MAGN`` x, y, z -> ``/imu/<tracked point>`` in SI (units as written: m/s^2, g; rad/s, deg/s;
  uT, T, gauss);
* ``ORNT`` ``quat_w``..``quat_z`` -> ``/orientation/<tracked point>``; other ``ORNT`` (Euler angles) and any other
  type (``VEL``, ``ANGVEL``, ...) -> ``/signals/<tracksys>`` with their units;
* ``POS`` x, y, z -> ``/markers/<tracksys>`` (one marker per tracked point; m, cm or mm);
* ``LATENCY`` (s) is the time of each sample; without it sample k is at k / ``SamplingFrequency``.

The recording's ``*_events.tsv`` (same entities without ``tracksys``) becomes ``/events/bids`` (onset, duration,
``trial_type``), attached by the recording's first tracking system only, so that the systems of one recording
(grouped by :meth:`BidsConverter.recording_key`: the file name without ``tracksys``) merge into one trial. A
dataset folder therefore converts to one trial per recording (``imulog convert DATASET/ -o trials/``).

Memory: in pieces of about 16 MiB of text (:func:`iter_motion`; the whole file is the one-piece case), the rows
through the one text cutter (:func:`~imulog.converters._pieces.iter_numeric`, ``n/a`` read as a gap): a piece costs
a few times its text. The channels file and sidecar say every stream and its meta before the first row, so no first
pass is needed.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from imulog.converters._common import LENGTH_TO_M, check_increasing, sanitize_name, unit_factor
from imulog.converters._lab import orientation_stream
from imulog.converters._pieces import PIECE_BYTES, NumericPiece, iter_numeric
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Intervals, MarkerStream, Recording, SignalStream

MOTION = re.compile(
    r"^(?P<pre>sub-[A-Za-z0-9]+(?:_[a-z]+-[A-Za-z0-9]+)*?)_tracksys-(?P<sys>[A-Za-z0-9]+)(?P<post>(?:_[a-z]+-[A-Za-z0-9]+)*)_motion\.tsv$"
)
IMU_TYPES = {"ACCEL": "acc", "GYRO": "gyr", "MAGN": "mag"}
EXTRA_MAG = {"t": 1e6, "mt": 1e3, "nt": 1e-3}


def _rows(path: Path) -> list[dict[str, str]]:
    try:
        with open(path, newline="", encoding="utf-8") as f:
            return [
                {k.strip(): (v or "").strip() for k, v in r.items() if k} for r in csv.DictReader(f, delimiter="\t")
            ]
    except OSError as e:
        raise ConversionError(path, f"cannot read: {e.strerror}") from None


def recording_stem(path: Path) -> tuple[str, str] | None:
    """(recording key without ``tracksys``, tracking system) of a ``*_motion.tsv`` name, else None."""
    m = MOTION.match(Path(path).name)
    return (m.group("pre") + m.group("post"), m.group("sys")) if m else None


def _unit(path: Path, quantity: str, unit: str, channel: str) -> float:
    if quantity == "markers":
        u = unit.strip().lower()
        if u not in LENGTH_TO_M:
            raise ConversionError(path, f"POS unit {unit!r} is not m, cm or mm", column=channel)
        return LENGTH_TO_M[u]
    f = unit_factor(quantity, unit)
    if f is None and quantity == "mag":
        f = EXTRA_MAG.get(unit.strip().lower())
    if f is None:
        raise ConversionError(path, f"unknown {quantity} unit {unit!r}", column=channel)
    return f


def read_motion(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole recording: :func:`iter_motion` as one piece."""
    from imulog.converters._binary import concat_chunks

    return concat_chunks(iter_motion(path, options, piece_bytes=None))


def _tables(
    path: Path, chans: list[dict[str, str]], channels_file: str, piece_bytes: int | None
) -> Iterator[NumericPiece]:
    """The motion table (no header, ``n/a`` or empty = missing) in pieces of about ``piece_bytes`` of text cut after
    whole lines (None: the whole file), through the one text cutter (:func:`iter_numeric`): every cell may be a gap,
    a cut final row is dropped with a warning, a malformed row is named by its line."""
    from imulog.converters._table import TableSpec

    with open(path, "rb") as f:
        first = f.readline().rstrip(b"\r\n")
    columns = first.count(b"\t") + 1
    if first.strip() and columns != len(chans):
        raise ConversionError(path, f"{columns} columns, {channels_file} lists {len(chans)} channels", line=1)
    names = [c["name"] for c in chans]
    spec = TableSpec(path, "\t", 0, names, optional=set(range(len(names))))
    yield from iter_numeric(spec, piece_bytes, missing=b"n/a")


def iter_motion(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """One tracking system's recording in pieces of about ``piece_bytes`` of text (None: one piece); the channels
    and sidecars say every stream up front, the events come with the first piece."""
    path = Path(path)
    parts = recording_stem(path)
    if parts is None:
        raise ConversionError(path, "not a BIDS-motion file name (sub-<label>_..._tracksys-<label>_..._motion.tsv)")
    key, system = parts
    base = path.name[: -len("_motion.tsv")]
    ch_path = path.with_name(f"{base}_channels.tsv")
    if not ch_path.is_file():
        raise ConversionError(path, f"no {ch_path.name} beside it (channel names, types and units)")
    chans = _rows(ch_path)
    if not chans or "name" not in chans[0] or "type" not in chans[0]:
        raise ConversionError(ch_path, "needs the columns name and type")
    side: dict = {}
    js = path.with_name(f"{base}_motion.json")
    if js.is_file():
        try:
            side = json.loads(js.read_text())
        except ValueError as e:
            raise ConversionError(js, f"not JSON: {e}") from None
    types = [c["type"].upper() for c in chans]
    rate = side.get("SamplingFrequency")
    if not isinstance(rate, int | float):
        rate = next(
            (float(c["sampling_frequency"]) for c in chans if c.get("sampling_frequency", "n/a") != "n/a"), None
        )
    if "LATENCY" not in types and not rate:
        raise ConversionError(path, "no LATENCY channel and no SamplingFrequency: sample times unknown")
    before = None
    row0 = 0  # samples before the piece (a sample's index when the rate gives its time)
    for piece in _tables(path, chans, ch_path.name, piece_bytes):
        data = piece.values
        if "LATENCY" in types:
            j = types.index("LATENCY")
            f = unit_factor("time", chans[j].get("units", "s") or "s") or 1e9
            t = data[:, j]
            if not np.isfinite(t).all():
                bad = int(np.argmax(~np.isfinite(t)))
                raise ConversionError(
                    path, "missing LATENCY value", line=piece.first_line + bad, column=chans[j]["name"]
                )
            t_ns = np.round(t * f).astype(np.int64)
        else:
            t_ns = np.round(np.arange(row0, row0 + len(data)) * (1e9 / float(rate))).astype(np.int64)
        check_increasing(path, t_ns, piece.first_line, "latency", before=before)
        before = int(t_ns[-1]) if len(t_ns) else before
        rec = _motion_piece(path, system, chans, types, rate, side, data, t_ns)
        rec.sources = [str(path), str(ch_path)] + ([str(js)] if js.is_file() else [])
        rec.warnings += piece.warnings
        if row0 == 0:
            _attach_events(rec, path, key, system)
        row0 += len(data)
        yield rec
        del rec, piece, data  # not held while the next piece is read and parsed


def _motion_piece(
    path: Path, system: str, chans: list[dict[str, str]], types: list[str], rate, side: dict, data, t_ns
) -> Recording:
    """The streams of some rows of one tracking system's table, and its device record."""
    rec = Recording()
    imus: dict[str, dict[str, list]] = {}
    markers: dict[str, dict[str, int]] = {}
    quats: dict[str, dict[str, int]] = {}
    other: list[int] = []
    for j, c in enumerate(chans):
        typ, comp = types[j], c.get("component", "n/a").lower()
        point = c.get("tracked_point", "n/a")
        point = system if point in ("", "n/a") else point
        if typ in IMU_TYPES and comp in ("x", "y", "z"):
            imus.setdefault(point, {}).setdefault(IMU_TYPES[typ], [None, None, None])["xyz".index(comp)] = j
        elif typ == "POS" and comp in ("x", "y", "z"):
            markers.setdefault(point, {})[comp] = j
        elif typ == "ORNT" and comp in ("quat_w", "quat_x", "quat_y", "quat_z"):
            quats.setdefault(point, {})[comp] = j
        elif typ != "LATENCY":
            other.append(j)
    for point, groups in imus.items():
        kw = {}
        for q, idx in groups.items():
            if None in idx:
                other += [i for i in idx if i is not None]
                continue
            kw[q] = np.column_stack(
                [data[:, i] * _unit(path, q, chans[i].get("units", ""), chans[i]["name"]) for i in idx]
            )
        if kw:
            meta = {"format": "bids-motion", "tracking_system": system, "rate_hz": rate, "source": path.name}
            rec.imus.append(ImuStream(name=sanitize_name(point), t_ns=t_ns, meta=meta, **kw))
    for point, comps in quats.items():
        if len(comps) == 4:
            q = np.column_stack([data[:, comps[k]] for k in ("quat_w", "quat_x", "quat_y", "quat_z")])
            rec.signals.append(orientation_stream(sanitize_name(point), t_ns, q))
        else:
            other += list(comps.values())
    full = {p: c for p, c in markers.items() if len(c) == 3}
    other += [i for p, c in markers.items() if p not in full for i in c.values()]
    if full:
        labels = list(full)
        pos = np.stack(
            [
                np.column_stack(
                    [
                        data[:, full[p][a]]
                        * _unit(path, "markers", chans[full[p][a]].get("units", "m"), chans[full[p][a]]["name"])
                        for a in "xyz"
                    ]
                )
                for p in labels
            ],
            axis=1,
        )
        rec.markers.append(
            MarkerStream(
                name=sanitize_name(system),
                t_ns=t_ns,
                labels=labels,
                pos=pos,
                meta={"rate_hz": rate, "source": path.name},
            )
        )
    if other:
        other.sort()
        rec.signals.append(
            SignalStream(
                f"/signals/{sanitize_name(system)}",
                t_ns,
                [chans[i]["name"] for i in other],
                [chans[i].get("units", "") for i in other],
                data[:, other],
            )
        )
    if not rec.streams():
        raise ConversionError(path, "no channel to convert")
    rec.metadata[f"imulog.device.{sanitize_name(system)}"] = {
        "format": "bids-motion",
        "tracking_system": system,
        "sidecar": side,
        "source": path.name,
        **({"model": side["ManufacturersModelName"]} if "ManufacturersModelName" in side else {}),
        **({"serial": side["DeviceSerialNumber"]} if "DeviceSerialNumber" in side else {}),
    }
    return rec


def _attach_events(rec: Recording, path: Path, key: str, system: str) -> None:
    """The recording's ``_events.tsv`` as ``/events/bids``, attached by its first tracking system only."""
    systems = sorted(
        s for p in path.parent.glob("*_motion.tsv") if (r := recording_stem(p)) and r[0] == key for s in [r[1]]
    )
    ev = path.with_name(f"{key}_events.tsv")
    if not ev.is_file() or (systems and systems[0] != system):
        return
    rows = _rows(ev)
    try:
        on = np.array([float(r["onset"]) for r in rows])
        dur = np.array([0.0 if r.get("duration", "n/a") in ("n/a", "") else float(r["duration"]) for r in rows])
    except (KeyError, ValueError) as e:
        raise ConversionError(ev, f"bad onset or duration: {e}") from None
    if len(rows):
        order = np.argsort(on, kind="stable")
        start = np.round(on[order] * 1e9).astype(np.int64)
        end = start + np.round(np.maximum(dur[order], 0) * 1e9).astype(np.int64)
        labels = [rows[i].get("trial_type", "") or rows[i].get("value", "") for i in order]
        rec.events.append(Intervals("/events/bids", start, end, labels))
    rec.sources.append(str(ev))


class BidsConverter(Converter):
    name = "bids-motion"
    description = "BIDS-motion *_tracksys-*_motion.tsv (+ channels.tsv, motion.json, events.tsv); a dataset folder"
    extensions = (".tsv",)
    example = "imulog convert DATASET/ -o trials/   # one trial per recording"

    def sniff(self, path: Path, head: bytes) -> float:
        p = Path(path)
        if recording_stem(p) is None:
            return 0.0
        return 0.97 if p.with_name(p.name[: -len("_motion.tsv")] + "_channels.tsv").is_file() else 0.6

    def recording_key(self, path: Path) -> str | None:
        r = recording_stem(Path(path))
        return r[0] if r else None

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_motion(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        from imulog.converters import _pieces

        return iter_motion(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = BidsConverter()
