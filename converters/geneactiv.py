"""GENEActiv ``.bin`` recordings (Activinsights GENEActiv 1.x: a text file of hexadecimal pages).

Layout (GENEActiv instructions, "Decoding .bin files"; GGIRread's and GENEAread's readers): CRLF text. A header of
``Key:Value`` lines in sections (``Device Identity``, ``Device Capabilities``, ``Configuration Info`` with
``Measurement Frequency`` and ``Time Zone:GMT +01:00``, ``Calibration Data`` with ``x gain``/``x offset`` ... and
``Volts``/``Lux``, ``Memory Status`` with ``Number of Pages``), then pages of ten lines each::

    Recorded Data
    Device Unique Serial Code:012967
    Sequence Number:0
    Page Time:2013-05-30 10:12:54:500          (local time of the page's first sample, ms after the last colon)
    Unassigned:
    Temperature:21.5                            (degC, one value per page)
    Battery voltage:4.1493                      (V)
    Device Status:Recording
    Measurement Frequency:85.7                  (Hz)
    <hex line: 300 samples x 12 hex digits>

Each 48-bit sample is x, y, z as 12-bit two's complement, then light (10 bits), button (1 bit) and one reserved bit.
Acceleration g = (raw * 100 - offset) / gain per axis; light lux = raw * Lux / Volts. Sample ``i`` of a page is at
``Page Time + i / frequency`` (as GGIRread). ``t_ns`` counts from the first sample, whose local time (with the
header's zone) is the trial's ``start_time``. Pages are decoded in batches so memory stays bounded
(:func:`iter_chunks`). A final page cut short (an interrupted download) is dropped with a warning; a damaged page
elsewhere stops the conversion naming its sequence number.

The older Genea ``.bin`` (binary 2048-byte pages after a ``GENEA`` header) is :mod:`imulog.converters.genea`'s.
"""

from __future__ import annotations

import json
import mmap
import re
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta, timezone
from pathlib import Path

import numpy as np
from imulog.converters._binary import NS_PER_S, concat_chunks
from imulog.converters._common import G0
from imulog.converters._lab import trial_start
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError

from imulog.model import ImuStream, Recording, SignalStream

PAGE_MARK = b"Recorded Data"
PAGE_LINES = 10
PAGES_PER_CHUNK = 4096  # ~1.2 M samples per decoded batch
_HEX = np.full(256, 255, dtype=np.uint8)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    _HEX[_c] = 10 + _i


def parse_header(path: Path, text: str) -> dict[str, dict[str, str]]:
    """The header's ``Key:Value`` lines by section (values stripped)."""
    sections: dict[str, dict[str, str]] = {}
    current = sections.setdefault("", {})
    for line in text.splitlines():
        line = line.strip()
        if not line:
            continue
        if ":" in line:
            k, _, v = line.partition(":")
            current[k.strip()] = v.strip()
        else:
            current = sections.setdefault(line, {})
    return sections


def _number(path: Path, section: dict[str, str], key: str) -> float:
    raw = section.get(key)
    m = re.match(r"^\s*([-+]?[0-9]*\.?[0-9]+)", raw or "")
    if not m:
        raise ConversionError(path, f"header: {key!r} missing or not a number ({raw!r})")
    return float(m.group(1))


def utc_offset_s(zone: str) -> int | None:
    """``GMT +01:00`` -> 3600; None when the header has no usable zone."""
    m = re.search(r"([+-])\s*(\d{1,2}):?(\d{2})", zone or "")
    if not m:
        return 0 if (zone or "").strip().upper() in ("GMT", "UTC") else None
    s = (int(m.group(2)) * 3600 + int(m.group(3)) * 60) * (1 if m.group(1) == "+" else -1)
    return s


def page_time_ms(path: Path, text: str, seq: str) -> int:
    """``2013-05-30 10:12:54:500`` -> ms since 1970 on the device's wall clock."""
    m = re.match(r"\s*(\d{4})-(\d{1,2})-(\d{1,2}) (\d{1,2}):(\d{2}):(\d{2})(?::(\d{1,3}))?", text)
    if not m:
        raise ConversionError(path, f"page {seq}: bad 'Page Time' {text.strip()!r}")
    y, mo, d, h, mi, s = (int(g) for g in m.groups()[:6])
    ms = int(m.group(7) or 0)
    when = datetime(y, mo, d, h, mi, s, tzinfo=UTC)
    return int(when.timestamp()) * 1000 + ms


def decode_hex(lines: np.ndarray) -> np.ndarray:
    """(pages, 12*n) ASCII hex -> (pages, n, 5) int: x, y, z (signed 12 bit), light (10 bit), button (0/1)."""
    nib = _HEX[lines].astype(np.int32).reshape(lines.shape[0], -1, 12)
    w = [(nib[..., 3 * k] << 8) | (nib[..., 3 * k + 1] << 4) | nib[..., 3 * k + 2] for k in range(4)]
    xyz = np.stack(w[:3], axis=-1)
    xyz = np.where(xyz >= 2048, xyz - 4096, xyz)
    light = w[3] >> 2
    button = (w[3] >> 1) & 1
    return np.concatenate([xyz, light[..., None], button[..., None]], axis=-1)


def _page_offsets(buf: mmap.mmap | bytes, start: int) -> list[int]:
    offs = []
    pos = buf.find(PAGE_MARK, start)
    while pos >= 0:
        offs.append(pos)
        pos = buf.find(PAGE_MARK, pos + len(PAGE_MARK))
    return offs


def _page(path: Path, buf, lo: int, hi: int) -> tuple[dict[str, str], bytes] | None:
    """(page keys, hex line) of the page in ``buf[lo:hi]``; None when it is cut short."""
    lines = bytes(buf[lo:hi]).split(b"\n")
    lines = [x.rstrip(b"\r") for x in lines]
    if len(lines) < PAGE_LINES or not lines[PAGE_LINES - 1]:
        return None
    keys = {}
    for raw in lines[1 : PAGE_LINES - 1]:
        k, _, v = raw.decode("latin-1").partition(":")
        keys[k.strip()] = v.strip()
    return keys, lines[PAGE_LINES - 1]


def iter_chunks(path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
    """The recording in pieces of up to :data:`PAGES_PER_CHUNK` pages (one time origin, time order)."""
    path = Path(path)
    with open(path, "rb") as f:
        try:
            buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        except ValueError:
            raise ConversionError(path, "empty file") from None
    with buf:
        if buf[:5] == b"GENEA":
            raise ConversionError(
                path, "an older Genea .bin (GENEA header, binary pages): convert it as --format genea"
            )
        first = buf.find(PAGE_MARK)
        if first < 0:
            raise ConversionError(path, "no 'Recorded Data' page: not a GENEActiv .bin, or the file holds no data")
        hdr = parse_header(path, bytes(buf[:first]).decode("latin-1"))
        cal = hdr.get("Calibration Data")
        if cal is None:
            raise ConversionError(path, "header has no 'Calibration Data' section")
        gain = np.array([_number(path, cal, f"{a} gain") for a in "xyz"])
        offset = np.array([_number(path, cal, f"{a} offset") for a in "xyz"])
        if (gain == 0).any():
            raise ConversionError(path, "header: an axis gain is 0")
        volts = _number(path, cal, "Volts") if "Volts" in cal else 0.0
        lux = _number(path, cal, "Lux") if "Lux" in cal else 0.0
        ident = hdr.get("Device Identity", {})
        config = hdr.get("Configuration Info", {})
        zone_s = utc_offset_s(config.get("Time Zone", ""))
        declared = hdr.get("Memory Status", {}).get("Number of Pages", "")
        offs = _page_offsets(buf, first) + [len(buf)]
        n_pages = len(offs) - 1
        warnings: list[str] = []
        if declared.isdigit() and int(declared) != n_pages:
            warnings.append(
                f"{path.name}: header declares {declared} pages, the file holds {n_pages}; read what is there"
            )
        name = "geneactiv"
        meta = {
            "format": "geneactiv-bin",
            "model": f"{ident.get('Device Type', 'GENEActiv')} {ident.get('Device Model', '')}".strip(),
            "serial": ident.get("Device Unique Serial Code", ""),
            "firmware": ident.get("Device Firmware Version", ""),
            "accel_range": hdr.get("Device Capabilities", {}).get("Accelerometer Range", ""),
            "calibration": {"gain": gain.tolist(), "offset": offset.tolist(), "volts": volts, "lux": lux},
            "time_zone": config.get("Time Zone", ""),
            "pages": n_pages,
            "time_base": "ns from start_time; sample i of a page at Page Time + i / Measurement Frequency",
            "source": path.name,
        }
        # stored as counts x 100 (GGIR's calibration offset is in hundredths of a count): ((c - offset) / gain) * g
        res = {"acc": {"shift": (-offset).tolist(), "divisor": gain.tolist(), "scale": G0}}
        # light and button stored as the 10-bit and 1-bit words: light = word * (Lux / Volts), exactly as computed
        light_res = json.dumps({"values": {"scale": [lux / volts if volts else 1.0, 1.0]}})
        origin_ms: int | None = None
        prev_end: float | None = None
        for c0 in range(0, n_pages, PAGES_PER_CHUNK):
            rows, times, temps, batts, rates, hexes = [], [], [], [], [], []
            for k in range(c0, min(n_pages, c0 + PAGES_PER_CHUNK)):
                page = _page(path, buf, offs[k], offs[k + 1])
                if page is None or (hexes and len(page[1]) != len(hexes[0])):
                    if k == n_pages - 1:
                        warnings.append(f"{path.name}: the last page (index {k}) is cut short; dropped")
                        break
                    raise ConversionError(path, f"page index {k}: damaged page (wrong length or missing lines)")
                keys, hexline = page
                seq = keys.get("Sequence Number", str(k))
                if len(hexline) % 12 or not hexline or (_HEX[np.frombuffer(hexline, np.uint8)] == 255).any():
                    if k == n_pages - 1:
                        warnings.append(f"{path.name}: the last page (sequence {seq}) is damaged; dropped")
                        break
                    raise ConversionError(path, f"page sequence {seq}: the data line is not 12-digit hex samples")
                times.append(page_time_ms(path, keys.get("Page Time", ""), seq))
                temps.append(_number(path, keys, "Temperature") if keys.get("Temperature") else np.nan)
                batts.append(_number(path, keys, "Battery voltage") if keys.get("Battery voltage") else np.nan)
                rates.append(_number(path, keys, "Measurement Frequency"))
                hexes.append(hexline)
                rows.append(k)
            if not hexes:
                break
            raw = decode_hex(np.frombuffer(b"".join(hexes), np.uint8).reshape(len(hexes), -1))
            n = raw.shape[1]
            rate = np.asarray(rates)
            if (rate <= 0).any():
                raise ConversionError(path, f"page index {rows[int(np.argmax(rate <= 0))]}: measurement frequency <= 0")
            page_ms = np.asarray(times, dtype=np.float64)
            if origin_ms is None:
                origin_ms = int(page_ms[0])
                meta["rate_hz"] = float(rate[0])
                meta["samples_per_page"] = n
            rel_ns = (page_ms - origin_ms) * 1e6
            t = (rel_ns[:, None] + np.arange(n)[None, :] * (NS_PER_S / rate[:, None])).round().astype(np.int64)
            flat_t = t.reshape(-1)
            d = np.diff(np.concatenate([[-1 if prev_end is None else prev_end], flat_t]))
            if (d <= 0).any():
                i = int(np.argmax(d <= 0)) // n
                raise ConversionError(path, f"page index {rows[i]}: page time goes backwards")
            prev_end = int(flat_t[-1])
            xyz = raw[..., :3].reshape(-1, 3).astype(np.float64)
            acc_g = (xyz * 100.0 - offset) / gain
            light = raw[..., 3].reshape(-1).astype(np.float64) * (lux / volts if volts else 1.0)
            button = raw[..., 4].reshape(-1).astype(np.float64)
            rec = Recording(
                imus=[ImuStream(name=name, t_ns=flat_t, acc=acc_g * G0, meta={**meta, "resolution": res})],
                signals=[
                    SignalStream(
                        f"/signals/{name}",
                        flat_t,
                        ["light", "button"],
                        ["lux" if volts else "counts", "1"],
                        np.column_stack([light, button]),
                        attrs={"resolution": light_res},
                    ),
                    SignalStream(
                        f"/signals/{name}_page",
                        t[:, 0],
                        ["temperature", "battery"],
                        ["degC", "V"],
                        np.column_stack([temps, batts]),
                    ),
                ],
                sources=[str(path)],
            )
            rec.metadata[f"imulog.device.{name}"] = dict(meta)
            when = datetime.fromtimestamp(origin_ms / 1000.0, tz=UTC).replace(tzinfo=None)
            if zone_s is not None:
                when = when.replace(tzinfo=timezone(timedelta(seconds=zone_s)))
            rec.metadata["imulog.trial"] = trial_start(when, "GENEActiv first page time (Page Time) and Time Zone")
            rec.warnings.extend(warnings)
            warnings = []
            yield rec
        if origin_ms is None:
            raise ConversionError(path, "no complete data page")


def read_bin(path: Path, options: ConvertOptions | None = None) -> Recording:
    """The whole file as one Recording (assembled from :func:`iter_chunks`)."""
    return concat_chunks(iter_chunks(path, options))


class GeneactivConverter(Converter):
    name = "geneactiv"
    description = "GENEActiv .bin (hex pages): accel calibrated by the header (m/s^2); light lux, button, temperature"
    extensions = (".bin",)
    example = "imulog convert ../shared/data/devices/geneactiv_bin/GENEActiv_testfile.bin -o geneactiv.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        if head.startswith(b"Device Identity") and b"Device Unique Serial Code" in head[:200]:
            return 0.99 if PAGE_MARK in head or b"Calibration Data" in head else 0.8
        return 0.0

    def recording_key(self, path: Path) -> str | None:
        return Path(path).name

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        return read_bin(Path(path), options)

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        return iter_chunks(Path(path), options)


CONVERTER = GeneactivConverter()
