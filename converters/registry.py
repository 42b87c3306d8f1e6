"""Converter registry: entry points ``imulog.converters``, format auto-detection and trial grouping.

Every converter (built-in or a lab's own) is found through the ``imulog.converters`` entry-point group; an
entry point names a :class:`imulog.converters.base.Converter` instance or class. The built-ins are also known directly,
so a source checkout works before ``pip install -e``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from importlib import import_module
from importlib.metadata import entry_points
from pathlib import Path

from imulog.converters._common import read_head
from imulog.converters.base import Converter, ConvertOptions
from imulog.converters.errors import ConversionError, UnknownFormatError, excerpt
from imulog.converters.mapping import is_mapping_file
from imulog.converters.values import ValueReport, check_recording

from imulog.model import Recording

ENTRY_POINT_GROUP = "imulog.converters"
BUILTIN: dict[str, str] = {
    "delimited": "imulog.converters.delimited:CONVERTER",
    "xsens": "imulog.converters.xsens:CONVERTER",
    "adc": "imulog.converters.adc:CONVERTER",
    "vicon-csv": "imulog.converters.vicon_csv:CONVERTER",
    "c3d": "imulog.converters.c3d:CONVERTER",
    "broad-hdf5": "imulog.converters.broad:CONVERTER",
    "gaitmap": "imulog.converters.gaitmap:CONVERTER",
    "apdm": "imulog.converters.apdm:CONVERTER",
    "opensim-sto": "imulog.converters.opensim_sto:CONVERTER",
    "motive": "imulog.converters.motive:CONVERTER",
    "delsys": "imulog.converters.delsys:CONVERTER",
    "mvnx": "imulog.converters.mvnx:CONVERTER",
    "qualisys": "imulog.converters.qualisys:CONVERTER",
    "axivity": "imulog.converters.axivity:CONVERTER",
    "actigraph": "imulog.converters.actigraph:CONVERTER",
    "actilife-csv": "imulog.converters.actilife_csv:CONVERTER",
    "xdf": "imulog.converters.xdf:CONVERTER",
    "geneactiv": "imulog.converters.geneactiv:CONVERTER",
    "genea": "imulog.converters.genea:CONVERTER",
    "opensim-trc": "imulog.converters.opensim_trc:CONVERTER",
    "edf": "imulog.converters.edf:CONVERTER",
    "nilspod": "imulog.converters.nilspod:CONVERTER",
    "bids-motion": "imulog.converters.bids:CONVERTER",
    "axivity-csv": "imulog.converters.axivity_csv:CONVERTER",
    "movella-dot": "imulog.converters.movella_dot:CONVERTER",
    "empatica-e4": "imulog.converters.empatica_e4:CONVERTER",
    "shimmer-csv": "imulog.converters.shimmer:CONVERTER",
    "compressed": "imulog.converters.compressed:CONVERTER",
    "opensignals": "imulog.converters.opensignals:CONVERTER",
    "opensignals-h5": "imulog.converters.opensignals_h5:CONVERTER",
}
MIN_CONFIDENCE = 0.3


def _load(target: str) -> Converter:
    module, _, attr = target.partition(":")
    obj = getattr(import_module(module), attr)
    return obj() if isinstance(obj, type) else obj


_DISCOVERED: dict[object, dict[str, Converter]] = {}  # entry_points function -> converters it named


def _plugins() -> dict[str, Converter]:
    """The converters named by installed entry points, discovered once per process.

    Scanning every installed distribution's metadata takes ~15 ms, as long as parsing a 5 MB file; a process
    converting many files (batch, tests) pays it once. The cache is keyed by the ``entry_points`` function, so
    a test that replaces it sees its own plug-ins.
    """
    key = entry_points
    if key not in _DISCOVERED:
        found: dict[str, Converter] = {}
        for ep in entry_points(group=ENTRY_POINT_GROUP):
            try:
                obj = ep.load()
            except Exception:  # noqa: BLE001 - a broken plug-in must not break every conversion
                continue
            found[ep.name] = obj() if isinstance(obj, type) else obj
        _DISCOVERED.clear()
        _DISCOVERED[key] = found
    return _DISCOVERED[key]


def available() -> dict[str, Converter]:
    """All converters by name: entry points first (a lab's own may replace a built-in of the same name)."""
    found = dict(_plugins())
    for name, target in BUILTIN.items():
        if name not in found:
            found[name] = _load(target)
    return dict(sorted(found.items()))


def get(name: str) -> Converter:
    convs = available()
    if name not in convs:
        raise UnknownFormatError(None, f"unknown format {name!r}; known: {', '.join(convs)}")
    return convs[name]


def detect(path: Path) -> Converter:
    """The converter most confident that ``path`` is its format; UnknownFormatError when none is."""
    path = Path(path)
    try:
        head = read_head(path)
    except IsADirectoryError:
        raise ConversionError(path, "is a directory") from None
    except OSError as e:
        raise ConversionError(path, f"cannot read: {e.strerror}") from None
    if not head:
        raise ConversionError(path, "empty file")
    best, score = None, 0.0
    for conv in available().values():
        try:
            s = float(conv.sniff(path, head))
        except Exception:  # noqa: BLE001 - sniffing must never fail a conversion
            s = 0.0
        if s > score:
            best, score = conv, s
    if best is None or score < MIN_CONFIDENCE:
        from imulog.converters.known_formats import recognise

        named = recognise(path, head)
        if named:
            raise UnknownFormatError(path, f"{named} (see `imulog convert --list-formats`)")
        hint = ""
        if path.suffix.lower() in (".csv", ".tsv", ".txt"):
            hint = (
                "; if it is IMU text whose header carries no units (e.g. ax,ay,gx), give a mapping file: --mapping "
                f"FILE or {path.stem}.mapping.json beside it"
            )
        raise UnknownFormatError(path, f"unknown format (see `imulog convert --list-formats`, or pass --format){hint}")
    return best


def convert_file(path: Path, fmt: str | None = None, options: ConvertOptions | None = None) -> Recording:
    """Convert one input file (format auto-detected unless ``fmt``); raises only ConversionError."""
    path = Path(path)
    if not path.exists():
        raise ConversionError(path, "no such file")
    try:
        conv = get(fmt) if fmt else detect(path)
    except UnknownFormatError:
        if fmt or options is None or options.mapping is None:
            raise
        conv = get("delimited")  # an explicit --mapping names the columns detection could not recognise
    with reader_errors(path, conv):
        rec = conv.convert(path, options or ConvertOptions())
        check_recording(rec, path)  # the one value check every reader's output gets (converters/values.py)
    return rec


def iter_file_chunks(
    path: Path, conv: Converter, options: ConvertOptions, report: ValueReport, files: Sequence[Path] | None = None
) -> Iterator[Recording]:
    """``conv.iter_chunks`` with the same safety net and value check as :func:`convert_file`, piece by piece.

    ``report`` accumulates the value check; the caller ends with ``values.finish(rec, report, path)``. ``files``: the
    files of one session read together (``conv.iter_session``), ``path`` their folder."""
    with reader_errors(path, conv):
        pieces = conv.iter_chunks(path, options) if files is None else conv.iter_session(list(files), options)
        if pieces is None:
            raise ConversionError(path, f"{conv.name} does not read piece by piece")
        pieces = iter(pieces)
    while True:
        with reader_errors(path, conv):
            piece = next(pieces, None)
            if piece is not None:
                check_recording(piece, path, report=report, final=False)
        if piece is None:
            return
        yield piece


@contextmanager
def reader_errors(path: Path, conv: Converter) -> Iterator[None]:
    """The last safety net around a reader: anything but ConversionError becomes one line without a Python type.

    Numpy's floating-point warnings (``RuntimeWarning: overflow encountered in multiply`` on a damaged file) are
    silenced inside: what they would say, the value check (``converters/values.py``) counts per channel."""
    import numpy as np

    try:
        with np.errstate(all="ignore"):
            yield
    except ConversionError:
        raise
    except MemoryError:
        raise ConversionError(
            path, f"out of memory while reading it as {conv.name}: the file is damaged or declares more than it holds"
        ) from None
    except RecursionError:
        raise ConversionError(path, f"nested too deeply to read as {conv.name}: the file is damaged") from None
    except Exception as e:  # noqa: BLE001 - last safety net: report, never crash with a traceback
        detail = str(e).strip() or "no detail"
        raise ConversionError(
            path,
            f"cannot be read as {conv.name} ({excerpt(detail, 120)}): the file is damaged or not in this format; "
            "check it, or name the format with --format",
        ) from None


def convert_files(
    paths: Sequence[Path],
    fmt: str | None = None,
    options: ConvertOptions | None = None,
    *,
    formats: Sequence[str] | None = None,
) -> Recording:
    """Convert several files of one trial (e.g. an IMU text file and a Vicon CSV) and merge them.

    ``formats``: the format of each path when already detected (one per path; detection is not repeated)."""
    if not paths:
        raise ConversionError(None, "no input files")
    if formats is not None and len(formats) != len(paths):
        raise ValueError(f"{len(formats)} formats for {len(paths)} paths")
    rec: Recording | None = None
    for k, p in enumerate(paths):
        part = convert_file(p, formats[k] if formats is not None else fmt, options)
        if rec is None:
            rec = part
        else:
            kept, first_ns = _start_of(rec), _first_ns(rec)
            try:
                rec = rec.merge(part)
            except ValueError as e:
                raise ConversionError(p, f"cannot combine with the other inputs: {e}") from None
            other = _start_of(part)
            same = _same_origin(kept, first_ns, other, _first_ns(part))
            if same is not None:  # one clock origin, stated from two first samples: the earlier one starts the trial
                rec.metadata["imulog.trial"].update(same)
            elif kept and other and kept != other:  # the first input's start time stays, and the user hears of it
                rec.metadata["imulog.trial"].update(kept)
                rec.warnings.append(
                    f"{Path(p).name}: start time {other['start_time']} ({other.get('time_zone', '?')}) differs from "
                    f"{kept['start_time']} ({kept.get('time_zone', '?')}) of an earlier input; kept the earlier one "
                    "(--meta start_time=... sets it)"
                )
    assert rec is not None
    return rec


def _first_ns(rec: Recording) -> int | None:
    """The earliest sample time of a recording's streams (its start_time is that sample's wall time)."""
    firsts = [int(t[0]) for s in rec.streams() for t in [getattr(s, "t_ns", getattr(s, "start_ns", None))] if len(t)]
    return min(firsts) if firsts else None


def _same_origin(a: dict[str, str], a_first: int | None, b: dict[str, str], b_first: int | None) -> dict | None:
    """``a``'s start entries moved to the earlier first sample when ``a`` and ``b`` put the same wall time at
    ``t_ns`` = 0 (two files of one session on one time base, e.g. E4's HR.csv starting 10 s after ACC.csv); else
    None. Both need a zoned or both a naive start_time, and the same time zone label."""
    from datetime import datetime, timedelta

    if not (a and b) or a_first is None or b_first is None or a.get("time_zone") != b.get("time_zone"):
        return None
    try:
        sa, sb = datetime.fromisoformat(a["start_time"]), datetime.fromisoformat(b["start_time"])
        zero_a = sa - timedelta(microseconds=a_first / 1000)
        zero_b = sb - timedelta(microseconds=b_first / 1000)
        if abs((zero_a - zero_b).total_seconds()) > 1e-6:
            return None
    except (KeyError, TypeError, ValueError):
        return None
    return a if a_first <= b_first else {**a, **b}


def _start_of(rec: Recording) -> dict[str, str]:
    """The start-time entries of a recording's ``imulog.trial`` record (empty when it has none)."""
    trial = rec.metadata.get("imulog.trial", {})
    return {k: trial[k] for k in ("start_time", "time_zone", "start_time_source") if k in trial}


_ROLE_TOKENS = {
    "imu",
    "vicon",
    "markers",
    "marker",
    "analogs",
    "analog",
    "mocap",
    "devices",
    "trajectories",
    "emg",
    "stride",
    "strides",
    "borders",
    "events",
    "adc",
}
_DOC_NAMES = ("LICENSE", "LICENCE", "NOTICE", "README", "COPYING")  # documentation, not recordings
_SKIP_SUFFIXES = {".md", ".txt.license", ".license", ".json", ".toml", ".npz", ".npy", ".pdf", ".png", ".mcap"}


def recording_key(path: Path, conv: Converter | None = None) -> str:
    """Files of one recording share a key: the stem without role words (``s01_t02_imu`` ~ ``s01_t02_vicon``).

    A converter that knows its format's file names decides first (``conv.recording_key``: Xsens per-sensor files
    ``MT_012005D6_031-000_00B421AF.txt`` ~ ``..._00B4227B.txt``). Self-contained formats (C3D, HDF5) are always a
    recording of their own.
    """
    path = Path(path)
    if conv is not None:
        try:
            key = conv.recording_key(path)
        except Exception:  # noqa: BLE001 - a plug-in's naming rule must not break grouping
            key = None
        if key:
            return key
    if path.suffix.lower() in (".c3d", ".hdf5", ".h5"):
        return path.name
    tokens = [t for t in re.split(r"[_\-.]+", path.stem) if t and t.lower() not in _ROLE_TOKENS]
    return "_".join(tokens)


def _export_source(path: Path, conv: Converter, found: dict[Path, Converter]) -> Path | None:
    """The convertible device file (in ``found``) that ``path`` is an export of (``conv.export_of``), else None."""
    try:
        source = conv.export_of(path)
    except Exception:  # noqa: BLE001 - a plug-in's naming rule must not break grouping
        return None
    return source if source is not None and source in found and source != path else None


def export_note(path: Path, source: Path, conv: Converter) -> str:
    """The one line for an export skipped in a folder (its reason in ``imulog convert``'s ``skipped`` list)."""
    return (
        f"an export of {source.name} beside it ({conv.description.split(':')[0].split(' (')[0]}): one recording, "
        f"converted from {source.name}; convert {path.name} by name to compare the two decodes"
    )


def group_directory(
    directory: Path, skipped: list[tuple[Path, str]] | None = None, detected: dict[Path, Converter] | None = None
) -> list[tuple[str, list[Path]]]:
    """Recordings under ``directory`` (recursively): (output name, files) per recording, convertible files only.

    A file is convertible when some converter recognises it; mapping files, licences and READMEs are skipped.
    A vendor's export of a device file beside it (``conv.export_of``: NilsPodLib's ``X_data.csv`` of ``X.bin``,
    ActiLife's ``XRAW.csv`` of ``X.gt3x``) is the same recording decoded twice: the device file is converted and
    the export skipped. ``skipped``, when given, receives (file, reason) for each data file no converter recognises
    and each export skipped; ``detected`` receives each convertible file's converter (:func:`detect` ran once per
    file: callers need not run it again).
    """
    directory = Path(directory)
    groups: dict[tuple[Path, str], list[Path]] = {}
    found: dict[Path, Converter] = {}
    for path in sorted(p for p in directory.rglob("*") if p.is_file()):
        if is_mapping_file(path) or path.suffix.lower() in _SKIP_SUFFIXES or path.name.startswith("."):
            continue
        try:
            found[path] = detect(path)
        except ConversionError as e:
            if path.name.upper().startswith(_DOC_NAMES):
                continue
            if skipped is not None:
                skipped.append((path, getattr(e, "problem", None) or str(e)))
    for path, conv in found.items():
        source = _export_source(path, conv, found)
        if source is not None:
            if skipped is not None:
                skipped.append((path, export_note(path, source, conv)))
            continue
        if detected is not None:
            detected[path] = conv
        groups.setdefault((path.parent, recording_key(path, conv)), []).append(path)
    out = []
    for (parent, key), files in groups.items():
        rel = parent.relative_to(directory)
        # a recording named by its file (C3D, HDF5, .cwa, .gt3x, ...: one file, one recording) is named by the
        # file's stem, like recordings grouped by their stems (s01_t02_imu.csv -> s01_t02): the output name never
        # depends on the format; colliding names get their extensions back (unique_names in imulog convert)
        by_name = {p.name: p for p in files}
        base = by_name[key].stem if key in by_name else key
        name = base or (parent.name if parent != directory or not rel.parts else parent.name) or "trial"
        out.append((str(rel / name) if rel.parts else name, files))
    return out


def list_formats(converters: Iterable[Converter] | None = None) -> list[tuple[str, str, str]]:
    """(name, extensions, description) of every converter, for ``--list-formats``."""
    convs = list(converters) if converters is not None else list(available().values())
    return [(c.name, " ".join(c.extensions), c.description) for c in convs]
