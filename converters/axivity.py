"""Axivity AX3 / AX6 ``.cwa`` binary recordings (OpenMovement continuous wave accelerometer format).

Layout: a 1024-byte ``MD`` header, then 512-byte ``AX`` data blocks, each::

    0  'AX'  u16 length (508)  u16 deviceFractional  u32 sessionId  u32 sequenceId  u32 RTC timestamp
    18 u16 light (AAAGGGLLLLLLLLLL)  u16 temperature  u8 events  u8 battery  u8 rate code  u8 numAxesBPS
    26 i16 timestampOffset  u16 sampleCount  30 480 bytes of samples  510 u16 checksum (word sum of block = 0)

Samples: ``numAxesBPS`` 0x30 = 3 axes packed in 32 bits (3 x 10-bit signed + 2-bit exponent, value << e; 1 g = 256),
0x32 = 3 x int16, 0x62/0x92 = int16 gyro X,Y,Z then accel X,Y,Z (then mag X,Y,Z, 1 uT = 16). Accelerometer LSB
1/2^(8+n) g with n the top 3 bits of ``light``; gyro range 8000/2^m deg/s with m the next 3 bits (32768 = range).

Time: the RTC (``YYYYYYMM MMDDDDDh hhhhmmmm mmssssss``, year + 2000) is the device's **local** time with no zone.
Sample times follow scikit-digital-health's rule by default, OpenMovement's with ``extra["cwa_times"] =
"openmovement"`` (both in :mod:`imulog.converters.axivity_time`). Where the device paused (the next block two
block durations or more later) the samples that would fit are NaN on the nominal grid (``gaps``, ``gap_samples``
in the device record), in bounded pieces. ``t_ns`` counts from the first sample, whose local time
is the trial's ``start_time`` (zone unknown). Light (raw 10-bit counts), temperature (degC = raw * 75 / 256 - 50,
OpenMovement's conversion; scikit-digital-health's (raw - 171) / 3.142 reads ~2 degC higher at skin temperature)
and battery (V = (raw + 512) * 6 / 1024) become one row per block in ``/signals/<name>``.

Every block's checksum is verified: a bad or truncated block stops the conversion with the file and block index
(a silently skipped block would turn damaged data into a time gap nobody sees). With
``ConvertOptions.extra["skip_damaged"]`` damaged blocks (bad checksum, length or block type) are skipped instead:
each run of them is a gap (NaN samples on the nominal grid, counted in ``gaps``/``gap_samples``; the block after
it is not chained across it), one warning per run names its blocks (the warnings go
to the conversion record), and ``skipped_damaged_blocks`` in the device record counts them.

Blocks are decoded in batches of plain reads, so memory does not grow with the recording (:func:`iter_chunks`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from imulog.converters._binary import (
    NS_PER_S,
    concat_chunks,
    iso_from_epoch_ns,
    time_zone_label,
    with_fills,
)
from imulog.converters._common import G0, sanitize_name
from imulog.converters.axivity_format import (  # noqa: F401 - re-exported: the format's names as before
    BLOCK_BYTES,
    BLOCK_DTYPE,
    BLOCKS_PER_CHUNK,
    HARDWARE,
    HEADER_BYTES,
    MAGIC_AX,
    OTHER_BLOCKS,
    CwaHeader,
    block_word_sums,
    gyro_range_dps,
    parse_header,
    temperature_degc,
    unpack_int16,
    unpack_packed,
)
from imulog.converters.axivity_time import (
    DEFAULT_TIME_RULE,
    TIME_RULES,
    PreviousBlock,
    anchor_ns,
    block_spans,
    block_start_ns,  # noqa: F401 - re-exported (tests, benchmarks)
    gaps,
    nominal_ns,
    rate_from_code,
    rtc_to_epoch_s,  # noqa: F401 - re-exported
    sample_times_ns,
)
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording, SignalStream


@dataclass(frozen=True)
class _Layout:
    axes: int
    packed: bool
    capacity: int  # samples a block can hold; each block says how many it holds (sampleCount)


def _layout(path: Path, blocks: np.ndarray, first_index: int) -> _Layout:
    """The (single) sample format of a batch of blocks; ConversionError naming the first odd block."""
    axes_bps = blocks["axes_bps"]
    a0 = int(axes_bps[0])
    odd = np.nonzero(axes_bps != a0)[0]
    if len(odd):
        i = int(odd[0])
        raise ConversionError(
            path,
            f"data block {first_index + i}: sample format changes (numAxesBPS 0x{int(axes_bps[i]):02X}; "
            f"the file started with 0x{a0:02X})",
        )
    axes, bps = a0 >> 4, a0 & 0x0F
    if bps == 0 and axes == 3:
        packed, size = True, 4
    elif bps == 2 and axes in (3, 6, 9):
        packed, size = False, 2 * axes
    else:
        raise ConversionError(path, f"data block {first_index}: unsupported sample format numAxesBPS 0x{a0:02X}")
    capacity = 480 // size
    too_many = np.nonzero(blocks["count"] > capacity)[0]
    if len(too_many):
        i = int(too_many[0])
        raise ConversionError(
            path,
            f"data block {first_index + i}: impossible sample count {int(blocks['count'][i])} (at most {capacity})",
        )
    return _Layout(axes=axes, packed=packed, capacity=capacity)


def _damage(raw: np.ndarray, blocks: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Per block of a batch: damaged?, and why ("" when intact)."""
    sums = block_word_sums(raw)
    magic = blocks["magic"]
    bad_magic = (magic != MAGIC_AX) & ~np.isin(magic, list(OTHER_BLOCKS))
    bad_sum = (magic == MAGIC_AX) & ((sums != 0) | (blocks["length"] != 508))
    why = [
        f"not an 'AX' data block (starts {bytes(raw[i, :2])!r})"
        if bad_magic[i]
        else "checksum mismatch"
        if bad_sum[i]
        else ""
        for i in range(len(raw))
    ]
    return bad_magic | bad_sum, why


def _check_blocks(
    path: Path, raw: np.ndarray, blocks: np.ndarray, first_index: int, skip_damaged: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """(indices in the batch of the AX blocks to decode, indices of damaged blocks). A damaged block is an error
    naming it unless ``skip_damaged``."""
    bad, why = _damage(raw, blocks)
    if bad.any() and not skip_damaged:
        i = int(np.nonzero(bad)[0][0])
        what = why[i] if why[i] != "checksum mismatch" else "checksum mismatch (the block is damaged)"
        raise ConversionError(
            path,
            f"data block {first_index + i} (byte {HEADER_BYTES + (first_index + i) * BLOCK_BYTES}): {what}; "
            "--skip-damaged converts the rest with the damaged blocks as gaps",
        )
    return np.nonzero((blocks["magic"] == MAGIC_AX) & ~bad)[0], np.nonzero(bad)[0]


def _decode(blocks: np.ndarray, layout: _Layout) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(acc g, gyr deg/s or None, mag uT or None), each (N, count, 3) float64."""
    accel_lsb = np.left_shift(1, 8 + ((blocks["light"].astype(np.int64) >> 13) & 7)).astype(np.float64)
    if layout.packed:
        return unpack_packed(blocks["data"], layout.capacity) / accel_lsb[:, None, None], None, None
    raw = unpack_int16(blocks["data"], layout.capacity, layout.axes).astype(np.float64)
    if layout.axes == 3:
        return raw / accel_lsb[:, None, None], None, None
    gyro_range = gyro_range_dps(blocks["light"])
    gyr = raw[..., 0:3] / (32768.0 / gyro_range)[:, None, None]  # counts / (counts per deg/s): resolution()
    acc = raw[..., 3:6] / accel_lsb[:, None, None]
    mag = raw[..., 6:9] / 16.0 if layout.axes == 9 else None
    return acc, gyr, mag


def resolution(blocks: np.ndarray, gyr: bool, mag: bool) -> dict[str, dict[str, float]]:
    """How the SI values of ``_decode`` (then ``* G0`` and ``np.radians``) follow from the counts of a block:
    ``(counts / divisor) * scale``; the archive stores the counts where this gives every value back
    (imulog.archive.numbers)."""
    light = blocks["light"][:1]
    out = {"acc": {"divisor": float(np.left_shift(1, 8 + ((int(light[0]) >> 13) & 7))), "scale": G0}}
    if gyr:
        out["gyr"] = {"divisor": float(32768.0 / gyro_range_dps(light)[0]), "scale": float(np.pi / 180)}
    if mag:
        out["mag"] = {"divisor": 16.0}
    return out


def iter_chunks(
    path: Path, options: ConvertOptions | None = None, blocks_per_chunk: int = BLOCKS_PER_CHUNK
) -> Iterator[Recording]:
    """Decode ``path`` batch by batch: one Recording per ``blocks_per_chunk`` blocks, same streams, one time origin.

    Memory is bounded by the batch (read with plain reads). Raises ConversionError for damaged input.
    """
    options = options or ConvertOptions()
    path = Path(path)
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(HEADER_BYTES)
    header = parse_header(path, head)
    n_blocks, rest = divmod(size - HEADER_BYTES, BLOCK_BYTES)
    if rest:
        raise ConversionError(
            path,
            f"data block {n_blocks} (byte {HEADER_BYTES + n_blocks * BLOCK_BYTES}): truncated ({rest} of 512 bytes)",
        )
    if n_blocks <= 0:
        raise ConversionError(path, "no data blocks after the header")
    source = open(path, "rb")  # noqa: SIM115 - closed in the finally below, when the generator ends
    serial = str(header.device_id)
    names = {str(k).upper(): v for k, v in (options.extra.get("names") or {}).items()}
    name = sanitize_name(names.get(serial.upper(), f"{header.model.lower()}_{serial}"))
    try:
        skip = bool(options.extra.get("skip_damaged"))
        rule = time_rule(path, options)
        yield from _decode_batches(path, source, header, n_blocks, blocks_per_chunk, name, skip, rule)
    finally:
        source.close()


def time_rule(path: Path, options: ConvertOptions) -> str:
    """The sample-time rule asked for (``ConvertOptions.extra["cwa_times"]``, ``--cwa-times``): ``"skdh"``
    (default) or ``"openmovement"`` (see :mod:`imulog.converters.axivity_time`)."""
    rule = options.extra.get("cwa_times") or DEFAULT_TIME_RULE
    if rule not in TIME_RULES:
        raise ConversionError(path, f"unknown .cwa time rule {rule!r}; known: {', '.join(TIME_RULES)}")
    return str(rule)


def _read_blocks(source, first: int, count: int) -> np.ndarray:
    """``count`` blocks from block index ``first`` as (count, 512) bytes: plain reads, so the pages of a week's
    file do not stay resident as a memory map's would (RSS would grow with the file)."""
    source.seek(HEADER_BYTES + first * BLOCK_BYTES)
    data = source.read(count * BLOCK_BYTES)
    return np.frombuffer(data, dtype=np.uint8).reshape(-1, BLOCK_BYTES).copy()


def _skipped_warning(path: Path, run: tuple[int, int]) -> str:
    return (
        f"{path.name}: data blocks {run[0]}-{run[1]} damaged (checksum or block header); skipped, a gap in the samples"
    )


def _runs(idx: np.ndarray) -> list[tuple[int, int]]:
    """Consecutive runs of sorted block indices as (first, last)."""
    out: list[tuple[int, int]] = []
    for i in map(int, idx):
        if out and out[-1][1] == i - 1:
            out[-1] = (out[-1][0], i)
        else:
            out.append((i, i))
    return out


def _decode_batches(
    path: Path,
    source,
    header: CwaHeader,
    n_blocks: int,
    blocks_per_chunk: int,
    name: str,
    skip_damaged: bool = False,
    rule: str = DEFAULT_TIME_RULE,
) -> Iterator[Recording]:
    layout: _Layout | None = None
    previous: PreviousBlock | None = None  # the last intact block so far (chaining across batches)
    origin: int | None = None
    meta: dict = {}
    prev_end: int | None = None
    n_gaps = gap_samples = skipped = 0
    warnings: list[str] = []
    pending: tuple[int, int] | None = None  # the last run of damaged blocks, reported when it ends
    for first in range(0, n_blocks, blocks_per_chunk):
        stop = min(n_blocks, first + blocks_per_chunk)
        raw = _read_blocks(source, first, min(n_blocks, stop + 1) - first)  # one block ahead: its start time
        blocks_all = raw.view(BLOCK_DTYPE).reshape(len(raw))
        keep, bad = _check_blocks(path, raw[: stop - first], blocks_all[: stop - first], first, skip_damaged)
        damaged = list(first + bad)
        ahead, ahead_index = None, n_blocks
        if stop < n_blocks:
            nxt_raw, j = raw[-1:], stop
            while True:  # the next intact block gives this batch's end time (damaged ones on the way skipped)
                nxt = nxt_raw.view(BLOCK_DTYPE).reshape(1)
                if nxt[0]["magic"] != MAGIC_AX and not _damage(nxt_raw, nxt)[0][0]:
                    break
                good, _ = _check_blocks(path, nxt_raw, nxt, j, skip_damaged)
                if len(good):
                    ahead, ahead_index = int(anchor_ns(nxt, rule)[0]), j
                    break
                damaged.append(j)
                j += 1
                if j >= n_blocks:
                    break
                nxt_raw = _read_blocks(source, j, 1)
        if bad.size:
            skipped += len(bad)
            for a, b in _runs(first + bad):
                if pending and a == pending[1] + 1:  # a run continued across batches
                    pending = (pending[0], b)
                    continue
                if pending:
                    warnings.append(_skipped_warning(path, pending))
                pending = (a, b)
        keep = keep[blocks_all["count"][keep] > 0]  # a block without samples adds nothing
        if len(keep) == 0:
            continue
        blocks = blocks_all[keep]
        index = first + keep  # block indices in the file
        breaks = None
        if damaged:
            following = np.append(index[1:], ahead_index)
            dmg = np.sort(np.asarray(damaged))
            breaks = np.searchsorted(dmg, following) > np.searchsorted(dmg, index, side="right")
        lay = _layout(path, blocks, int(index[0]))
        if layout is None:
            layout = lay
        elif lay != layout:
            raise ConversionError(path, f"data block {int(index[0])}: sample layout changes within the recording")
        rate = rate_from_code(blocks["rate_code"])
        anchors = anchor_ns(blocks, rule)
        counts = blocks["count"].astype(np.int64)
        filled = np.arange(layout.capacity)[None, :] < counts[:, None]  # (N, capacity): the samples each block holds
        starts, spans = block_spans(rule, anchors, ahead, counts, rate, breaks, previous)
        previous = PreviousBlock(
            anchor=int(anchors[-1]),
            nominal=int(nominal_ns(counts[-1:], rate[-1:])[0]),
            break_after=bool(breaks[-1]) if breaks is not None else False,
        )
        t = sample_times_ns(starts, spans, counts)
        t = np.pad(t, ((0, 0), (0, layout.capacity - t.shape[1])))[filled]
        if origin is None:
            origin = int(t[0])
            meta = _device_meta(path, header, layout, name, blocks)
            meta["time_rule"] = rule
        d = np.diff(np.concatenate([[origin - 1 if prev_end is None else prev_end], t]))
        if (d <= 0).any():
            i = int(np.repeat(np.arange(len(counts)), counts)[int(np.nonzero(d <= 0)[0][0])])
            raise ConversionError(path, f"data block {int(index[i])}: time stamp goes backwards")
        prev_end = int(t[-1])
        acc, gyr, mag = _decode(blocks, layout)
        meta["resolution"] = resolution(blocks[:1], gyr is not None, mag is not None)
        values = {
            "acc": acc[filled] * G0,
            "gyr": None if gyr is None else np.radians(gyr[filled]),
            "mag": None if mag is None else mag[filled],
        }
        positions, fill_t0, fill_n = gaps(path, anchors, ahead, starts + spans, counts, rate, index, breaks)
        n_gaps += int(np.count_nonzero(fill_n))
        gap_samples += int(fill_n.sum())
        meta.update(gaps=n_gaps, gap_samples=gap_samples)
        if skip_damaged:
            meta["skipped_damaged_blocks"] = skipped
        step_ns = NS_PER_S / float(rate[0])
        pieces = with_fills(t - origin, values, positions, fill_t0 - origin, fill_n, step_ns)
        imus = [ImuStream(name=name, t_ns=pt, meta=dict(meta), **pv) for pt, pv in pieces]
        signals = SignalStream(
            topic=f"/signals/{name}",
            t_ns=starts - origin,
            columns=["light", "temperature", "battery"],
            units=["counts", "degC", "V"],
            values=np.column_stack(
                [
                    (blocks["light"] & 0x3FF).astype(np.float64),
                    temperature_degc(blocks["temperature"]),
                    (blocks["battery"].astype(np.float64) + 512.0) * 6.0 / 1024.0,
                ]
            ),
        )
        trial = {"start_time": iso_from_epoch_ns(origin), "time_zone": time_zone_label(None)}
        for i, part in enumerate(imus):
            rec = Recording(imus=[part], signals=[signals] if i == 0 else [], sources=[str(path)])
            rec.metadata[f"imulog.device.{name}"] = dict(meta)
            rec.metadata["imulog.trial"] = dict(trial)
            if i == 0:
                rec.warnings.extend(warnings)
                warnings = []
            yield rec
    if origin is None:
        raise ConversionError(path, "no 'AX' data blocks")
    if pending:
        warnings.append(_skipped_warning(path, pending))
    if warnings:  # runs of damaged blocks not yet reported
        rec = Recording(sources=[str(path)], warnings=warnings)
        rec.metadata[f"imulog.device.{name}"] = dict(meta, skipped_damaged_blocks=skipped)
        yield rec


def _device_meta(path: Path, header: CwaHeader, layout: _Layout, name: str, blocks: np.ndarray) -> dict:
    light = int(blocks["light"][0])
    meta = {
        "format": "axivity-cwa",
        "model": f"Axivity {header.model}",
        "serial": str(header.device_id),
        "session_id": header.session_id,
        "firmware": header.firmware,
        "rate_hz": float(rate_from_code(int(blocks["rate_code"][0]))),
        "accel_range_g": header.accel_range_g,
        "accel_lsb_per_g": 1 << (8 + ((light >> 13) & 7)),
        "sample_format": "packed 3x10-bit + exponent" if layout.packed else f"{layout.axes} x int16",
        "samples_per_block": int(blocks["count"][0]),
        "time_base": "ns from start_time; device RTC in local time without a zone",
        "source": path.name,
    }
    if layout.axes >= 6:
        meta["gyro_range_dps"] = int(gyro_range_dps(np.array([light]))[0])
    if header.annotation:
        meta["annotation"] = header.annotation
    return meta


def read_cwa(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file as one Recording (assembled from :func:`iter_chunks`)."""
    return concat_chunks(iter_chunks(path, options))


class AxivityConverter(Converter):
    name = "axivity"
    description = "Axivity AX3/AX6 .cwa (accel, gyro; light, temperature, battery as signals); local start time"
    extensions = (".cwa",)
    example = "imulog convert ../shared/data/devices/axivity_cwa/ax6_sample.cwa -o ax6.mcap"
    fixed_pieces = True  # BLOCKS_PER_CHUNK blocks a piece: the same temporaries each time

    def sniff(self, path: Path, head: bytes) -> float:
        if len(head) >= HEADER_BYTES + 2 and head[:2] == b"MD" and head[HEADER_BYTES : HEADER_BYTES + 2] == b"AX":
            return 0.99
        if head[:2] == b"MD" and Path(path).suffix.lower() == ".cwa":
            return 0.9
        return 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_cwa(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Bounded-memory pieces for the streaming convert (see the module's :func:`iter_chunks`)."""
        return iter_chunks(Path(path), options)


CONVERTER = AxivityConverter()
