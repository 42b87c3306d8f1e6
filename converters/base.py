"""What a converter is: a named object that recognises (``sniff``) and reads (``convert``) one source format.

A lab adds its own device by writing a class like this and registering an instance (or the class) under the
``imulog.converters`` entry-point group of its own package (see docs/converters.md).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from imulog.model import Recording


@dataclass(frozen=True)
class ConvertOptions:
    """Options the ``convert`` command passes to every converter (each uses what applies to it).

    ``mapping``: a column mapping file for delimited text (else a sibling ``<stem>.mapping.json``/``.toml``).
    ``rate_hz``: sampling rate for formats without time stamps (raw ADC text), Hz.
    ``extra``: converter-specific settings, e.g. ``{"zero_counts": 512, "counts_per_g": 256}`` for ADC text.
    """

    mapping: Path | None = None
    rate_hz: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def export_source(path: Path, stem_pattern: str, suffix: str | tuple[str, ...]) -> Path | None:
    """The device file an export was named after: ``path``'s stem matched by ``stem_pattern`` (its first group
    the device file's stem), with ``suffix`` (or the first of several that exists, e.g. ``(".cwa", ".CWA")``),
    when it exists beside ``path``; else None (:meth:`Converter.export_of`)."""
    m = re.fullmatch(stem_pattern, Path(path).stem)
    for end in (suffix,) if isinstance(suffix, str) else suffix:
        source = Path(path).with_name(f"{m.group(1)}{end}") if m else None
        if source is not None and source != Path(path) and source.is_file():
            return source
    return None


class Converter:
    """Base class of converters. Subclasses set ``name``/``description``/``extensions`` and implement both methods.

    ``sniff(path, head)`` returns a confidence in [0, 1] that ``path`` (whose first bytes are ``head``) is in this
    format, never raising. ``convert(path, options)`` returns an :class:`imulog.model.Recording` with SI units on
    the device clock, ``metadata['imulog.device.<name>']`` for each device and ``sources`` = the files read;
    it raises only :class:`imulog.converters.errors.ConversionError` for bad input.
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    extensions: ClassVar[tuple[str, ...]] = ()
    example: ClassVar[str] = ""
    #: True when ``iter_chunks`` yields pieces of one fixed size (binary block formats): ``imulog convert`` then
    #: keeps freed piece temporaries in the heap for the next piece to reuse (imulog.heap.reuse_heap) instead of
    #: mapping each afresh (bound_heap, which pieces of varying size need to keep memory flat)
    fixed_pieces: ClassVar[bool] = False
    #: files at least this large (bytes) convert piece by piece even below ``imulog convert``'s general threshold
    #: (``STREAM_MIN_BYTES``): for formats whose whole-file conversion costs many times the text (None: the general one)
    stream_min_bytes: ClassVar[int | None] = None

    def sniff(self, path: Path, head: bytes) -> float:  # pragma: no cover - interface
        raise NotImplementedError

    def convert(self, path: Path, options: ConvertOptions | None = None) -> Recording:  # pragma: no cover
        raise NotImplementedError

    def iter_chunks(self, path: Path, options: ConvertOptions | None = None) -> Iterator[Recording] | None:
        """Consecutive pieces of the recording in bounded memory (same streams, time order, one time origin), or
        None when the format is read whole. ``imulog convert`` streams large files of formats that have it."""
        return None

    def iter_session(
        self, paths: list[Path], options: ConvertOptions | None = None, *, whole: bool = False
    ) -> Iterator[Recording] | None:
        """The files of one recording that belong together (a session folder: Empatica E4's ACC.csv, BVP.csv, ...) as
        one recording, in pieces each covering one time window of every file (``whole``: one piece), or None when
        the format's files convert one by one. ``imulog convert FOLDER`` uses it for such a folder's files."""
        return None

    def recording_key(self, path: Path) -> str | None:
        """The recording ``path`` belongs to when the format names it (e.g. Xsens ``MT_<master>_<trial>-000_<id>``:
        one file per sensor); None lets the registry group by the file name without role words."""
        return None

    def export_of(self, path: Path) -> Path | None:
        """The device file beside ``path`` that ``path`` is the vendor software's documented export of (NilsPodLib's
        ``X_data.csv`` of ``X.bin``), when that file exists; else None. ``imulog convert FOLDER`` converts the device
        file and skips the export with one line (docs/converters.md, "One trial per recording")."""
        return None

    def __repr__(self) -> str:
        return f"<converter {self.name}>"
