"""Older Genea ``.bin`` recordings (Unilever Discover / Activinsights Genea, the binary format before GENEActiv).

Layout (GGIRread's ``readGenea.R``, read as documentation of the format, and checked byte by byte on GGIRread's
real ``genea_testfile.bin``, kept as ``tests/data/genea_testfile.bin.xz``)::

    GENEA/1.00\\r\\n                                  format and version
    Serial-Number:01275\\r\\n ... Key:Value\\r\\n        header lines (Accel-Offsets, Accel-Gains, Sample-Rate...)
    \\r\\n                                            a blank line ends the header; pages start on the next byte
    pages of 2048 bytes: 341 chunks of 6 bytes, then 2 padding bytes

A chunk's type is the high nibble of its second byte (the first byte is not used by the reference reader):

* 0, one accelerometer sample: x = byte 3 + (byte 2 & 15) << 8, y = byte 4 << 4 + byte 5 >> 4,
  z = (byte 5 & 15) << 8 + byte 6, each 12-bit two's complement;
* 2, a time stamp: bytes 3-6 big-endian, whole seconds since 1970 on the device clock (no time zone);
* 4, the battery: byte 3 x 3.3 x 11 / 1024 V, at the time of the sample before it (so in the second of the
  stamp before it, as GGIRread times it); of several readings with no sample between them the first is kept.

The published conversion (readGenea.R) turns x and z round, adds ``Accel-Offsets`` and scales by
``Accel-Gains`` / 8192 at 340 counts per g: g = (s x raw + offset) x gain / (8192 x 340) with s = (-1, 1, -1).
GGIRread rounds twice to whole mg; imulog keeps the exact value (the two agree within 1 mg).

Time: a time stamp applies to the sample that follows it, and the samples between two stamps are spread evenly
between them (GGIRread's rule); samples before the first stamp and after the last are at the header's
``Sample-Rate``. ``t_ns`` counts from the first sample, whose device-clock time is ``start_time`` (zone unknown).
A stamp interval whose sample count is off the rate by more than 10 % (lost data, a damaged stamp) is warned
about; a stamp that does not increase, or jumps by more than 31 days, is an error naming its page. A final page
cut short (an interrupted download) is dropped with a warning, as GGIRread drops it. The file is read from a
memory map in batches of pages (:func:`iter_chunks`), so memory stays bounded.
"""

from __future__ import annotations

import mmap
import re
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
from imulog.converters._binary import NS_PER_S, concat_chunks
from imulog.converters._common import G0
from imulog.converters._lab import trial_start
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording, SignalStream

MAGIC = b"GENEA"
HEADER_MAX = 64 << 10
PAGE_BYTES = 2048
CHUNK_BYTES = 6
CHUNKS_PER_PAGE = PAGE_BYTES // CHUNK_BYTES  # 341, then 2 padding bytes
CT_ACC, CT_TIME, CT_BATTERY = 0, 2, 4
COUNTS_PER_G = 340.0
GAIN_UNIT = 8192.0
AXIS_SIGN = np.array([-1, 1, -1])
BATTERY_V_PER_COUNT = 3.3 * 11 / 1024
PAGES_PER_CHUNK = 8192  # ~2.8 M samples per decoded batch
MAX_STEP_S = 31 * 86400


@dataclass
class _Clock:
    """Where every sample sits in time: time stamps, the samples after each, and the samples before the first."""

    stamps: np.ndarray  # (K,) int64 s
    seg_start: np.ndarray  # (K,) global index of the first sample after stamp k
    seg_len: np.ndarray  # (K,) samples after stamp k (before stamp k + 1)
    n_head: int  # samples before the first stamp
    rate: float  # Hz, for the head and the tail

    def rel_ns(self, idx: np.ndarray) -> np.ndarray:
        """ns of global sample indices relative to the first stamp (negative before it)."""
        idx = np.asarray(idx, dtype=np.int64)
        k = np.searchsorted(self.seg_start, idx, side="right") - 1
        head = k < 0
        kk = np.maximum(k, 0)
        j = (idx - self.seg_start[kk]).astype(np.float64)
        last = len(self.stamps) - 1
        nxt = self.stamps[np.minimum(kk + 1, last)]
        step = np.where(
            kk < last, (nxt - self.stamps[kk]) * float(NS_PER_S) / np.maximum(self.seg_len[kk], 1), NS_PER_S / self.rate
        )
        out = (self.stamps[kk] - self.stamps[0]) * NS_PER_S + np.round(j * step).astype(np.int64)
        before = -np.round((self.n_head - idx) * (NS_PER_S / self.rate)).astype(np.int64)
        return np.where(head, before, out)


def parse_header(path: Path, buf: bytes | mmap.mmap) -> tuple[str, dict[str, str], int]:
    """(version line, ``Key:Value`` items, byte where the pages start)."""
    end = buf.find(b"\r\n\r\n", 0, HEADER_MAX)
    if not buf[:5] == MAGIC or end < 0:
        raise ConversionError(path, "older Genea .bin: no 'GENEA' header ended by a blank line in the first 64 KiB")
    lines = bytes(buf[:end]).decode("latin-1").split("\r\n")
    items = {}
    for line in lines[1:]:
        key, sep, value = line.partition(":")
        if sep:
            items[key.strip()] = value.strip()
    return lines[0].strip(), items, end + 4


def _ints(path: Path, items: dict[str, str], key: str, default: int) -> np.ndarray:
    raw = items.get(key)
    if raw is None:
        return np.full(3, default, dtype=np.int64)
    parts = raw.split()
    if len(parts) != 3 or not all(re.fullmatch(r"[-+]?\d+", p) for p in parts):
        raise ConversionError(path, f"header: {key!r} is not three whole numbers ({raw!r})")
    return np.array([int(p) for p in parts], dtype=np.int64)


def _chunks(buf: mmap.mmap, start: int, p0: int, p1: int) -> np.ndarray:
    """(pages x 341, 6) uint8 chunks of pages ``p0:p1``."""
    raw = np.frombuffer(bytes(buf[start + p0 * PAGE_BYTES : start + p1 * PAGE_BYTES]), dtype=np.uint8)
    return raw.reshape(p1 - p0, PAGE_BYTES)[:, : CHUNKS_PER_PAGE * CHUNK_BYTES].reshape(-1, CHUNK_BYTES)


def _stamp_values(ch: np.ndarray) -> np.ndarray:
    c = ch.astype(np.int64)
    return (c[:, 2] << 24) | (c[:, 3] << 16) | (c[:, 4] << 8) | c[:, 5]


def decode_acc(ch: np.ndarray) -> np.ndarray:
    """(N, 6) accelerometer chunks -> (N, 3) signed 12-bit counts x, y, z as stored."""
    c = ch.astype(np.int64)
    xyz = np.column_stack(
        [c[:, 2] | ((c[:, 1] & 15) << 8), (c[:, 3] << 4) | (c[:, 4] >> 4), ((c[:, 4] & 15) << 8) | c[:, 5]]
    )
    return np.where(xyz >= 2048, xyz - 4096, xyz)


def _clock(path: Path, buf: mmap.mmap, start: int, n_pages: int, rate: float | None) -> tuple[_Clock, int, int]:
    """Pass 1 over the chunk types: the clock, the sample count and the count of off-rate stamp intervals."""
    stamps, stamp_page, stamp_pos = [], [], []
    n_acc = 0
    for p0 in range(0, n_pages, PAGES_PER_CHUNK):
        p1 = min(n_pages, p0 + PAGES_PER_CHUNK)
        ch = _chunks(buf, start, p0, p1)
        ct = ch[:, 1] >> 4
        is_acc = ct == CT_ACC
        at = np.flatnonzero(ct == CT_TIME)
        stamps.append(_stamp_values(ch[at]))
        stamp_page.append(p0 + at // CHUNKS_PER_PAGE)
        stamp_pos.append(n_acc + np.cumsum(is_acc)[at] - is_acc[at])  # samples before each stamp
        n_acc += int(is_acc.sum())
    st = np.concatenate(stamps) if stamps else np.zeros(0, np.int64)
    if n_acc == 0:
        raise ConversionError(path, "older Genea .bin: no accelerometer sample in the file's pages")
    if len(st) == 0:
        raise ConversionError(path, "older Genea .bin: no time stamp chunk (type 2), so no sample has a time")
    pages = np.concatenate(stamp_page)
    pos = np.concatenate(stamp_pos).astype(np.int64)
    step = np.diff(st)
    bad = np.flatnonzero((step <= 0) | (step > MAX_STEP_S))
    if len(bad):
        k = int(bad[0]) + 1
        what = "does not increase" if step[k - 1] <= 0 else f"jumps {step[k - 1]} s ahead"
        raise ConversionError(path, f"page {int(pages[k])}: time stamp {int(st[k])} {what} (previous {int(st[k - 1])})")
    seg_len = np.diff(np.append(pos, n_acc))
    if rate is None:  # no Sample-Rate in the header: the stamps' own rate
        rate = float(seg_len[:-1].sum() / step.sum()) if len(step) and step.sum() else 0.0
        if not rate > 0:
            raise ConversionError(path, "header has no 'Sample-Rate' and the time stamps give none")
    off = np.abs(seg_len[:-1] - rate * step) > 0.1 * rate * step + 1
    return _Clock(st, pos, seg_len, int(pos[0]), rate), n_acc, int(off.sum())


def iter_chunks(path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
    """The recording in pieces of up to :data:`PAGES_PER_CHUNK` pages (one time origin, time order)."""
    path = Path(path)
    with open(path, "rb") as f:
        try:
            buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        except ValueError:
            raise ConversionError(path, "empty file") from None
    with buf:
        version, items, start = parse_header(path, buf)
        n_pages, cut = divmod(len(buf) - start, PAGE_BYTES)
        if n_pages == 0:
            raise ConversionError(path, "older Genea .bin: no complete 2048-byte data page after the header")
        warnings = []
        if cut:
            warnings.append(f"{path.name}: the last page (index {n_pages}) is cut short ({cut} bytes); dropped")
        gains = _ints(path, items, "Accel-Gains", int(GAIN_UNIT))
        offsets = _ints(path, items, "Accel-Offsets", 0)
        if (gains <= 0).any():
            raise ConversionError(path, f"header: 'Accel-Gains' must be positive ({items.get('Accel-Gains')!r})")
        m = re.match(r"\s*([0-9]*\.?[0-9]+)", items.get("Sample-Rate", ""))
        declared = float(m.group(1)) if m and float(m.group(1)) > 0 else None
        clock, n_acc, off_rate = _clock(path, buf, start, n_pages, declared)
        if off_rate:
            warnings.append(
                f"{path.name}: {off_rate} interval(s) between time stamps hold a sample count off "
                f"{clock.rate:g} Hz by more than 10 %; their samples are spread evenly between the stamps"
            )
        origin = int(clock.rel_ns(np.array([0]))[0])
        when = datetime.fromtimestamp(int(clock.stamps[0]), tz=UTC).replace(tzinfo=None)
        when += timedelta(microseconds=origin / 1000)
        divisor = GAIN_UNIT * COUNTS_PER_G / gains
        name = "genea"
        meta = {
            "format": "genea-bin",
            "model": "Genea",
            "version": version,
            "serial": items.get("Serial-Number", ""),
            "firmware": items.get("Firmware-Version", ""),
            "body_location": items.get("Body-Location", ""),
            "rate_hz": clock.rate,
            "declared_sample_rate": items.get("Sample-Rate", ""),
            "calibration": {"gain": gains.tolist(), "offset": offsets.tolist(), "counts_per_g": COUNTS_PER_G},
            "pages": n_pages,
            "time_stamps": len(clock.stamps),
            "time_base": "ns from start_time; samples spread evenly between the 1 s time stamps (GGIRread)",
            "header": dict(items),
            "source": path.name,
        }
        # counts with the axis signs applied: ((counts + offset) / divisor) * g
        res = {"acc": {"shift": offsets.astype(float).tolist(), "divisor": divisor.tolist(), "scale": G0}}
        done, last_bat = 0, -1
        for p0 in range(0, n_pages, PAGES_PER_CHUNK):
            p1 = min(n_pages, p0 + PAGES_PER_CHUNK)
            ch = _chunks(buf, start, p0, p1)
            ct = ch[:, 1] >> 4
            is_acc = ct == CT_ACC
            n = int(is_acc.sum())
            idx = done + np.arange(n)
            t_ns = clock.rel_ns(idx) - origin
            counts = decode_acc(ch[is_acc]) * AXIS_SIGN
            acc = ((counts + offsets) / divisor) * G0
            at_bat = np.flatnonzero(ct == CT_BATTERY)
            bat_idx = np.maximum(done + np.cumsum(is_acc)[at_bat] - 1, 0)  # the sample before it
            first = np.diff(np.concatenate([[last_bat], bat_idx])) > 0  # one reading per sample: the first
            at_bat, bat_idx = at_bat[first], bat_idx[first]
            last_bat = int(bat_idx[-1]) if len(bat_idx) else last_bat
            volts = ch[at_bat, 2].astype(np.float64) * BATTERY_V_PER_COUNT
            done += n
            rec = Recording(sources=[str(path)])
            if n:
                rec.imus.append(ImuStream(name=name, t_ns=t_ns, acc=acc, meta={**meta, "resolution": res}))
            if len(at_bat):
                t_bat = clock.rel_ns(bat_idx) - origin
                rec.signals.append(SignalStream(f"/signals/{name}", t_bat, ["battery"], ["V"], volts[:, None]))
            rec.metadata[f"imulog.device.{name}"] = dict(meta)
            rec.metadata["imulog.trial"] = trial_start(when, "Genea first time stamp (device clock, zone unknown)")
            rec.warnings.extend(warnings)
            warnings = []
            yield rec


def read_bin(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file as one Recording (assembled from :func:`iter_chunks`)."""
    return concat_chunks(iter_chunks(path, options))


class GeneaConverter(Converter):
    name = "genea"
    description = "older Genea .bin (GENEA header, 2048-byte binary pages): accel calibrated by the header; battery"
    extensions = (".bin",)
    example = "imulog convert genea.bin -o genea.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        if head[:5] == MAGIC and b"\r\n" in head[:64]:
            return 0.95 if b"\r\n\r\n" in head or len(head) >= HEADER_MAX else 0.8
        return 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_bin(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        return iter_chunks(Path(path), options)


CONVERTER = GeneaConverter()
