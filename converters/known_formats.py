"""Formats imulog recognises but cannot read (yet): named in the error instead of "unknown format".

When no converter is confident about a file, :func:`recognise` looks for the plain signature of a known format
(``# OpenSignals Text File Format``, ``Device Identity``, EDF's ``0`` + spaces, ``PathFileType``, an Excel
workbook, MATLAB, Parquet...) and returns a one-line explanation: the format, what is missing, what to do.
Formats whose reader is registered are never named here (a converter recognises them first).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from imulog.converters._common import text_head_lines


@dataclass(frozen=True)
class KnownFormat:
    name: str
    matches: Callable[[Path, bytes, list[str]], bool]
    missing: str
    todo: str


def _first(lines: list[str], prefix: str, n: int = 3) -> bool:
    return any(line.lstrip().startswith(prefix) for line in lines[:n])


KNOWN: tuple[KnownFormat, ...] = (
    KnownFormat(
        "OpenSignals/BITalino text",
        lambda p, h, ln: _first(ln, "# OpenSignals Text File Format"),
        "this OpenSignals header variant is not read",
        "export again as OpenSignals text with its JSON header line, or pass a mapping file",
    ),
    KnownFormat(
        "GENEActiv/Genea .bin",
        lambda p, h, ln: h.lstrip(b"\xef\xbb\xbf").startswith(b"Device Identity"),
        "no GENEActiv reader is installed",
        "export CSV from GENEActiv PC software (then use a mapping file), or install an imulog with the geneactiv "
        "converter",
    ),
    KnownFormat(
        "older Genea .bin",
        lambda p, h, ln: h[:5] == b"GENEA",
        "its header is not the layout the genea reader knows (CRLF 'Key:Value' lines ended by a blank line)",
        "force it with --format genea to see the first thing wrong, or export CSV with the Genea software",
    ),
    KnownFormat(
        "EDF/EDF+",
        lambda p, h, ln: h[:8] == b"0       " and len(h) >= 256 and h[184:192].strip().isdigit(),
        "no EDF reader is installed",
        "install an imulog with the edf converter, or export the channels as CSV",
    ),
    KnownFormat(
        "BDF (BioSemi)",
        lambda p, h, ln: h[:8] == b"\xffBIOSEMI",
        "no BDF reader is installed",
        "install an imulog with the edf converter, or export the channels as CSV",
    ),
    KnownFormat(
        "OpenSim marker file (.trc)",
        lambda p, h, ln: _first(ln, "PathFileType", 1),
        "no TRC reader is installed",
        "install an imulog with the opensim-trc converter, or give the markers as CSV with a mapping file",
    ),
    KnownFormat(
        "OpenSim storage/motion (.sto/.mot) without quaternion columns",
        lambda p, h, ln: any(line.strip().strip(",;\t").strip().lower() == "endheader" for line in ln[:40]),
        "only quaternion (OpenSense orientation) storage files are read here",
        "joint angles and moments need the opensim-mot converter; orientations need DataType=Quaternion",
    ),
    KnownFormat(
        "NilsPod session header (NilsPodLib's _header.json)",
        lambda p, h, ln: p.name.endswith("_header.json") and b'"sampling_rate_hz"' in h and b'"enabled_sensors"' in h,
        "it holds the session's settings, not its samples",
        "convert the _data.csv beside it (which reads this header), or the session's .bin",
    ),
    KnownFormat(
        "Excel workbook",
        lambda p, h, ln: h.startswith(b"PK\x03\x04") and (b"xl/" in h[:4096] or p.suffix.lower() in (".xlsx", ".xlsm")),
        "spreadsheets are not read",
        "save the sheet as CSV (one header row with units, or a mapping file)",
    ),
    KnownFormat(
        "legacy Excel workbook (.xls)",
        lambda p, h, ln: h.startswith(b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1"),
        "spreadsheets are not read",
        "save the sheet as CSV (one header row with units, or a mapping file)",
    ),
    KnownFormat(
        "MATLAB .mat",
        lambda p, h, ln: h.startswith(b"MATLAB 5.0 MAT-file") or (h.startswith(b"\x89HDF") and p.suffix == ".mat"),
        "MATLAB files have no fixed layout to read",
        "save the arrays as CSV with a time column and units, or write a converter plug-in (docs/converters.md)",
    ),
    KnownFormat(
        "Apache Parquet",
        lambda p, h, ln: h.startswith(b"PAR1"),
        "Parquet tables are not read",
        "write the table as CSV (pandas: df.to_csv) with units in the column names",
    ),
    KnownFormat(
        "HDF5",
        lambda p, h, ln: h.startswith(b"\x89HDF\r\n\x1a\n"),
        "no reader knows this HDF5 layout (APDM, BROAD and OpenSignals files are read)",
        "export CSV, or write a converter plug-in for the layout (docs/converters.md)",
    ),
    KnownFormat(
        "BIDS sidecar/table",
        lambda p, h, ln: re.search(r"_(channels|motion|events)\.tsv$", p.name) is not None,
        "BIDS-motion datasets are read per recording, not per table",
        "convert the dataset folder (an imulog with the bids converter), or give the *_motion.tsv a mapping file",
    ),
)


def recognise(path: Path, head: bytes) -> str | None:
    """``"<format>: <what is missing>; <what to do>"`` when ``head`` is a known format no converter reads."""
    lines = text_head_lines(head, 60) or []
    for known in KNOWN:
        try:
            hit = known.matches(Path(path), head, lines)
        except Exception:  # noqa: BLE001 - recognising is best effort, never a new failure
            hit = False
        if hit:
            return f"recognised as {known.name}, but {known.missing}: {known.todo}"
    return None
