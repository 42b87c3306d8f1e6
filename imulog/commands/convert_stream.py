"""``imulog convert`` of one large file piece by piece (``Converter.iter_chunks``): memory bounded by a piece."""

from __future__ import annotations

import itertools
import os
import sys
from pathlib import Path

import click

from imulog.commands.convert_common import _echo_json, _format_name, conversion_record
from imulog.converters import ConversionError, ConvertOptions, UnknownFormatError
from imulog.converters.base import Converter
from imulog.converters.registry import get
from imulog.model import Recording

#: files at least this large are converted piece by piece when their format can (memory stays bounded)
STREAM_MIN_BYTES = int(os.environ.get("IMULOG_STREAM_MIN_BYTES", 32 * 1024 * 1024))


def _streams(path: Path, name: str) -> bool:
    """True when ``path`` is large and its format ``name`` (forced or already detected: ``_format_name``) reads piece
    by piece (``Converter.iter_chunks``): at least ``STREAM_MIN_BYTES``, or its converter's smaller
    ``stream_min_bytes``."""
    if not path.is_file():
        return False
    size = path.stat().st_size
    try:
        conv = get(name)
    except (ConversionError, UnknownFormatError):
        return False
    threshold = STREAM_MIN_BYTES if conv.stream_min_bytes is None else min(STREAM_MIN_BYTES, conv.stream_min_bytes)
    return size >= threshold and type(conv).iter_chunks is not Converter.iter_chunks


def session_converter(
    files: list[Path], fmt: str | None, options: ConvertOptions, names: list[str] | None = None
) -> Converter | None:
    """The converter that reads ``files`` together as one session (``Converter.iter_session``: every file of one format
    that has it), else None (the files convert one by one). ``names``: the files' formats when already known."""
    try:
        found = set(names) if names is not None else {_format_name(p, fmt, options) for p in files}
        conv = get(found.pop()) if len(found) == 1 else None
    except (ConversionError, UnknownFormatError):
        return None
    return conv if conv is not None and type(conv).iter_session is not Converter.iter_session else None


def _convert_streaming(
    path: Path,
    output: Path,
    fmt: str | None,
    options: ConvertOptions,
    meta: dict,
    *,
    attach: str,
    overwrite: bool,
    as_json: bool = False,
    files: list[Path] | None = None,
) -> tuple[dict[str, int], list[str]] | None:
    """Convert one large file piece by piece (memory bounded by a piece, not by the recording). ``files``: the files
    of one session read together in time windows (``Converter.iter_session``), ``path`` their folder; then nothing
    is printed and (samples per topic, warnings) are returned."""
    from imulog.archive import ArchiveError
    from imulog.archive.streaming import StreamingTrialWriter
    from imulog.converters.plausibility import PieceExcerpts, marker_warnings
    from imulog.converters.registry import iter_file_chunks
    from imulog.converters.values import ValueReport, finish
    from imulog.heap import bound_heap, reuse_heap

    name = _format_name(files[0] if files else path, fmt, options)
    conv = get(name)
    # the same temporaries piece after piece (imulog.heap): pieces of one size reuse their pages (a .cwa day: 5 s
    # of system time less); pieces of varying size are mapped afresh, which keeps memory flat
    if conv.fixed_pieces:
        reuse_heap()
    else:
        bound_heap()
    size = sum(p.stat().st_size for p in files or [path])
    notes: list[str] = []
    counts: dict[str, int] = {}
    try:
        report = ValueReport()  # the value check of converters/values.py, over all pieces
        pieces = iter_file_chunks(path, conv, options, report, files)
        first = next(pieces, None)
        if first is None:
            raise ConversionError(path, "no samples")
        records = {k: {**first.metadata.get(k, {}), **v} for k, v in meta.items()}
        sources = [Path(s) for s in first.sources] or [path]  # the sidecars a reader read too (BIDS, NilsPod CSV)
        expected = _declared_duration_s(first) or _expected_duration_s(
            first, size, _bytes_per_sample((files or [path])[0])
        )
        with (
            StreamingTrialWriter(
                output,
                metadata=records,
                sources=sources,
                attach=attach,
                overwrite=overwrite,
                expected_duration_s=expected,
            ) as writer,
            click.progressbar(
                length=max(1, int(expected or 1)), label=f"converting {path.name} (s of recording)", file=sys.stderr
            ) as bar,
        ):
            covered, shown = 0.0, 0
            spread = PieceExcerpts()  # unit plausibility on excerpts from the whole recording, judged at the end
            for piece in itertools.chain([first], pieces):
                writer.write(piece)
                for stream in piece.streams():
                    counts[stream.topic] = counts.get(stream.topic, 0) + len(stream)
                for imu in piece.imus:
                    spread.add(imu)
                checks = [w for m in piece.markers for w in marker_warnings(m.topic, m.pos)] if piece is first else []
                for note in [*piece.warnings, *checks]:  # the converter's own notes for every piece
                    if note not in notes:
                        notes.append(note)
                covered += _span_s(piece)
                target = min(bar.length - 1, int(covered))  # an estimate: the bar closes when the file ends
                bar.update(max(0, target - shown))
                shown = max(shown, target)
            bar.update(bar.length - shown)
            notes.extend(w for w in spread.warnings() if w not in notes)
            checked = Recording()
            finish(checked, report, path)  # an unusable channel fails here, before the file is kept
            notes.extend(w for w in checked.warnings if w not in notes)
            # after the pieces: a reader that hashed the file while reading it spares a second pass over it
            writer.metadata["imulog.conversion"] = {
                **conversion_record(sources, {p.name: name for p in files or [path]}),
                "streamed": True,
            }
            if notes:
                writer.metadata["imulog.conversion"]["warnings"] = notes
    except ConversionError as e:
        raise click.ClickException(str(e)) from None
    except ArchiveError as e:
        raise click.ClickException(str(e)) from None
    except (FileExistsError, ValueError, OSError) as e:
        raise click.ClickException(f"{output}: {e}") from None
    if files is not None:
        return counts, notes
    if as_json:
        _echo_json([{"path": str(output), "channels": counts, "warnings": notes, "streamed": True}], [])
        return
    click.echo(f"wrote {output} ({', '.join(f'{t} {n}' for t, n in counts.items())}; converted piece by piece)")
    for msg in notes:
        click.echo(f"warning: {output}: {msg}", err=True)
    return None


def _span_s(piece: Recording) -> float:
    """Seconds covered by a piece (its longest stream)."""
    spans = [(s.t_ns[-1] - s.t_ns[0]) / 1e9 for s in piece.streams() if getattr(s, "t_ns", None) is not None and len(s)]
    return max(spans, default=0.0)


def _declared_duration_s(first: Recording) -> float | None:
    """The recording's length (s) from the stream spans its first piece declares (``imulog.pieces``), if it does."""
    from imulog.model import PIECES_RECORD

    spans = (first.metadata.get(PIECES_RECORD) or {}).get("spans") or {}
    lengths = [(int(v[1]) - int(v[0])) / 1e9 for v in spans.values() if v is not None]
    return max(lengths) if lengths else None


def _bytes_per_sample(path: Path) -> float:
    """About how many bytes of the file one sample takes: ~12 in the wearables' binary formats, one line of text
    (the mean line length of the file's first 256 KiB) in text exports."""
    from imulog.converters._common import looks_binary, read_head

    head = read_head(path)
    lines = head.count(b"\n")
    return 12.0 if looks_binary(head) or lines < 2 else len(head) / lines


def _expected_duration_s(first: Recording, size: int, bytes_per_sample: float = 12.0) -> float | None:
    """About how long the file's recording is (s), from the first piece's rate and ``bytes_per_sample``; for the
    progress bar and the viewer twins' message budget only."""
    span = _span_s(first)
    rate = sum(len(s) for s in first.imus) / span if span > 0 else 0.0
    return size / (bytes_per_sample * rate) if rate > 0 else None
