"""Xsens MT Manager text exports (one file per sensor; several files = several sensors, named by serial).

Layout::

    // General information:
    //  MT Manager version: 2022.0.0
    // Device information:
    //  DeviceId: 00B41234
    // Device settings:
    //  Filter Profile: human (46.1)
    // Update Rate: 100.0Hz
    PacketCounter<TAB>SampleTimeFine<TAB>Acc_X<TAB>Acc_Y<TAB>Acc_Z<TAB>Gyr_X<TAB>...<TAB>Mag_X<TAB>...<TAB>Quat_q0...

comma or tab delimited. Units: ``Acc_*`` m/s^2, ``Gyr_*`` rad/s, ``Mag_*`` arbitrary units normalised to the
calibration field (kept as a signal, not uT), ``Temperature`` degC.

Time: ``SampleTimeFine`` (10 kHz ticks, unsigned 32 bit, unwrapped) when every row has it; otherwise the
``PacketCounter`` (16 bit, wraps from 65535 to 0, unwrapped; lost packets leave gaps) divided by the update rate.
The stream is named ``mt_<serial>`` unless ``options.extra["names"]`` maps the serial to a name.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from converters._common import (
    TableSpec,
    check_increasing,
    estimate_rate_hz,
    head_lines,
    is_number,
    read_numeric,
    sanitize_name,
    split_row,
    text_head_lines,
)
from converters.base import Converter, ConvertOptions
from converters.errors import ConversionError
from imulog.model import ImuStream, Recording, SignalStream

TICKS_PER_S = 10_000  # SampleTimeFine resolution
SIGNAL_UNITS = {
    "quat": "1",
    "roll": "deg",
    "pitch": "deg",
    "yaw": "deg",
    "freeacc": "m/s^2",
    "mag": "a.u.",
    "pressure": "Pa",
}


def unwrap_counter(values: np.ndarray, modulus: int) -> tuple[np.ndarray, int | None, str]:
    """Unwrap a wrapping counter; returns (unwrapped int64, index of first bad step or None, problem)."""
    c = values.astype(np.int64)
    d = np.diff(c)
    d = np.where(d < 0, d + modulus, d)
    bad = np.nonzero((d <= 0) | (d > modulus // 2))[0]
    if len(bad):
        i = int(bad[0])
        problem = "duplicated" if c[i + 1] == c[i] else "goes backwards or jumps more than half its range"
        return c, i + 1, problem
    return np.concatenate([[c[0]], c[0] + np.cumsum(d)]), None, ""


def _check_counter(path: Path, values: np.ndarray, modulus: int, first_line: int, column: str) -> None:
    bad = ~((values >= 0) & (values < modulus) & (values == np.round(values)))
    if bad.any():
        i = int(np.argmax(bad))
        raise ConversionError(
            path, f"{values[i]:g} is not a counter value in 0..{modulus - 1}", line=first_line + i, column=column
        )


def _header_info(lines: list[str]) -> tuple[dict[str, str], int]:
    info: dict[str, str] = {}
    n = 0
    for line in lines:
        if not line.lstrip().startswith("//"):
            break
        n += 1
        m = re.match(r"^\s*//\s*([^:]+?)\s*:\s*(.*?)\s*$", line)
        if m and m.group(2):
            info[m.group(1).strip()] = m.group(2)
    return info, n


def read_xsens(path: Path, *, names: dict[str, str] | None = None, rate_hz: float | None = None) -> Recording:
    path = Path(path)
    lines = head_lines(path)
    info, n_comment = _header_info(lines)
    if n_comment >= len(lines):
        raise ConversionError(path, "no column header after the // lines", line=n_comment)
    header_line = lines[n_comment]
    delimiter = "\t" if "\t" in header_line else ","
    cols = split_row(header_line, delimiter)
    while cols and cols[-1] == "":
        cols.pop()
    ncols_header = len(cols)
    if "PacketCounter" not in cols and "SampleTimeFine" not in cols:
        raise ConversionError(path, "no PacketCounter or SampleTimeFine column", line=n_comment + 1)
    seen: dict[str, int] = {}
    for i, c in enumerate(cols):
        if c == "":
            raise ConversionError(path, f"empty column name (column {i + 1})", line=n_comment + 1)
        if c in seen:
            raise ConversionError(path, f"duplicated column {c!r}", line=n_comment + 1)
        seen[c] = i
    first = split_row(lines[n_comment + 1], delimiter) if n_comment + 1 < len(lines) else []
    ncols = (
        max(ncols_header, len(first)) if first and len(first) == ncols_header + 1 and first[-1] == "" else ncols_header
    )
    names_all = cols + [""] * (ncols - ncols_header)
    imu_cols = {f"{q}_{a}" for q in ("Acc", "Gyr") for a in "XYZ"}
    text_cols = {
        i for i, c in enumerate(cols) if c not in imu_cols and i < len(first) and first[i] and not is_number(first[i])
    }
    ignore = text_cols | set(range(ncols_header, ncols))
    required = {seen[c] for c in imu_cols if c in seen}
    if "PacketCounter" in seen:
        required.add(seen["PacketCounter"])
    optional = set(range(ncols)) - required - ignore
    spec = TableSpec(
        path=path, delimiter=delimiter, skip_lines=n_comment + 1, names=names_all, optional=optional, ignore=ignore
    )
    values = read_numeric(spec)
    first_line = n_comment + 2

    rate = rate_hz
    m = re.search(r"([0-9]+(?:\.[0-9]+)?)", info.get("Update Rate", info.get("Sample rate", "")))
    if rate is None and m:
        rate = float(m.group(1))
    time_source = ""
    t_ns: np.ndarray | None = None
    if "SampleTimeFine" in seen:
        stf = values[:, seen["SampleTimeFine"]]
        if np.isfinite(stf).all():
            _check_counter(path, stf, 2**32, first_line, "SampleTimeFine")
            ticks, bad, problem = unwrap_counter(stf, 2**32)
            if bad is not None:
                raise ConversionError(path, f"SampleTimeFine {problem}", line=first_line + bad, column="SampleTimeFine")
            t_ns = ticks * (1_000_000_000 // TICKS_PER_S)
            time_source = "SampleTimeFine (10 kHz ticks, unwrapped at 2^32)"
    if t_ns is None:
        if "PacketCounter" not in seen:
            raise ConversionError(
                path, "SampleTimeFine has empty cells and there is no PacketCounter", column="SampleTimeFine"
            )
        if not rate:
            raise ConversionError(path, "no '// Update Rate' line and no --rate: cannot time the PacketCounter")
        pc = values[:, seen["PacketCounter"]]
        _check_counter(path, pc, 65536, first_line, "PacketCounter")
        counts, bad, problem = unwrap_counter(pc, 65536)
        if bad is not None:
            raise ConversionError(path, f"PacketCounter {problem}", line=first_line + bad, column="PacketCounter")
        t_ns = np.round(counts * (1e9 / rate)).astype(np.int64)
        time_source = "PacketCounter / update rate (unwrapped at 65535)"
    check_increasing(path, t_ns, first_line)

    serial = info.get("DeviceId") or info.get("Device ID") or ""
    if not serial:
        fm = re.search(r"MT_([0-9A-Fa-f]{8})", path.name)
        serial = fm.group(1) if fm else ""
    serial = serial.split()[0].upper() if serial else ""
    names = names or {}
    name = sanitize_name(names.get(serial, f"mt_{serial}" if serial else "xsens"))
    streams: dict[str, np.ndarray] = {}
    for q, key in (("Acc", "acc"), ("Gyr", "gyr")):
        present = [f"{q}_{a}" in seen for a in "XYZ"]
        if any(present) and not all(present):
            missing = [f"{q}_{a}" for a in "XYZ" if f"{q}_{a}" not in seen]
            raise ConversionError(path, f"missing column(s) {', '.join(missing)}", line=n_comment + 1)
        if all(present):
            streams[key] = values[:, [seen[f"{q}_{a}"] for a in "XYZ"]]
    if "Temperature" in seen:
        temp = values[:, seen["Temperature"]]
        if np.isfinite(temp).all():
            streams["temperature"] = temp
    if not streams:
        raise ConversionError(path, "no Acc_X/Y/Z or Gyr_X/Y/Z columns", line=n_comment + 1)
    meta: dict[str, Any] = {
        "format": "xsens",
        "model": info.get("ProductCode", info.get("Product Code", "Xsens MT")),
        "serial": serial,
        "rate_hz": float(rate) if rate else estimate_rate_hz(t_ns),
        "units": {"acc": "m/s^2", "gyr": "rad/s", "mag": "a.u. (normalised to the calibration field)"},
        "time": time_source,
        "source": path.name,
        "header": info,
    }
    for key in ("Filter Profile", "Firmware Version", "Firmware revision", "Start Time", "Option Flags"):
        if key in info:
            meta[key.lower().replace(" ", "_")] = info[key]
    rec = Recording(sources=[str(path)])
    rec.imus.append(ImuStream(name=name, t_ns=t_ns, meta=dict(meta), **streams))
    rec.metadata[f"imulog.device.{name}"] = meta
    skip = (
        imu_cols | {"PacketCounter", "SampleTimeFine", "Temperature"}
        if "temperature" in streams
        else imu_cols | {"PacketCounter", "SampleTimeFine"}
    )
    extra = [(c, i) for c, i in seen.items() if c not in skip and i not in ignore]
    if extra:
        units = [SIGNAL_UNITS.get(c.split("_")[0].lower(), "") for c, _ in extra]
        rec.signals.append(
            SignalStream(
                topic=f"/signals/{name}",
                t_ns=t_ns,
                columns=[c for c, _ in extra],
                units=units,
                values=values[:, [i for _, i in extra]],
            )
        )
    return rec


class XsensConverter(Converter):
    name = "xsens"
    description = "Xsens MT Manager text export (// header, comma or tab; one sensor per file, named by serial)"
    extensions = (".txt", ".csv")
    example = "imulog convert MT_00B41234_000.txt MT_00B45678_000.txt -o trial.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 60)
        if not lines:
            return 0.0
        if lines[0].startswith(("PacketCounter\t", "PacketCounter,")):
            return 0.8  # exported without the // header lines
        if not lines[0].lstrip().startswith("//"):
            return 0.0
        for line in lines:
            if not line.lstrip().startswith("//"):
                return 0.9 if ("PacketCounter" in line or "SampleTimeFine" in line) else 0.0
        return 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        options = options or ConvertOptions()
        return read_xsens(Path(path), names=options.extra.get("names"), rate_hz=options.rate_hz)


CONVERTER = XsensConverter()
