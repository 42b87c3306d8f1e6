"""C3D content to model streams, a range of frames at a time (:mod:`imulog.converters.c3d` reads the ranges).

:func:`plan` decides from the header and parameters alone what the whole file gives (topics, labels, units, rates,
the ``resolution`` hints, events, the device record), so every range of frames makes the same streams with the same
``meta``; :func:`piece` turns one range's decoded data (:func:`imulog.converters.c3d_data.decode`) into a Recording,
and :class:`Tally` gathers what only the whole file tells (markers never valid, unmeasured points at the origin) for
the warnings of the last piece. Time on the capture clock: point frame ``k`` at ``round((first + k) / rate * 1e9)``
ns, analog sample ``j`` at ``round((first + j / ratio) / rate * 1e9)`` ns (``ratio`` = analog rate / point rate).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters.c3d_data import Layout
from imulog.converters.c3d_imus import C3dImu, find_imus, imu_meta, imu_streams, sample_rows
from imulog.converters.errors import ConversionError

from imulog.model import PIECES_RECORD, AnalogStream, Intervals, MarkerStream, Recording, SignalStream
from imulog.numeric import finite_rows

LENGTH_TO_M = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}
MODEL_OUTPUT_GROUPS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS")
OUTPUTS_TOPIC = "/vicon/model_outputs"


def _param(params: dict, group: str, name: str, default: Any = None) -> Any:
    try:
        return params[group][name]["value"]
    except KeyError:
        return default


def _labels(params: dict, group: str, n: int) -> list[str]:
    labels = list(_param(params, group, "LABELS", []) or [])
    if len(labels) < n:
        labels += list(_param(params, group, "LABELS2", []) or [])
    labels = [str(x).strip() for x in labels[:n]]
    labels += [f"{group.lower()}_{i + 1}" for i in range(len(labels), n)]
    seen: dict[str, int] = {}
    out = []
    for lab in labels:  # C3D allows repeated or blank labels: make them unique, keep the original order
        lab = lab or "unnamed"
        if lab in seen:
            seen[lab] += 1
            lab = f"{lab}#{seen[lab]}"
        else:
            seen[lab] = 1
        out.append(lab)
    return out


def _position_step(params: dict, unit: str) -> float | None:
    """Metres per count of an integer C3D (``POINT:SCALE`` > 0, finite): positions are then ``counts * step`` and
    the archive stores the file's int16 words (:mod:`imulog.archive.numbers`); None for a float C3D."""
    scale = _param(params, "POINT", "SCALE")
    step = float(scale[0]) if scale is not None and len(scale) else 0.0
    return step * LENGTH_TO_M[unit] if step > 0 and np.isfinite(step) else None


def _analog_words(params: dict, n_ch: int, lay: Layout) -> tuple[np.ndarray, np.ndarray] | None:
    """(shift, scale) per channel when the analogs are the file's words, so that values = ``(counts + shift) *
    scale`` (shift = -ANALOG:OFFSET, scale = GEN_SCALE x SCALE) and the archive gives them back exactly: an
    integer C3D with finite, non-zero scales and finite offsets. A float C3D's analogs keep float64."""
    if lay.word == 4:
        return None

    def per_channel(key: str, default: float) -> np.ndarray:
        out = np.full(n_ch, default)
        given = _param(params, "ANALOG", key)
        given = np.asarray([] if given is None else given, dtype=np.float64).reshape(-1)[:n_ch]
        out[: len(given)] = given
        return out

    off = per_channel("OFFSET", 0.0)
    step = per_channel("GEN_SCALE", 1.0)[0] * per_channel("SCALE", 1.0)
    if not (np.isfinite(step).all() and (step != 0).all() and np.isfinite(off).all()):
        return None
    return -off, step


def _events(params: dict, name: str) -> Intervals | None:
    """``EVENT:TIMES`` (minutes, seconds; float32) with ``CONTEXTS`` + ``LABELS`` as labels, in time order."""
    used = int((_param(params, "EVENT", "USED", [0]) or [0])[0])
    if used <= 0:
        return None
    times = np.asarray(_param(params, "EVENT", "TIMES"), dtype=np.float64).reshape(2, -1)[:, :used]
    seconds = times[0] * 60.0 + times[1]
    ev_labels = [str(x).strip() for x in (_param(params, "EVENT", "LABELS", []) or [])][:used]
    contexts = [str(x).strip() for x in (_param(params, "EVENT", "CONTEXTS", []) or [])][:used]
    ev_labels += [""] * (used - len(ev_labels))
    contexts += [""] * (used - len(contexts))
    full = [f"{ctx} {lab}".strip() for ctx, lab in zip(contexts, ev_labels, strict=True)]
    order = np.argsort(seconds, kind="stable")
    t_ev = np.round(seconds[order] * 1e9).astype(np.int64)
    return Intervals(topic=f"/events/{name}", start_ns=t_ev, end_ns=t_ev, labels=[full[i] for i in order])


@dataclass
class C3dPlan:
    """What the whole file gives, decided from its header and parameters (every piece keeps to it)."""

    path: Path
    name: str
    lay: Layout
    rate: float  # point rate, Hz
    unit: str  # POINT:UNITS
    labels: list[str]
    marker_idx: list[int]
    out_idx: list[int]
    pos_step: float | None  # metres per count (integer files)
    a_rate: float
    a_labels: list[str]
    a_units: list[str]
    a_words: tuple[np.ndarray, np.ndarray] | None  # (shift, scale) of the analog words
    events: Intervals | None
    meta: dict[str, Any]  # the device record
    imus: list[C3dImu] = field(default_factory=list)  # IMUs among the analogs (imulog's naming and units)
    analog_idx: list[int] = field(default_factory=list)  # the analog columns that stay /analog/NAME
    imu_spans: dict[str, list[int]] = field(default_factory=dict)  # IMU -> [first, last] sample ns (whole file)
    warnings: list[str] = field(default_factory=list)  # what the plan saw (IMU-like analogs in other units)

    def frame_times(self, lo: int, hi: int) -> np.ndarray:
        """ns of point frames ``[lo, hi)``."""
        return np.round((self.lay.first + np.arange(lo, hi)) * (1e9 / self.rate)).astype(np.int64)

    def analog_times(self, lo: int, hi: int) -> np.ndarray:
        """ns of the analog samples of frames ``[lo, hi)``."""
        r = self.lay.ratio
        return np.round(
            (self.lay.first + np.arange(lo * r, hi * r) / (self.a_rate / self.rate)) * (1e9 / self.rate)
        ).astype(np.int64)

    def marker_meta(self) -> dict[str, Any]:
        res = {"resolution": {"pos": {"scale": self.pos_step}}} if self.pos_step is not None else {}
        return {"rate_hz": self.rate, "units": self.unit, "source": self.path.name, **res}

    def analog_meta(self) -> dict[str, Any]:
        hint = {}
        if self.a_words is not None:
            k = self.analog_idx
            hint = {
                "resolution": {"values": {"shift": self.a_words[0][k].tolist(), "scale": self.a_words[1][k].tolist()}}
            }
        return {"rate_hz": self.a_rate, "source": self.path.name, **hint}

    def imu_meta(self, imu: C3dImu) -> dict[str, Any]:
        return imu_meta(imu, {"rate_hz": self.a_rate, "source": self.path.name})

    def declaration(self) -> dict[str, Any]:
        """What the first piece declares (:data:`imulog.model.PIECES_RECORD`): each stream's first and last time and
        its final ``meta``, known from the header and parameters."""
        n = self.lay.frames
        spans: dict[str, list[int]] = {}
        meta: dict[str, dict[str, Any]] = {}
        if n and self.marker_idx:
            spans[f"/markers/{self.name}"] = [int(self.frame_times(0, 1)[0]), int(self.frame_times(n - 1, n)[0])]
            meta[f"/markers/{self.name}"] = self.marker_meta()
        if n and self.out_idx:
            spans[OUTPUTS_TOPIC] = spans.get(f"/markers/{self.name}") or [
                int(self.frame_times(0, 1)[0]),
                int(self.frame_times(n - 1, n)[0]),
            ]
        if n and self.analog_idx:
            t = self.analog_times(0, 1)[:1].tolist() + self.analog_times(n - 1, n)[-1:].tolist()
            spans[f"/analog/{self.name}"] = t
            meta[f"/analog/{self.name}"] = self.analog_meta()
        for imu in self.imus:
            if imu.name in self.imu_spans:
                spans[f"/imu/{imu.name}"] = list(self.imu_spans[imu.name])
                meta[f"/imu/{imu.name}"] = self.imu_meta(imu)
        if self.events is not None:
            spans[self.events.topic] = [int(self.events.start_ns.min()), int(self.events.end_ns.max())]
        return {"spans": spans, "meta": meta}


def plan(path: Path, name: str, header: dict, params: dict, lay: Layout) -> C3dPlan:
    """The :class:`C3dPlan` of a file from ezc3d's (or imulog's) ``header`` and ``params`` and its data layout."""
    rate = float(header["points"]["frame_rate"])
    rate_param = _param(params, "POINT", "RATE")
    if rate_param is not None and len(rate_param):
        rate = float(rate_param[0])
    if not (rate > 0 and np.isfinite(rate)):
        raise ConversionError(path, f"point rate {rate!r} is not positive")
    units_list = _param(params, "POINT", "UNITS", ["mm"]) or ["mm"]
    unit = str(units_list[0]).strip(" \x00") or "mm"
    n_points = lay.n_points if lay.frames else 0
    labels: list[str] = []
    marker_idx: list[int] = []
    out_idx: list[int] = []
    pos_step = None
    meta: dict[str, Any] = {"format": "c3d", "source": path.name, "rate_hz": rate, "first_frame": lay.first}
    if n_points:
        if unit not in LENGTH_TO_M:
            raise ConversionError(path, f"unknown POINT:UNITS {unit!r}")
        labels = _labels(params, "POINT", n_points)
        outputs = set()
        for grp in MODEL_OUTPUT_GROUPS:
            outputs.update(str(x).strip() for x in (_param(params, "POINT", grp, []) or []))
        marker_idx = [i for i, lab in enumerate(labels) if lab not in outputs]
        out_idx = [i for i, lab in enumerate(labels) if lab in outputs]
        if marker_idx:
            pos_step = _position_step(params, unit)
            meta.update(marker_units=unit, markers=len(marker_idx))
    a_rate, a_labels, a_units, a_words = 0.0, [], [], None
    n_ch = lay.n_analog if lay.frames and lay.ratio else 0
    if n_ch:
        a_rate = float((_param(params, "ANALOG", "RATE", [0.0]) or [0.0])[0]) or rate
        a_labels = _labels(params, "ANALOG", n_ch)
        given = list(_param(params, "ANALOG", "UNITS", []) or [])
        a_units = [str(u).strip() for u in given[:n_ch]] + [""] * max(0, n_ch - len(given))
        a_words = _analog_words(params, n_ch, lay)
        meta.update(analog_rate_hz=a_rate, analog_channels=n_ch)
    imus, analog_idx, imu_warnings = find_imus(path.name, a_labels, a_units)
    if imus:
        meta["imus"] = [imu.name for imu in imus]
    events = _events(params, name)
    if events is not None:
        meta["events"] = len(events)
    if not (marker_idx or out_idx or n_ch or events is not None):
        raise ConversionError(path, "C3D file holds no points and no analog data")
    return C3dPlan(
        path,
        name,
        lay,
        rate,
        unit,
        labels,
        marker_idx,
        out_idx,
        pos_step,
        a_rate,
        a_labels,
        a_units,
        a_words,
        events,
        meta,
        imus,
        analog_idx,
        warnings=imu_warnings,
    )


@dataclass
class Tally:
    """What the pieces so far showed: markers valid at least once, unmeasured points at the origin."""

    ever_valid: np.ndarray | None = None
    zero_samples: int = 0
    zero_markers: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)

    def add(self, valid: np.ndarray, zeros: np.ndarray) -> None:
        any_valid, any_zero = valid.any(axis=0), zeros.any(axis=0)
        self.ever_valid = any_valid if self.ever_valid is None else self.ever_valid | any_valid
        self.zero_markers = any_zero if self.zero_markers is None else self.zero_markers | any_zero
        self.zero_samples += int(zeros.sum())

    def warnings(self, p: C3dPlan) -> list[str]:
        """The whole file's warnings about its markers (for the last piece)."""
        if self.ever_valid is None:
            return []
        out = []
        if self.zero_samples:  # the C3D guide's invalid point: X = Y = Z = 0, written without the -1 residual word
            out.append(
                f"{p.path.name}: marker set {p.name!r}: {self.zero_samples} sample(s) of "
                f"{int(self.zero_markers.sum())} marker(s) at exactly (0, 0, 0) with no residual (not measured: "
                "the C3D convention for an invalid point) stored as gaps"
            )
        labels = [p.labels[i] for i in p.marker_idx]
        never = [lab for j, lab in enumerate(labels) if not self.ever_valid[j]]
        if len(never) == len(labels):
            out.append(f"{p.path.name}: marker set {p.name!r}: all {len(labels)} markers are invalid in every frame")
        elif never:
            shown = ", ".join(never[:5]) + (" ..." if len(never) > 5 else "")
            out.append(
                f"{p.path.name}: marker set {p.name!r}: {len(never)} of {len(labels)} markers never valid ({shown})"
            )
        return out


def piece(p: C3dPlan, data: dict[str, Any], lo: int, tally: Tally) -> Recording:
    """Frames ``[lo, lo + n)`` decoded (:func:`imulog.converters.c3d_data.decode`) as a Recording of ``p``'s streams."""
    points = data["points"]  # (4, M, n)
    n = points.shape[2]
    rec = Recording(sources=[str(p.path)])
    t_ns = p.frame_times(lo, lo + n)
    if p.marker_idx or p.out_idx:
        meta_points = data["meta_points"]
        residuals = meta_points["residuals"][0]
        no_camera = ~np.asarray(meta_points["camera_masks"]).any(axis=0).T
        xyz = np.transpose(points[:3], (2, 1, 0)).astype(np.float64)  # (n, M, 3)
        valid = finite_rows(xyz) & (residuals.T >= 0)
        unmeasured_origin = valid & (residuals.T == 0) & no_camera & (xyz == 0).all(axis=2)
        if p.marker_idx:
            zeros = unmeasured_origin[:, p.marker_idx]
            valid[:, p.marker_idx] &= ~zeros
            tally.add(valid[:, p.marker_idx], zeros)
            pos = xyz[:, p.marker_idx, :]
            if p.pos_step is not None:  # the words of an integer file: counts x metres per count
                with np.errstate(invalid="ignore"):
                    pos = np.rint(pos / abs(p.lay.scale)) * p.pos_step
            else:
                pos = pos * LENGTH_TO_M[p.unit]
            rec.markers.append(
                MarkerStream(
                    name=p.name,
                    t_ns=t_ns,
                    labels=[p.labels[i] for i in p.marker_idx],
                    pos=pos,
                    valid=valid[:, p.marker_idx],
                    meta=p.marker_meta(),
                )
            )
        if p.out_idx:
            cols, units, vals = [], [], []
            for i in p.out_idx:
                for k, ax in enumerate("XYZ"):
                    cols.append(f"{p.labels[i]}.{ax}")
                    units.append("")
                    vals.append(np.where(valid[:, i], xyz[:, i, k], np.nan))
            rec.signals.append(
                SignalStream(topic=OUTPUTS_TOPIC, t_ns=t_ns, columns=cols, units=units, values=np.column_stack(vals))
            )
    if p.a_labels:
        values = data["analogs"][0].T.astype(np.float64)
        if p.a_words is not None:  # the file's words again (within a thousandth of a count), as the archive keeps them
            shift, scale = p.a_words
            values = (np.rint(values / scale - shift) + shift) * scale
        t_analog = p.analog_times(lo, lo + n)
        if p.analog_idx:
            k = p.analog_idx
            rec.analogs.append(
                AnalogStream(
                    name=p.name,
                    t_ns=t_analog,
                    channel_names=[p.a_labels[i] for i in k],
                    units=[p.a_units[i] for i in k],
                    values=values if len(k) == len(p.a_labels) else values[:, k],
                    meta=p.analog_meta(),
                )
            )
        for imu in imu_streams(p.imus, t_analog, values, {"rate_hz": p.a_rate, "source": p.path.name}):
            rec.imus.append(imu)
    if lo == 0 and p.events is not None:
        rec.events.append(p.events)
    return rec


def device_records(p: C3dPlan) -> dict[str, dict[str, Any]]:
    """The device records of every piece: the C3D's (``imulog.device.NAME``) and each IMU's found among its analogs."""
    out = {f"imulog.device.{p.name}": dict(p.meta)}
    for imu in p.imus:
        out[f"imulog.device.{imu.name}"] = {"format": "c3d", **p.imu_meta(imu)}
    return out


def imu_spans(p: C3dPlan, decoded) -> dict[str, list[int]]:
    """IMU -> [first, last] time (ns) of its samples over the whole file, from ``decoded`` ((first frame, data) of
    every range of frames, in order): a piece's IMU streams leave out the rows without a sample, so the spans the
    first piece declares come from the data, not the header."""
    first: dict[str, int] = {}
    last: dict[str, int] = {}
    for lo, data in decoded:
        values = data["analogs"][0].T
        t = p.analog_times(lo, lo + data["points"].shape[2])
        for imu in p.imus:
            rows = np.flatnonzero(sample_rows(imu, values))
            if len(rows):
                first.setdefault(imu.name, int(t[rows[0]]))
                last[imu.name] = int(t[rows[-1]])
    return {n: [first[n], last[n]] for n in first}


def first_piece_metadata(p: C3dPlan, rec: Recording, pieces: bool) -> None:
    """The device record (every piece), and for the first of several pieces the declaration."""
    rec.metadata.update(device_records(p))
    if pieces:
        rec.metadata[PIECES_RECORD] = p.declaration()
