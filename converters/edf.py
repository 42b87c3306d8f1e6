"""EDF, EDF+ and BDF recordings (European Data Format; BioSemi's 24-bit variant).

Layout (edfplus.info): a 256-byte ASCII header (version ``0`` or ``\\xffBIOSEMI``, patient, recording, start date
``dd.mm.yy``, start time ``hh.mm.ss``, header bytes, reserved ``EDF+C``/``EDF+D``/``24BIT``, number of data
records, record duration s, number of signals ``ns``), then ``ns`` x 256 bytes of per-signal fields (label 16,
transducer 80, physical dimension 8, physical min/max 8+8, digital min/max 8+8, prefiltering 80, samples per
record 8, reserved 32), then the data records: per signal its samples as little-endian int16 (BDF: int24).

Physical value = pmin + (digital - dmin) * (pmax - pmin) / (dmax - dmin) (the reference readers' scaling).
Channels are classified by label, transducer and physical dimension:

* accelerometer (``acc`` in label/transducer, dimension g, mg or m/s^2) and gyroscope (``gyr``, deg/s or rad/s)
  channels at one rate become one IMU per sensor (label without its axis suffix), in SI units;
* every other signal (EMG in V, anything else as its dimension says) goes to ``/analog/edf`` (one stream per sample
  rate: ``edf``, ``edf_<rate>hz``), values as physical, dimension as the unit (``uV``/``mV`` EMG converted to V);
* EDF+ annotations (``EDF Annotations``/``BDF Annotations``) become ``/events/edf`` (onset, duration, text); the
  first time-keeping annotation of each record gives its onset, so EDF+D (discontinuous) files keep their gaps.

Time: ns from the header's start date and time (device local time, zone unknown; EDF+ sub-second start from the
first record's onset). The file is memory-mapped and each channel decoded straight from the records; large files
convert piece by piece (:func:`iter_chunks`, whole records of about 4 M samples).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import datetime
from pathlib import Path

import numpy as np
from imulog.converters._common import sanitize_name, unit_factor
from imulog.converters._lab import trial_start
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import AnalogStream, ImuStream, Intervals, Recording

FIELDS = (
    ("label", 16),
    ("transducer", 80),
    ("dimension", 8),
    ("pmin", 8),
    ("pmax", 8),
    ("dmin", 8),
    ("dmax", 8),
    ("prefilter", 80),
    ("samples", 8),
    ("reserved", 32),
)
EMG_TO_V = {"v": 1.0, "mv": 1e-3, "uv": 1e-6, "µv": 1e-6, "μv": 1e-6, "nv": 1e-9}
_AXIS = re.compile(r"[\s_.:-]*(?:acc(?:el)?|gyr(?:o)?)?[\s_.:-]*\(?([xyz])\)?$", re.I)


def _ascii(raw: bytes) -> str:
    return raw.decode("latin-1").strip()


def _num(path: Path, text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ConversionError(path, f"header: {what} {text!r} is not a number") from None


def parse_header(path: Path, head: bytes) -> tuple[dict, list[dict]]:
    """(file fields, per-signal fields) of an EDF/BDF header; raises ConversionError on a malformed header."""
    if len(head) < 256:
        raise ConversionError(path, "file ends inside the 256-byte EDF header")
    bdf = head[:8] == b"\xffBIOSEMI"
    if not bdf and head[:8].strip() != b"0":
        raise ConversionError(path, f"version field {head[:8]!r} is neither EDF '0' nor BDF")
    ns = int(_num(path, _ascii(head[252:256]), "number of signals"))
    if not 0 < ns <= 4096:
        raise ConversionError(path, f"header: {ns} signals")
    info = {
        "bdf": bdf,
        "patient": _ascii(head[8:88]),
        "recording": _ascii(head[88:168]),
        "date": _ascii(head[168:176]),
        "time": _ascii(head[176:184]),
        "header_bytes": int(_num(path, _ascii(head[184:192]), "header bytes")),
        "reserved": _ascii(head[192:236]),
        "records": int(_num(path, _ascii(head[236:244]), "number of data records")),
        "duration_s": _num(path, _ascii(head[244:252]), "record duration"),
        "signals": ns,
    }
    if info["header_bytes"] != 256 * (ns + 1):
        raise ConversionError(path, f"header bytes {info['header_bytes']} != 256 * (1 + {ns} signals)")
    if len(head) < info["header_bytes"]:
        raise ConversionError(path, "file ends inside the signal headers")
    sigs: list[dict] = [{} for _ in range(ns)]
    off = 256
    for key, width in FIELDS:
        for i in range(ns):
            sigs[i][key] = _ascii(head[off + i * width : off + (i + 1) * width])
        off += width * ns
    for i, s in enumerate(sigs):
        for key in ("pmin", "pmax", "dmin", "dmax", "samples"):
            s[key] = _num(path, s[key], f"signal {i + 1} ({s['label']!r}) {key}")
        s["samples"] = int(s["samples"])
        if s["samples"] < 0 or (s["dmax"] == s["dmin"]):
            raise ConversionError(path, f"signal {i + 1} ({s['label']!r}): digital min == max or negative samples")
        s["annotations"] = s["label"] in ("EDF Annotations", "BDF Annotations")
    return info, sigs


def start_datetime(path: Path, info: dict) -> datetime:
    """The header's start; the 4-digit year from EDF+ ``Startdate dd-MMM-yyyy`` when present (else 85-99 -> 19xx)."""
    try:
        d, m, y = (int(x) for x in info["date"].split("."))
        hh, mm, ss = (int(x) for x in info["time"].split("."))
    except ValueError:
        raise ConversionError(path, f"header: bad start date/time {info['date']!r} {info['time']!r}") from None
    year = 1900 + y if y >= 85 else 2000 + y
    full = re.search(r"Startdate \d{2}-[A-Z]{3}-(\d{4})", info["recording"])
    if full:
        year = int(full.group(1))
    try:
        return datetime(year, m, d, hh, mm, ss)
    except ValueError:
        raise ConversionError(path, f"header: bad start date/time {info['date']!r} {info['time']!r}") from None


def parse_tals(raw: bytes) -> list[tuple[float, float, str]]:
    """The time-stamped annotation lists of one record: (onset s, duration s or 0, text); time-keeping ones have
    text ``""``."""
    out = []
    for tal in raw.split(b"\x00"):
        if not tal or tal[:1] not in (b"+", b"-"):
            continue
        parts = tal.split(b"\x14")
        head = parts[0].split(b"\x15")
        try:
            onset = float(head[0])
            dur = float(head[1]) if len(head) > 1 and head[1] else 0.0
        except ValueError:
            continue
        texts = [p.decode("utf-8", "replace") for p in parts[1:] if p]
        for t in texts or [""]:
            out.append((onset, dur, t))
    return out


def _sensor_key(label: str) -> tuple[str, str | None]:
    """(sensor name, axis) from a label like ``Acc X``, ``ACC_Y``, ``Sensor 1: Acc.Z``."""
    m = _AXIS.search(label)
    if m:
        return label[: m.start()].strip(" :_-."), m.group(1).lower()
    return label, None


def _kind(s: dict) -> str:
    text = f"{s['label']} {s['transducer']}".lower()
    dim = s["dimension"]
    if "acc" in text and unit_factor("acc", dim) is not None:
        return "acc"
    if "gyr" in text and unit_factor("gyr", dim) is not None:
        return "gyr"
    if "emg" in text and dim.strip().lower() in EMG_TO_V:
        return "emg"
    return "other"


CHUNK_SAMPLES = 4_000_000  # samples (all channels) per piece of the streaming convert


def iter_chunks(
    path: Path, options: ConvertOptions | None = None, max_samples: int | None = CHUNK_SAMPLES
) -> Iterator[Recording]:
    """The recording in pieces of whole data records of about ``max_samples`` samples (None: one piece)."""
    path = Path(path)
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(256)
        if len(head) == 256:
            ns = _ascii(head[252:256])
            n = int(ns) if ns.isdigit() else 0
            head += f.read(256 * min(n, 4096))
    info, sigs = parse_header(path, head)
    width = 3 if info["bdf"] else 2
    rec_samples = sum(s["samples"] for s in sigs)
    rec_bytes = rec_samples * width
    if rec_bytes <= 0:
        raise ConversionError(path, "data records hold no samples")
    available = (size - info["header_bytes"]) // rec_bytes
    warnings: list[str] = []
    n_rec = info["records"]
    if n_rec < 0 or n_rec > available:
        if n_rec >= 0:
            warnings.append(f"{path.name}: header declares {n_rec} data records, the file holds {available}")
        n_rec = available
    if n_rec == 0:
        raise ConversionError(path, "no complete data record")
    duration = info["duration_s"]
    if not duration > 0:
        raise ConversionError(path, f"header: record duration {duration} s (must be > 0)")
    mm = np.memmap(path, dtype=np.uint8, mode="r", offset=info["header_bytes"], shape=(n_rec, rec_bytes))
    offsets = np.concatenate([[0], np.cumsum([s["samples"] * width for s in sigs])])
    edf_plus = info["reserved"].startswith(("EDF+", "BDF+"))
    start = start_datetime(path, info)
    record_onset = np.arange(n_rec) * duration
    events: list[tuple[float, float, str]] = []
    for i, s in enumerate(sigs):
        if not s["annotations"]:
            continue
        block = mm[:, offsets[i] : offsets[i + 1]]
        for r in range(n_rec):
            tals = parse_tals(bytes(block[r]))
            keep = [t for t in tals if t[2]]
            if edf_plus and tals and not tals[0][2]:
                record_onset[r] = tals[0][0]
            events.extend(keep if i == next(k for k, x in enumerate(sigs) if x["annotations"]) else keep)
    sub = float(record_onset[0]) if edf_plus else 0.0
    record_ns = np.round((record_onset - sub) * 1e9).astype(np.int64)
    if (np.diff(record_ns) <= 0).any():
        r = int(np.argmax(np.diff(record_ns) <= 0)) + 1
        raise ConversionError(path, f"data record {r}: onset does not increase")

    data_idx = [i for i, s in enumerate(sigs) if not s["annotations"] and s["samples"] > 0]
    for i in data_idx:
        if sigs[i]["pmin"] == sigs[i]["pmax"]:
            warnings.append(
                f"{path.name}: signal {i + 1} ({sigs[i]['label']!r}, {sigs[i]['transducer'] or 'no transducer'}) "
                f"has physical min == max ({sigs[i]['pmin']:g}): every value reads as {sigs[i]['pmin']:g}"
            )

    def build(r0: int, r1: int) -> Recording:
        """Records r0..r1 as one Recording (events and warnings with the first)."""

        def values(i: int, factor: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
            """Times and physical values of signal ``i`` times a unit ``factor``, computed as the archive's
            counts formula gives them back: ``(digital - dmin) * (gain * factor) + pmin * factor``."""
            s = sigs[i]
            block = np.ascontiguousarray(mm[r0:r1, offsets[i] : offsets[i + 1]])
            if width == 2:
                dig = block.view("<i2").astype(np.float64).reshape(-1)
            else:
                b = block.reshape(-1, 3).astype(np.int32)
                v = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)
                dig = np.where(v >= 1 << 23, v - (1 << 24), v).astype(np.float64)
            gain = (s["pmax"] - s["pmin"]) / (s["dmax"] - s["dmin"])
            phys = (dig - s["dmin"]) * (gain * factor) + s["pmin"] * factor
            k = s["samples"]
            t = (
                record_ns[r0:r1, None] + np.round(np.arange(k) * (duration * 1e9 / k)).astype(np.int64)[None, :]
            ).reshape(-1)
            return t, phys

        rec = Recording(sources=[str(path)])
        used: set[int] = set()
        # IMUs: acc/gyr channels grouped by sensor name and rate, three axes each
        groups: dict[tuple[str, int], dict[str, dict[str, int]]] = {}
        for i in data_idx:
            kind = _kind(sigs[i])
            if kind in ("acc", "gyr"):
                sensor, axis = _sensor_key(sigs[i]["label"])
                g = groups.setdefault((sensor, sigs[i]["samples"]), {}).setdefault(kind, {})
                if axis is None or axis in g:
                    axis = "xyz"[len(g)] if len(g) < 3 else None
                if axis is not None:
                    g[axis] = i
        names: set[str] = set()
        for (sensor, _), kinds in groups.items():
            parts = {k: v for k, v in kinds.items() if sorted(v) == ["x", "y", "z"]}
            if not parts:
                continue
            name = sanitize_name(sensor).lower() or "imu"
            while name in names:
                name += "_"
            names.add(name)
            kw, t_ns, meta = {}, None, {"format": "edf", "source": path.name, "channels": {}}
            for kind, axes in parts.items():
                cols = []
                for a in "xyz":
                    t_ns, v = values(axes[a])
                    cols.append(v * unit_factor(kind, sigs[axes[a]]["dimension"]))
                    used.add(axes[a])
                    meta["channels"][f"{kind}.{a}"] = f"signal {axes[a] + 1}: {sigs[axes[a]]['label']}"
                kw[kind] = np.column_stack(cols)
            meta["rate_hz"] = sigs[next(iter(next(iter(parts.values())).values()))]["samples"] / duration
            rec.imus.append(ImuStream(name=name, t_ns=t_ns - 0, meta=meta, **kw))
        by_rate: dict[int, list[int]] = {}
        for i in data_idx:
            if i not in used:
                by_rate.setdefault(sigs[i]["samples"], []).append(i)
        labels_seen: dict[str, int] = {}
        for k, (spr, idx) in enumerate(sorted(by_rate.items(), key=lambda kv: -kv[0])):
            chans, units, cols, t_ns = [], [], [], None
            res: dict[str, list[float]] = {"shift": [], "scale": [], "offset": []}
            for i in idx:
                s = sigs[i]
                f = EMG_TO_V[s["dimension"].strip().lower()] if _kind(s) == "emg" else 1.0
                t_ns, v = values(i, f)
                # stored as the digital words: ((digital - dmin) * gain * f) + pmin * f (imulog.archive.numbers)
                res["shift"].append(-s["dmin"])
                res["scale"].append((s["pmax"] - s["pmin"]) / (s["dmax"] - s["dmin"]) * f)
                res["offset"].append(s["pmin"] * f)
                label = s["label"] or f"signal {i + 1}"
                if label in labels_seen or sum(x["label"] == s["label"] for x in sigs) > 1:
                    label = f"{label} {s['transducer']} #{i + 1}".strip()
                labels_seen[label] = i
                unit = "V" if _kind(s) == "emg" else s["dimension"]
                chans.append(label)
                units.append(unit)
                cols.append(v)
            name = "edf" if k == 0 else f"edf_{spr / duration:g}hz".replace(".", "_")
            rec.analogs.append(
                AnalogStream(
                    name,
                    t_ns,
                    chans,
                    units,
                    np.column_stack(cols),
                    meta={"rate_hz": spr / duration, "resolution": {"values": res}},
                )
            )
        if events and r0 == 0:
            ev = sorted(events)
            on = np.round((np.array([e[0] for e in ev]) - sub) * 1e9).astype(np.int64)
            end = on + np.round(np.array([e[1] for e in ev]) * 1e9).astype(np.int64)
            rec.events.append(Intervals("/events/edf", on, end, [e[2] for e in ev]))
        from datetime import timedelta

        rec.metadata["imulog.trial"] = trial_start(start + timedelta(seconds=sub), "EDF header start date/time")
        rec.metadata["imulog.device.edf"] = {
            "format": "bdf" if info["bdf"] else ("edf+" if edf_plus else "edf"),
            "variant": info["reserved"],
            "patient": info["patient"],
            "recording": info["recording"],
            "records": n_rec,
            "record_duration_s": duration,
            "signals": [
                {
                    k: s[k]
                    for k in (
                        "label",
                        "transducer",
                        "dimension",
                        "pmin",
                        "pmax",
                        "dmin",
                        "dmax",
                        "prefilter",
                        "samples",
                    )
                }
                for s in sigs
            ],
            "source": path.name,
        }
        if r0 == 0:
            rec.warnings.extend(warnings)
        return rec

    per = n_rec if max_samples is None else max(1, max_samples // rec_samples)
    for r0 in range(0, n_rec, per):
        yield build(r0, min(n_rec, r0 + per))


def read_edf(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file as one Recording."""
    return next(iter_chunks(path, options, max_samples=None))


class EdfConverter(Converter):
    name = "edf"
    description = "EDF/EDF+/BDF: acc/gyro channels -> IMUs (SI), EMG and others -> /analog/edf, annotations -> events"
    extensions = (".edf", ".bdf", ".rec")
    example = "imulog convert ../shared/data/devices/edf/trigno_emg.edf -o emg.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        if len(head) < 256:
            return 0.0
        if head[:8] == b"\xffBIOSEMI":
            return 0.97
        if head[:8] != b"0       ":
            return 0.0
        ok = head[252:256].strip().isdigit() and re.fullmatch(rb"\d\d\.\d\d\.\d\d", head[168:176]) is not None
        return 0.95 if ok else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_edf(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of whole data records for the streaming convert of large files."""
        return iter_chunks(Path(path), options)


CONVERTER = EdfConverter()
