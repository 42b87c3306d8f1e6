"""``imulog convert``: device exports (IMU text, Vicon CSV, C3D, ...) -> one self-describing MCAP trial."""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import sys
import tomllib
from pathlib import Path
from typing import Any

import click

from imulog.commands.outputs import overwrite_option, refuse_existing
from imulog.converters import ConversionError, ConvertOptions, UnknownFormatError
from imulog.converters.base import Converter
from imulog.converters.registry import (
    available,
    convert_files,
    detect,
    get,
    group_directory,
    list_formats,
    recording_key,
)
from imulog.model import Recording

TRIAL_RECORD = "imulog.trial"


def parse_value(text: str) -> Any:
    """``70`` -> 70, ``1.8`` -> 1.8, ``true`` -> True, ``[1,2]`` -> list; anything else stays a string."""
    try:
        return json.loads(text)
    except (json.JSONDecodeError, ValueError):
        return text


def record_name(prefix: str) -> str:
    """``anthropometrics`` -> ``imulog.anthropometrics``; names already starting with ``imulog.`` stay."""
    return prefix if prefix.startswith("imulog.") else f"imulog.{prefix}"


def parse_meta(pairs: tuple[str, ...] | list[str]) -> dict[str, dict[str, Any]]:
    """``subject=S01`` -> imulog.trial; ``anthropometrics.forearm_m=0.27`` -> imulog.anthropometrics."""
    out: dict[str, dict[str, Any]] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise click.BadParameter(f"{pair!r} is not key=value", param_hint="--meta")
        record, dot, field = key.rpartition(".")
        name = record_name(record) if dot else TRIAL_RECORD
        out.setdefault(name, {})[field if dot else key] = parse_value(value)
    return out


def load_meta_file(path: Path) -> dict[str, dict[str, Any]]:
    """JSON or TOML: top-level scalars go to imulog.trial, tables/objects to their own record."""
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
        doc = tomllib.loads(text) if Path(path).suffix.lower() == ".toml" else json.loads(text)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, tomllib.TOMLDecodeError) as e:
        raise click.ClickException(f"{path}: cannot read metadata file: {e}") from None
    if not isinstance(doc, dict):
        raise click.ClickException(f"{path}: metadata file must hold an object/table")
    out: dict[str, dict[str, Any]] = {}
    for key, value in doc.items():
        if isinstance(value, dict):
            out.setdefault(record_name(key), {}).update(value)
        else:
            out.setdefault(TRIAL_RECORD, {})[key] = value
    return out


def sha256_of(path: Path) -> str:
    """SHA-256 of a file (hex); the digest a converter computed from the bytes it parsed when it read them whole."""
    from imulog.converters._common import known_sha256

    known = known_sha256(path)
    if known is not None:
        return known
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def conversion_record(sources: list[str] | list[Path], formats: dict[str, str]) -> dict[str, Any]:
    """The ``imulog.conversion`` record: imulog version, input names, their formats and SHA-256."""
    from imulog import __version__

    return {
        "imulog_version": __version__,
        "inputs": [Path(s).name for s in sources],
        "formats": formats,
        "sha256": {Path(s).name: sha256_of(Path(s)) for s in sources},
    }


def finish_recording(rec: Recording, meta: dict[str, dict[str, Any]], formats: dict[str, str]) -> Recording:
    """Add user metadata and the ``imulog.conversion`` record (inputs, formats, SHA-256 of each source)."""
    for name, values in meta.items():
        rec.metadata[name] = {**rec.metadata.get(name, {}), **values}
    rec.metadata["imulog.conversion"] = conversion_record(rec.sources, formats)
    notes = unit_warnings(rec)
    if notes:
        rec.metadata["imulog.conversion"]["warnings"] = notes
    return rec


def unit_warnings(rec: Recording) -> list[str]:
    """The converters' own notes (rows dropped, units assumed) and the plausibility of the declared units (a wrong
    unit is not an error in the file, so nothing else sees it; see ``imulog.converters.plausibility``). One line each."""
    from imulog.converters.plausibility import recording_warnings

    return [*rec.warnings, *recording_warnings(rec)]


def conversion_warnings(rec: Recording) -> list[str]:
    """The warnings ``finish_recording`` recorded in ``imulog.conversion``."""
    return list(rec.metadata.get("imulog.conversion", {}).get("warnings", []))


def _format_name(path: Path, fmt: str | None, options: ConvertOptions) -> str:
    """The format ``convert_file`` will use: forced, detected, or delimited when --mapping names the columns."""
    if fmt:
        return fmt
    try:
        return detect(path).name
    except UnknownFormatError:
        if options.mapping is None:
            raise
        return "delimited"


def _convert_group(files: list[Path], fmt: str | None, options: ConvertOptions) -> tuple[Recording, dict[str, str]]:
    names = [_format_name(p, fmt, options) for p in files]  # detected once, here
    return convert_files(files, fmt, options, formats=names), {p.name: n for p, n in zip(files, names, strict=True)}


def _write(out: Path, rec: Recording, *, attach: str, overwrite: bool) -> Path:
    """``write_trial`` (atomic: nothing is left behind on failure); archive errors become ConversionError."""
    from imulog.archive import ArchiveError, write_trial
    from imulog.archive.errors import ArchiveExistsError
    from imulog.commands.outputs import exists_message

    try:
        return write_trial(out, rec, attach_sources=attach, overwrite=overwrite)
    except ArchiveExistsError:
        raise ConversionError(None, exists_message(out)) from None
    except ArchiveError as e:
        raise ConversionError(None, str(e)) from None


#: files at least this large are converted piece by piece when their format can (memory stays bounded)
STREAM_MIN_BYTES = int(os.environ.get("IMULOG_STREAM_MIN_BYTES", 32 * 1024 * 1024))


def _streams(path: Path, fmt: str | None, options: ConvertOptions) -> bool:
    """True when ``path`` is large and its format reads piece by piece (``Converter.iter_chunks``)."""
    if not path.is_file() or path.stat().st_size < STREAM_MIN_BYTES:
        return False
    try:
        conv = get(_format_name(path, fmt, options))
    except (ConversionError, UnknownFormatError):
        return False
    return type(conv).iter_chunks is not Converter.iter_chunks


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
) -> None:
    """Convert one large file piece by piece (memory bounded by a piece, not by the recording)."""
    from imulog.archive import ArchiveError
    from imulog.archive.streaming import StreamingTrialWriter
    from imulog.converters.plausibility import PieceExcerpts, marker_warnings
    from imulog.converters.registry import iter_file_chunks
    from imulog.converters.values import ValueReport, finish

    name = _format_name(path, fmt, options)
    conv = get(name)
    size = path.stat().st_size
    notes: list[str] = []
    counts: dict[str, int] = {}
    try:
        report = ValueReport()  # the value check of converters/values.py, over all pieces
        pieces = iter_file_chunks(path, conv, options, report)
        first = next(pieces, None)
        if first is None:
            raise ConversionError(path, "no samples")
        records = {k: {**first.metadata.get(k, {}), **v} for k, v in meta.items()}
        expected = _expected_duration_s(first, size, _bytes_per_sample(path))
        with (
            StreamingTrialWriter(
                output,
                metadata=records,
                sources=[path],
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
            writer.metadata["imulog.conversion"] = {**conversion_record([path], {path.name: name}), "streamed": True}
            if notes:
                writer.metadata["imulog.conversion"]["warnings"] = notes
    except ConversionError as e:
        raise click.ClickException(str(e)) from None
    except ArchiveError as e:
        raise click.ClickException(str(e)) from None
    except (FileExistsError, ValueError, OSError) as e:
        raise click.ClickException(f"{output}: {e}") from None
    if as_json:
        _echo_json([{"path": str(output), "channels": counts, "warnings": notes, "streamed": True}], [])
        return
    click.echo(f"wrote {output} ({', '.join(f'{t} {n}' for t, n in counts.items())}; converted piece by piece)")
    for msg in notes:
        click.echo(f"warning: {output}: {msg}", err=True)


def _echo_json(
    trials: list[dict[str, Any]], failures: list[str], skipped: list[tuple[Path, str]] | None = None
) -> None:
    """``--json``: the trials written (path, samples per channel, warnings), the failures, the files skipped."""
    import json

    doc: dict[str, Any] = {"trials": trials, "failures": failures}
    if skipped:
        doc["skipped"] = [{"path": str(p), "reason": why} for p, why in skipped]
    click.echo(json.dumps(doc, indent=2))


def _channel_list(counts: dict[str, int]) -> str:
    """``/imu/a 3369, /markers/vicon 700`` (samples per channel)."""
    return ", ".join(f"{t} {n}" for t, n in counts.items())


def _span_s(piece: Recording) -> float:
    """Seconds covered by a piece (its longest stream)."""
    spans = [(s.t_ns[-1] - s.t_ns[0]) / 1e9 for s in piece.streams() if getattr(s, "t_ns", None) is not None and len(s)]
    return max(spans, default=0.0)


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


def _kv(pairs: tuple[str, ...], option: str) -> dict[str, str]:
    out = {}
    for pair in pairs:
        k, sep, v = pair.partition("=")
        if not sep or not k.strip() or not v.strip():
            raise click.BadParameter(f"{pair!r} is not KEY=VALUE", param_hint=option)
        out[k.strip().upper()] = v.strip()
    return out


def _units(pairs: tuple[str, ...]) -> dict[str, str]:
    """``("acc=g", "gyr=deg/s")`` -> ``{"acc": "g", "gyr": "deg/s"}``, each unit checked against its quantity."""
    from imulog.converters._common import UNIT_QUANTITIES, check_unit

    out = {}
    for pair in pairs:
        q, sep, u = pair.partition("=")
        q, u = q.strip().lower(), u.strip()
        if not sep or not u:
            raise click.BadParameter(f"{pair!r} is not QUANTITY=UNIT", param_hint="--unit")
        if q not in UNIT_QUANTITIES:
            raise click.BadParameter(f"unknown quantity {q!r}; use {', '.join(UNIT_QUANTITIES)}", param_hint="--unit")
        problem = check_unit(q, u)
        if problem:
            raise click.BadParameter(problem, param_hint="--unit")
        out[q] = u
    return out


@click.command("convert")
@click.argument("inputs", nargs=-1, type=click.Path(exists=True, path_type=Path))
@click.option(
    "-o", "--output", type=click.Path(path_type=Path), help="Output .mcap (or a folder when INPUT is a folder)."
)
@click.option("--format", "fmt", metavar="NAME", help="Force the input format (see --list-formats).")
@click.option(
    "--meta",
    "meta_pairs",
    multiple=True,
    metavar="KEY=VALUE",
    help="Trial metadata (repeatable); RECORD.KEY=VALUE for other records.",
)
@click.option(
    "--meta-file", type=click.Path(exists=True, dir_okay=False, path_type=Path), help="Metadata as JSON or TOML."
)
@click.option("--no-attach", is_flag=True, help="Do not attach the original files (same as --attach-original never).")
@click.option(
    "--attach-original",
    type=click.Choice(["auto", "always", "never"]),
    default="auto",
    show_default=True,
    help="Attach the original files byte for byte; auto: up to 64 MB, larger ones are recorded by name, size and "
    "SHA-256 (check them later with imulog doctor TRIAL --original FILE).",
)
@click.option(
    "--mapping",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Column mapping file for delimited IMU text.",
)
@click.option(
    "--rate", "rate_hz", type=float, metavar="HZ", help="Sampling rate for files without time stamps (raw ADC text)."
)
@click.option("--adc-zero", type=float, default=512.0, show_default=True, help="ADC zero-g level, counts.")
@click.option("--adc-counts-per-g", type=float, default=256.0, show_default=True, help="ADC sensitivity, counts per g.")
@click.option(
    "--device-name",
    "device_names",
    multiple=True,
    metavar="SERIAL=NAME",
    help="Stream name for a sensor (repeatable): Xsens DeviceId, APDM case ID or label, Delsys sensor number, MVN "
    "sensor label, e.g. 00B421AF=left_forearm.",
)
@click.option(
    "--unit",
    "unit_pairs",
    multiple=True,
    metavar="QUANTITY=UNIT",
    help="Unit of a quantity whose header is missing or wrong (repeatable): acc=g, gyr=deg/s, mag=uT, markers=mm.",
)
@overwrite_option("Replace an existing output trial (without it, an existing output is refused).")
@click.option("--list-formats", "list_formats_flag", is_flag=True, help="List the known input formats and exit.")
@click.option(
    "--skip-damaged",
    is_flag=True,
    help="Axivity .cwa: skip blocks that fail their checksum, each run of them a gap with a warning "
    "(default: the first damaged block is an error naming it).",
)
@click.option(
    "--cwa-times",
    type=click.Choice(["skdh", "openmovement"]),
    default="skdh",
    show_default=True,
    help="Axivity .cwa sample times: skdh = scikit-digital-health's rule (the reference decode; GGIR's exports "
    "agree), openmovement = OpenMovement's block starts with the sub-second fraction (docs/converters.md).",
)
@click.option(
    "--inspect",
    is_flag=True,
    help="Print what would be made (format, columns to channels, units, rate, start time, warnings); write nothing.",
)
@click.option(
    "--json", "as_json", is_flag=True, help="Print what was written (paths, channels, warnings) as one JSON document."
)
def convert(
    inputs: tuple[Path, ...],
    output: Path | None,
    fmt: str | None,
    meta_pairs: tuple[str, ...],
    meta_file: Path | None,
    no_attach: bool,
    attach_original: str,
    mapping: Path | None,
    rate_hz: float | None,
    adc_zero: float,
    adc_counts_per_g: float,
    device_names: tuple[str, ...],
    unit_pairs: tuple[str, ...],
    overwrite: bool,
    list_formats_flag: bool,
    as_json: bool = False,
    skip_damaged: bool = False,
    cwa_times: str = "skdh",
    inspect: bool = False,
) -> None:
    """Convert device exports into one MCAP trial (or a folder of exports into one trial per recording).

    Each INPUT's format is detected from its content (override with --format); an IMU file and a Vicon file
    given together become one trial. The original files are attached byte for byte with their SHA-256; above
    64 MB (--attach-original auto) they are recorded by name, size and SHA-256 instead.

    \b
    Examples:
      imulog convert --list-formats
      imulog convert fusion_sensor_data.csv -o imu.mcap --meta subject=S01 --meta side=right
      imulog convert s01_imu.csv s01_vicon.csv -o s01.mcap --meta-file subject.toml
      imulog convert wrist.csv --mapping bluebuddy.mapping.json -o wrist.mcap
      imulog convert witilt.txt --rate 50 --adc-zero 510 -o tilt.mcap
      imulog convert wrist_acc.csv --unit acc=g --unit gyr=deg/s -o wrist.mcap   # header without units
      imulog convert exports/ -o trials/          # one trial per recording, with a progress bar
      imulog convert week.cwa -o week.mcap --attach-original never   # record the .cwa's hash, keep it apart
      imulog convert --inspect odd_export.csv     # what would be made, nothing written

    In folder mode the files of one recording share a name stem apart from role words (s01_imu.csv +
    s01_vicon.csv), and a s01_meta.json/.toml beside them adds that trial's metadata.

    Bad input stops with one line naming the file, line and column, and leaves no output file.
    """
    if list_formats_flag:
        for name, exts, desc in list_formats():
            click.echo(f"{name:12s} {exts:20s} {desc}")
        return
    if not inputs:
        raise click.UsageError("give at least one INPUT (or --list-formats)")
    if inspect:
        _inspect(inputs, fmt, mapping, rate_hz, device_names, unit_pairs, as_json)
        return
    if output is None:
        raise click.UsageError("give the output with -o/--output")
    if fmt and fmt not in available():
        raise click.BadParameter(f"unknown format {fmt!r}; known: {', '.join(available())}", param_hint="--format")
    attach_mode = "never" if no_attach else attach_original
    meta: dict[str, dict[str, Any]] = {}
    if meta_file:
        meta = load_meta_file(meta_file)
    for name, values in parse_meta(meta_pairs).items():
        meta.setdefault(name, {}).update(values)
    options = ConvertOptions(
        mapping=mapping,
        rate_hz=rate_hz,
        extra={
            "zero_counts": adc_zero,
            "counts_per_g": adc_counts_per_g,
            "names": _kv(device_names, "--device-name"),
            "units": _units(unit_pairs),
            "skip_damaged": skip_damaged,
            "cwa_times": cwa_times,
        },
    )
    dirs = [p for p in inputs if p.is_dir()]
    if dirs:
        if len(dirs) != len(inputs):
            raise click.UsageError("give either files (one trial) or folders (one trial per recording), not both")
        _convert_directories(dirs, output, fmt, options, meta, attach=attach_mode, overwrite=overwrite, as_json=as_json)
        return
    if output.suffix.lower() != ".mcap":
        raise click.UsageError(f"output {output} should end in .mcap")
    refuse_existing(output, overwrite=overwrite)  # before any reading
    if len(inputs) == 1 and _streams(inputs[0], fmt, options):
        _convert_streaming(
            inputs[0], output, fmt, options, meta, attach=attach_mode, overwrite=overwrite, as_json=as_json
        )
        return
    try:
        rec, formats = _convert_group(list(inputs), fmt, options)
        finish_recording(rec, meta, formats)
        path = _write(output, rec, attach=attach_mode, overwrite=overwrite)
    except ConversionError as e:
        raise click.ClickException(str(e)) from None
    except (FileExistsError, ValueError, OSError) as e:
        raise click.ClickException(f"{output}: {e}") from None
    if as_json:
        _echo_json(
            [
                {
                    "path": str(path),
                    "channels": {s.topic: len(s) for s in rec.streams()},
                    "warnings": conversion_warnings(rec),
                }
            ],
            [],
        )
        return
    click.echo(f"wrote {path} ({', '.join(f'{s.topic} {len(s)}' for s in rec.streams())})")
    for msg in conversion_warnings(rec):
        click.echo(f"warning: {output}: {msg}", err=True)


def _inspect(
    inputs: tuple[Path, ...],
    fmt: str | None,
    mapping: Path | None,
    rate_hz: float | None,
    device_names: tuple[str, ...],
    unit_pairs: tuple[str, ...],
    as_json: bool,
) -> None:
    """``--inspect``: convert in memory and describe the result (files as one trial, folders per recording)."""
    from imulog.commands.convert_inspect import describe, render

    options = ConvertOptions(
        mapping=mapping,
        rate_hz=rate_hz,
        extra={"names": _kv(device_names, "--device-name"), "units": _units(unit_pairs)},
    )
    groups: list[list[Path]] = []
    for p in inputs:
        if p.is_dir():
            groups.extend(files for _, files in sessions(group_directory(p)))
        else:
            groups.append([p])
    if all(not p.is_dir() for p in inputs):
        groups = [list(inputs)]
    if not groups:
        raise click.ClickException(f"no convertible files under {', '.join(map(str, inputs))}")
    reports, failures = [], []
    for files in groups:
        try:
            formats = [_format_name(p, fmt, options) for p in files]
            rec = convert_files(files, options=options, formats=formats)
            reports.append(describe(files, formats, rec, unit_warnings(rec), options))
        except ConversionError as e:
            failures.append(str(e))
    if as_json:
        click.echo(json.dumps({"inspect": reports, "errors": failures}, indent=2, default=str))
    else:
        for k, report in enumerate(reports):
            if k:
                click.echo("")
            for line in render(report):
                click.echo(line)
    if failures:
        if not as_json:
            for msg in failures[:-1]:
                click.echo(f"error: {msg}", err=True)
            raise click.ClickException(failures[-1])
        raise click.exceptions.Exit(1)


#: formats of optical (motion capture) exports: beside one IMU recording in a folder, they are its session's
OPTICAL_FORMATS = frozenset({"c3d", "vicon-csv", "motive", "qualisys", "opensim-trc"})


def _is_optical(files: list[Path]) -> bool:
    """True when every file of a recording is an optical export (:data:`OPTICAL_FORMATS`)."""
    try:
        return all(detect(p).name in OPTICAL_FORMATS for p in files)
    except ConversionError:
        return False


def sessions(groups: list[tuple[str, list[Path]]]) -> list[tuple[str, list[Path]]]:
    """One trial per session: in each folder, a single recording with IMU data (e.g. 11 per-sensor Xsens files)
    and the optical exports beside it (C3D, Nexus CSV, Motive, Qualisys, TRC) are one trial, named after the
    IMU recording. A folder with several IMU recordings keeps one trial per recording."""
    by_folder: dict[Path, list[tuple[str, list[Path]]]] = {}
    for name, files in groups:
        by_folder.setdefault(files[0].parent, []).append((name, files))
    out: list[tuple[str, list[Path]]] = []
    for found in by_folder.values():
        optical = [_is_optical(files) for _, files in found]
        imu = [g for g, opt in zip(found, optical, strict=True) if not opt]
        if len(imu) == 1 and len(found) > 1:
            out.append(
                (
                    imu[0][0],
                    [*imu[0][1], *(p for (_, files), opt in zip(found, optical, strict=True) if opt for p in files)],
                )
            )
        else:
            out.extend(found)
    return out


def _convert_folder_group(
    files: list[Path], fmt: str | None, options: ConvertOptions
) -> tuple[Recording, dict[str, str], list[tuple[Path, str]]]:
    """Convert the files of one folder trial; a file that fails to convert is left out and returned with its
    reason (the others still make the trial). Files that convert but cannot be combined are an error."""
    skipped: list[tuple[Path, str]] = []
    todo = list(files)
    while True:
        try:
            rec, formats = _convert_group(todo, fmt, options)
            return rec, formats, skipped
        except ConversionError as e:
            bad = next((p for p in todo if e.path == str(p)), None)
            if bad is None or len(todo) == 1 or e.problem.startswith("cannot combine"):
                raise
            skipped.append((bad, e.problem))
            todo.remove(bad)


def _sibling_meta(files: list[Path]) -> dict[str, dict[str, Any]]:
    """Per-recording metadata beside the exports: ``<key>_meta.json`` / ``<key>.meta.toml`` (as the simulator writes)."""
    try:
        conv = detect(files[0])
    except ConversionError:
        conv = None
    key = recording_key(files[0], conv)  # the format's own key (Xsens: MT_<master>_<trial>) when it has one
    for suffix in ("_meta.json", "_meta.toml", ".meta.json", ".meta.toml"):
        candidate = files[0].parent / f"{key}{suffix}"
        if key and candidate.is_file():
            return load_meta_file(candidate)
    return {}


def _convert_directories(
    dirs: list[Path],
    out_dir: Path,
    fmt: str | None,
    options: ConvertOptions,
    meta: dict,
    *,
    attach: str,
    overwrite: bool,
    as_json: bool = False,
) -> None:
    jobs: list[tuple[Path, list[Path]]] = []
    skipped: list[tuple[Path, str]] = []
    for d in dirs:
        for name, files in sessions(group_directory(d, skipped)):
            prefix = d.name if len(dirs) > 1 else ""
            jobs.append((out_dir / prefix / f"{name}.mcap", files))
    if not jobs:
        reasons = "".join(f"; {p.name}: {why}" for p, why in skipped[:3])
        raise click.ClickException(f"no convertible files under {', '.join(map(str, dirs))}{reasons}")
    if out_dir.suffix.lower() == ".mcap":  # -o trial.mcap: fine for a folder holding one recording
        if len(jobs) != 1:
            raise click.UsageError(
                f"the folder holds {len(jobs)} recordings, one trial each: give an output folder "
                f"(e.g. -o {out_dir.with_suffix('')}/), not {out_dir} (one session is one trial: one IMU "
                "recording, e.g. per-sensor files sharing a name, with its optical exports; or list the files)"
            )
        jobs = [(out_dir, jobs[0][1])]
    failures: list[str] = []
    warnings: list[str] = []
    written = 0
    trials: list[dict[str, Any]] = []
    with click.progressbar(
        jobs, label="converting", item_show_func=lambda j: j[0].name if j else "", file=sys.stderr
    ) as bar:
        for target, files in bar:
            try:
                rec, formats, left_out = _convert_folder_group(files, fmt, options)
                skipped.extend(left_out)
                trial_meta = _sibling_meta(files)
                for name, values in meta.items():
                    trial_meta.setdefault(name, {}).update(values)
                finish_recording(rec, trial_meta, formats)
                target.parent.mkdir(parents=True, exist_ok=True)
                _write(target, rec, attach=attach, overwrite=overwrite)
                written += 1
                warnings.extend(f"{target}: {msg}" for msg in conversion_warnings(rec))
                trials.append(
                    {
                        "path": str(target),
                        "channels": {s.topic: len(s) for s in rec.streams()},
                        "warnings": conversion_warnings(rec),
                        "inputs": [p.name for p in files if p not in {q for q, _ in left_out}],
                    }
                )
            except ConversionError as e:
                failures.append(str(e))
            except (FileExistsError, ValueError, OSError) as e:
                failures.append(f"{target}: {e}")
    if as_json:
        _echo_json(trials, failures, skipped)
        if failures:
            raise click.exceptions.Exit(1)
        return
    if out_dir.suffix.lower() == ".mcap" and trials:
        click.echo(f"wrote {out_dir} from {len(trials[0]['inputs'])} files ({_channel_list(trials[0]['channels'])})")
    else:
        click.echo(f"wrote {written} trial(s) to {out_dir}")
    for path, why in skipped:
        click.echo(f"skipped {path}: {why}", err=True)
    for msg in warnings:
        click.echo(f"warning: {msg}", err=True)
    for msg in failures:
        click.echo(f"error: {msg}", err=True)
    if failures:
        raise click.exceptions.Exit(1)
