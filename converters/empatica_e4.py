"""Empatica E4 session folders (E4 connect "download session" zip, unpacked): one recording per folder.

Every signal file has the same two-line header (Empatica's "Data export" description)::

    1680686620.000000, 1680686620.000000, 1680686620.000000     (session start, Unix s, UTC, per column)
    32.000000, 32.000000, 32.000000                             (sample rate, Hz)
    -34,-23,45                                                  (samples)

Files: ``ACC.csv`` (x, y, z in 1/64 g, 32 Hz) -> ``/imu/e4`` in m/s^2; ``BVP.csv`` (photoplethysmograph, 64 Hz),
``EDA.csv`` (electrodermal activity, uS, 4 Hz), ``TEMP.csv`` (skin temperature, degC, 4 Hz), ``HR.csv`` (average
heart rate, bpm, 1 Hz, computed from BVP: starts about 10 s later) -> ``/signals/e4_<file>``; ``IBI.csv``
(first row ``start, IBI``; then the beat's offset from the start in s and the inter-beat interval in s) ->
``/signals/e4_ibi`` (irregular, one sample per beat); ``tags.csv`` (Unix s of each button press) ->
``/events/e4_tags``. Time is ns from the earliest start of the folder's files, so every file of the session is
on one time base (a file converted alone still reads its siblings' first lines for that origin).

Memory: each file in pieces of about 16 MB of text (:func:`iter_e4_file`), the whole-file ``convert`` being the
one-piece case: the header rows say start and rate, so nothing needs declaring; ``imulog convert`` streams one
large file (a week's ``ACC.csv``, about 280 MB); a session folder is converted file by file, whole (``tags.csv`` is
always one piece). A final row cut short is dropped with a warning (it was dropped silently before).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import G0, TableSpec, read_numeric, text_head_lines
from imulog.converters._lab import trial_start
from imulog.converters._pieces import PIECE_BYTES, iter_numeric
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Intervals, Recording, SignalStream

SIGNALS = {
    "ACC": (3, "1/64 g"),
    "BVP": (1, "nW"),
    "EDA": (1, "uS"),
    "TEMP": (1, "degC"),
    "HR": (1, "bpm"),
}
FILES = set(SIGNALS) | {"IBI", "TAGS"}
ACC_G_PER_COUNT = 1.0 / 64.0  # Empatica: ACC data in 1/64 g (range +-2 g)
_UNIX = re.compile(r"^\d{9,10}(\.\d*)?$")


def _kind(path: Path) -> str | None:
    stem = Path(path).stem.upper()
    return stem if Path(path).suffix.lower() == ".csv" and stem in FILES else None


def _first_cells(lines: list[str], row: int) -> list[str]:
    return [c.strip() for c in lines[row].split(",")] if len(lines) > row else []


def session_start(path: Path) -> float | None:
    """The Unix start (s) in the first row of an E4 file, None when it has none."""
    try:
        with open(path, "rb") as f:
            head = f.read(256)
    except OSError:
        return None
    lines = text_head_lines(head, 2) or []
    cells = _first_cells(lines, 0)
    if not cells or not _UNIX.match(cells[0]):
        return None
    return float(cells[0])


def folder_origin(path: Path) -> float:
    """The earliest start (Unix s) among the E4 files beside ``path``: the session's common time origin."""
    starts = [s for p in Path(path).parent.iterdir() if _kind(p) and _kind(p) != "TAGS" for s in [session_start(p)]]
    starts = [s for s in starts if s is not None]
    if not starts:
        raise ConversionError(path, "no E4 session start in the folder's files")
    return min(starts)


def read_e4_file(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file: :func:`iter_e4_file` as one piece."""
    (rec,) = iter_e4_file(path, options, piece_bytes=None)
    return rec


def iter_e4_file(
    path: Path, options: ConvertOptions | None = None, piece_bytes: int | None = PIECE_BYTES
) -> Iterator[Recording]:
    """One E4 file in pieces of about ``piece_bytes`` of text (None: one piece), rows read by
    :func:`~imulog.converters._pieces.iter_numeric`. The two header rows say the start and rate, so sample ``i``
    of the file is at ``start + i / rate`` in every piece; IBI beats are checked to increase across pieces; the
    device and trial records come with the first piece. ``tags.csv`` (a few button presses) is one piece."""
    path = Path(path)
    kind = _kind(path)
    if kind is None:
        raise ConversionError(path, "not an Empatica E4 file (ACC, BVP, EDA, HR, IBI, TEMP or tags .csv)")
    device = {
        "format": "empatica-e4",
        "model": "Empatica E4",
        "time_base": "ns from the session's earliest file start (Unix s, UTC)",
        "source": path.parent.name,
    }
    if kind == "TAGS":
        spec = TableSpec(path=path, delimiter=",", skip_lines=0, names=["tag_time"])
        t = read_numeric(spec).reshape(-1) if path.stat().st_size else np.zeros(0)
        siblings = [p for p in path.parent.iterdir() if _kind(p) not in (None, "TAGS")]
        origin_s = folder_origin(siblings[0]) if siblings else (float(t[0]) if len(t) else 0.0)
        t_ns = np.round((t - origin_s) * 1e9).astype(np.int64)
        rec = Recording(sources=[str(path)])
        rec.events.append(
            Intervals(
                topic="/events/e4_tags", start_ns=t_ns, end_ns=t_ns, labels=[f"tag {i + 1}" for i in range(len(t))]
            )
        )
        rec.metadata["imulog.device.e4"] = device
        yield rec
        return
    origin_s = folder_origin(path)
    with open(path, "rb") as f:
        head = f.read(4096)
    lines = text_head_lines(head, 3) or []
    start_cells = _first_cells(lines, 0)
    if not start_cells or not _UNIX.match(start_cells[0]):
        raise ConversionError(path, "first row is not the session start (Unix seconds)", line=1)
    start_s = float(start_cells[0])
    offset_ns = int(round((start_s - origin_s) * 1e9))
    if kind == "IBI":
        width, rate, names = 2, None, ["offset_s", "ibi_s"]
        spec = TableSpec(path=path, delimiter=",", skip_lines=1, names=names)
    else:
        width, unit = SIGNALS[kind]
        rate_cells = _first_cells(lines, 1)
        try:
            rate = float(rate_cells[0])
        except (IndexError, ValueError):
            raise ConversionError(path, "second row is not the sample rate (Hz)", line=2) from None
        if not 1e-3 <= rate <= 10_000:
            raise ConversionError(path, f"sample rate {rate:g} Hz is not plausible", line=2)
        if len(start_cells) != width:
            raise ConversionError(path, f"{len(start_cells)} columns, {kind}.csv has {width}", line=1)
        names = [f"{kind.lower()}_{a}" for a in "xyz"] if width == 3 else [kind.lower()]
        spec = TableSpec(path=path, delimiter=",", skip_lines=2, names=names)
        if kind == "ACC":
            device.update(rate_hz=rate, units="ACC 1/64 g (converted to m/s^2)")
    done = 0
    before: int | None = None
    for k, piece in enumerate(iter_numeric(spec, piece_bytes)):
        v = piece.values.reshape(-1, width)
        rec = Recording(sources=[str(path)], warnings=list(piece.warnings))
        if rate is None:  # IBI: the beat's offset from the start (s), the interval (s)
            t_ns = offset_ns + np.round(v[:, 0] * 1e9).astype(np.int64)
            d = np.diff(t_ns if before is None else np.concatenate([[before], t_ns]))
            if (d <= 0).any():
                i = int(np.nonzero(d <= 0)[0][0]) + (1 if before is None else 0)
                raise ConversionError(path, "beat time does not increase", line=piece.first_line + i)
            rec.signals.append(
                SignalStream(topic="/signals/e4_ibi", t_ns=t_ns, columns=["ibi"], units=["s"], values=v[:, 1:])
            )
        else:
            t_ns = offset_ns + np.round(np.arange(done, done + len(v)) * (1e9 / rate)).astype(np.int64)
            if kind == "ACC":
                # stored as the file's counts: (counts / 64) * g, the same double as counts * (1/64) * g (1/64 is exact)
                res = {"resolution": {"acc": {"divisor": 1.0 / ACC_G_PER_COUNT, "scale": G0}}}
                rec.imus.append(ImuStream(name="e4", t_ns=t_ns, acc=v * ACC_G_PER_COUNT * G0, meta={**device, **res}))
            else:
                rec.signals.append(
                    SignalStream(topic=f"/signals/e4_{kind.lower()}", t_ns=t_ns, columns=names, units=[unit], values=v)
                )
        if k == 0:
            rec.metadata["imulog.device.e4"] = dict(device)
            # start_time is the wall time of this file's first sample (the trial's time axis starts there); t_ns stay
            # on the session origin, so files converted one by one line up, and a folder's files merge to its earliest
            first_s = origin_s + (int(t_ns[0]) / 1e9 if len(t_ns) else 0.0)
            rec.metadata["imulog.trial"] = trial_start(
                datetime.fromtimestamp(first_s, tz=UTC), "E4 files' first row (Unix s)"
            )
        done += len(v)
        if len(t_ns):
            before = int(t_ns[-1])
        yield rec


class EmpaticaE4Converter(Converter):
    name = "empatica-e4"
    description = "Empatica E4 session folder (ACC 1/64 g, BVP, EDA, HR, IBI, TEMP, tags .csv; one trial per folder)"
    extensions = (".csv",)
    example = "imulog convert ../shared/data/devices/empatica_e4 -o e4"

    def sniff(self, path: Path, head: bytes) -> float:
        kind = _kind(path)
        if kind is None:
            return 0.0
        lines = text_head_lines(head, 3)
        if not lines:
            return 0.0
        first = _first_cells(lines, 0)
        if kind == "TAGS":
            return 0.6 if first and _UNIX.match(first[0]) else 0.0
        if kind == "IBI":
            return 0.9 if len(first) == 2 and _UNIX.match(first[0]) and first[1].upper() == "IBI" else 0.0
        width = SIGNALS[kind][0]
        second = _first_cells(lines, 1)
        ok = len(first) == width and all(_UNIX.match(c) for c in first) and len(second) == width
        return 0.9 if ok else 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).parent.name or "e4"

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_e4_file(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """One file in pieces of about 16 MB of text (see :func:`iter_e4_file`)."""
        return iter_e4_file(Path(path), options, piece_bytes=_pieces.PIECE_BYTES)


CONVERTER = EmpaticaE4Converter()
