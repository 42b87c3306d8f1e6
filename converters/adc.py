"""Raw ADC text of a 3-axis accelerometer board (WiTilt, Doshi thesis): lines ``X=512 Y=498 Z=600``.

Counts -> g -> m/s^2: ``acc = (counts - zero_counts) / counts_per_g * 9.80665``. Defaults are the 10-bit board in
its +-2 g range: zero level 512 counts, 256 counts per g. The file has no time stamps, so the sampling rate must
be given (``--rate HZ``); sample ``i`` is at ``round(i / rate * 1e9)`` ns.

Settings (``ConvertOptions.extra``, CLI ``--adc-zero``, ``--adc-counts-per-g``): ``zero_counts`` (one number or one
per axis), ``counts_per_g``, ``adc_bits`` (10: counts must lie in 0..1023), ``name`` (stream name, default
``acc``).

Memory: in pieces of text (:func:`iter_adc`, ``iter_chunks``); the whole file is the one-piece case.
"""

from __future__ import annotations

import io
import json
import re
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from imulog.converters import _pieces
from imulog.converters._common import G0, drop_cut_final_row, looks_binary, text_head_lines
from imulog.converters._pieces import text_pieces
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError
from imulog.converters.mapping import sibling_mapping

from imulog.model import ImuStream, Recording

LINE = re.compile(rb"^[ \t]*X=(-?\d+)[ \t]+Y=(-?\d+)[ \t]+Z=(-?\d+)[ \t]*\r?$")
_NOISE = b"0123456789- \t=\r"


def _locate(path: Path, data: bytes, line_offset: int = 0, *, at_end: bool = True) -> None:
    """Careful pass: raise ConversionError at the first line that is not ``X=.. Y=.. Z=..`` (``data`` follows
    ``line_offset`` lines of the file; blank lines at its end are the file's end only when ``at_end``)."""
    lines = data.split(b"\n")
    if not at_end and lines and lines[-1] == b"":
        lines.pop()  # the piece ends with a line break
    while at_end and lines and not lines[-1].strip():
        lines.pop()
    for lineno, line in enumerate(lines, start=line_offset + 1):
        if not LINE.match(line):
            shown = line.decode("latin-1").strip()
            shown = shown if len(shown) <= 30 else shown[:27] + "..."
            what = "empty line" if not shown else f"expected 'X=<int> Y=<int> Z=<int>', got {shown!r}"
            raise ConversionError(path, what, line=lineno)


def read_adc(
    path: Path,
    *,
    rate_hz: float | None,
    zero_counts: float | list[float] = 512.0,
    counts_per_g: float = 256.0,
    adc_bits: int = 10,
    name: str = "acc",
) -> Recording:
    """The whole file: :func:`iter_adc` as one piece."""
    (rec,) = iter_adc(
        path, rate_hz=rate_hz, zero_counts=zero_counts, counts_per_g=counts_per_g, adc_bits=adc_bits, name=name
    )
    return rec


def iter_adc(
    path: Path,
    *,
    rate_hz: float | None,
    zero_counts: float | list[float] = 512.0,
    counts_per_g: float = 256.0,
    adc_bits: int = 10,
    name: str = "acc",
    piece_bytes: int | None = None,
) -> Iterator[Recording]:
    """The recording in pieces of about ``piece_bytes`` of text (None: the whole file as one piece), cut after whole
    lines (:func:`~imulog.converters._pieces.text_pieces`); every value, error line and warning as in one piece."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(65536)
    if not head.strip() and path.stat().st_size <= len(head):
        raise ConversionError(path, "empty file")
    if looks_binary(head):
        raise ConversionError(path, "binary data, not a text export")
    if rate_hz is None or not rate_hz > 0:
        raise ConversionError(path, "raw ADC text has no time stamps: give the sampling rate with --rate HZ")
    if not counts_per_g > 0:
        raise ConversionError(path, f"counts_per_g must be positive, got {counts_per_g}")
    try:
        zero = np.broadcast_to(np.asarray(zero_counts, dtype=np.float64), (3,))
    except (ValueError, TypeError):
        raise ConversionError(path, f"zero_counts must be one number or three, got {zero_counts!r}") from None
    top = 2**adc_bits - 1
    meta = {
        "format": "adc",
        "model": "3-axis ADC accelerometer (WiTilt-style)",
        "serial": "",
        "rate_hz": float(rate_hz),
        "zero_counts": [float(z) for z in zero],
        "counts_per_g": float(counts_per_g),
        "acc_range_g": float((top + 1) / 2 / counts_per_g),
        "adc_bits": adc_bits,
        "units": {"acc": "counts"},
        "source": path.name,
    }
    # the archive stores the counts: ((counts + shift) / divisor) * scale gives acc back exactly (issue 28)
    resolution = {"acc": {"shift": [-float(z) for z in zero], "divisor": float(counts_per_g), "scale": G0}}
    pieces = iter([(path.read_bytes(), 0, 0, True)]) if piece_bytes is None else text_pieces(path, 0, piece_bytes)
    first_row = 0
    for data, lines_before, k, last in pieces:
        cut_warning = None
        if last:
            end, cut_warning = drop_cut_final_row(path, data, " ", line_offset=lines_before)  # power lost mid-line
            data = data[:end]
            if not data.strip():
                if k:
                    continue  # nothing but blank lines after the previous piece
                raise ConversionError(path, "empty file")
        counts = _counts(path, data, lines_before, last)
        out = (counts < 0) | (counts > top) | (counts != np.round(counts))
        if out.any():
            row, col = (int(x) for x in np.argwhere(out)[0])
            raise ConversionError(
                path,
                f"{counts[row, col]:g} counts outside the {adc_bits}-bit range 0..{top}",
                line=lines_before + row + 1,
                column="XYZ"[col],
            )
        acc = (counts - zero) / counts_per_g * G0
        t_ns = np.round(np.arange(first_row, first_row + len(counts)) * (1e9 / rate_hz)).astype(np.int64)
        first_row += len(counts)
        rec = Recording(sources=[str(path)], warnings=[cut_warning] if cut_warning else [])
        rec.imus.append(ImuStream(name=name, t_ns=t_ns, acc=acc, meta={**meta, "resolution": resolution}))
        rec.metadata[f"imulog.device.{name}"] = dict(meta)
        yield rec


def _counts(path: Path, data: bytes, lines_before: int, last: bool) -> np.ndarray:
    """The (N, 3) counts of the lines ``data`` (after ``lines_before`` lines; ``last``: the file ends with it)."""
    import pandas as pd  # here, not at module top: detecting a format must not import pandas

    body = data.rstrip(b" \t\r\n") + b"\n" if last else data
    n = body.count(b"\n")
    # structural check at C speed: with digits, signs, blanks and '=' removed every line must read 'XYZ'
    if body.translate(None, _NOISE) != b"XYZ\n" * n or b"==" in body or b"--" in body:
        _locate(path, data, lines_before, at_end=last)
    try:
        counts = pd.read_csv(
            io.BytesIO(body.translate(None, b"XYZ=")), sep=r"\s+", header=None, dtype=np.float64, engine="c"
        ).to_numpy()
    except Exception:  # noqa: BLE001 - located precisely below
        _locate(path, data, lines_before, at_end=last)
        raise ConversionError(path, "could not parse the counts") from None
    if counts.shape != (n, 3) or not np.isfinite(counts).all():
        _locate(path, data, lines_before, at_end=last)
        raise ConversionError(path, "could not parse the counts")
    return counts


class AdcConverter(Converter):
    name = "adc"
    description = (
        "raw 3-axis ADC accelerometer text 'X=512 Y=498 Z=600' (needs --rate or a sidecar; zero 512, 256 counts/g)"
    )
    extensions = (".txt", ".log", ".dat")
    example = "imulog convert witilt.txt --rate 50 -o trial.mcap"

    def sniff(self, path: Path, head: bytes) -> float:
        lines = text_head_lines(head, 5)
        if not lines:
            return 0.0
        first = next((ln for ln in lines if ln.strip()), "")
        return 0.95 if LINE.match(first.encode("latin-1", "replace")) else 0.0

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:
        """Options on the command line win over a sibling ``<stem>.mapping.json`` ``device`` section."""
        return read_adc(Path(path), **_settings(Path(path), options))

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording]:
        """Pieces of about 16 MB of text (see :func:`iter_adc`)."""
        return iter_adc(Path(path), **_settings(Path(path), options), piece_bytes=_pieces.PIECE_BYTES)


def _settings(path: Path, options: ConvertOptions | None) -> dict[str, Any]:
    """The board's settings: the command line's over a sibling ``<stem>.mapping.json`` ``device`` section."""
    options = options or ConvertOptions()
    device = device_sidecar(options.mapping or sibling_mapping(path))
    extra = {**device, **options.extra}
    return {
        "rate_hz": options.rate_hz if options.rate_hz is not None else extra.get("rate_hz"),
        "zero_counts": extra.get("zero_counts", 512.0),
        "counts_per_g": float(extra.get("counts_per_g", 256.0)),
        "adc_bits": int(extra.get("adc_bits", 10)),
        "name": str(extra.get("name", "acc")),
    }


def device_sidecar(mapping_path: Path | None) -> dict:
    """The ``device`` section (rate_hz, zero_counts, counts_per_g, adc_bits, name) of an ADC sidecar file.

    Raw ADC text has no header, so a lab that records many sessions can keep the board's rate and
    calibration beside each file (``session.mapping.json``: ``{"format": "imulog.mapping/1",
    "device": {"name": "acc", "rate_hz": 100}}``) instead of typing ``--rate`` each time.
    """
    if mapping_path is None:
        return {}
    path = Path(mapping_path)
    try:
        text = path.read_text(encoding="utf-8")
        doc = tomllib.loads(text) if path.suffix.lower() == ".toml" else json.loads(text)
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise ConversionError(path, f"cannot read the ADC sidecar file: {exc}") from None
    device = doc.get("device", {}) if isinstance(doc, dict) else {}
    if not isinstance(device, dict):
        raise ConversionError(path, "'device' must be a table of rate_hz, zero_counts, counts_per_g, adc_bits, name")
    known = {"rate_hz", "zero_counts", "counts_per_g", "adc_bits", "name"}
    return {k: v for k, v in device.items() if k in known}


CONVERTER = AdcConverter()
