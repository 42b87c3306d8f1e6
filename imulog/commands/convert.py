"""``imulog convert``: device exports (IMU text, Vicon CSV, C3D, ...) -> one self-describing MCAP trial."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from imulog.commands.convert_common import (
    TRIAL_RECORD,
    _convert_group,
    _echo_json,
    _format_name,
    _kv,
    _units,
    _write,
    conversion_record,
    conversion_warnings,
    echo_skipped,
    finish_recording,
    load_meta_file,
    parse_meta,
    parse_value,
    record_name,
    sha256_of,
    skipped_records,
    unit_warnings,
)
from imulog.commands.convert_folders import (
    OPTICAL_FORMATS,
    _convert_directories,
    format_names,
    sessions,
)
from imulog.commands.convert_stream import (
    STREAM_MIN_BYTES,
    _convert_streaming,
    _streams,
)
from imulog.commands.outputs import overwrite_option, refuse_existing
from imulog.converters import ConversionError, ConvertOptions
from imulog.converters.registry import (
    available,
    convert_files,
    group_directory,
    list_formats,
)

__all__ = [
    "conversion_record",
    "conversion_warnings",
    "convert",
    "finish_recording",
    "load_meta_file",
    "OPTICAL_FORMATS",
    "parse_meta",
    "parse_value",
    "record_name",
    "sessions",
    "sha256_of",
    "STREAM_MIN_BYTES",
    "TRIAL_RECORD",
    "unit_warnings",
]


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
    "--rate",
    "rate_hz",
    type=float,
    metavar="HZ",
    help="Sampling rate for files without time stamps (raw ADC text); for delimited text with a time column, the "
    "device's nominal rate, declared beside the stamps (kept as they are; process epochs counts at it).",
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
    s01_vicon.csv), and a s01_meta.json/.toml beside them adds that trial's metadata. Each trial is named
    by its recording's stem, whatever the format (s01.mcap, ax3_sample.mcap from ax3_sample.cwa); trials
    whose stems collide all keep their file's extension (s01.csv.mcap and s01.c3d.mcap).

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
    try:
        names = [_format_name(p, fmt, options) for p in inputs]  # each file sniffed once, for both paths below
    except ConversionError as e:
        raise click.ClickException(str(e)) from None
    if len(inputs) == 1 and _streams(inputs[0], names[0]):
        _convert_streaming(
            inputs[0], output, names[0], options, meta, attach=attach_mode, overwrite=overwrite, as_json=as_json
        )
        return
    try:
        rec, formats = _convert_group(list(inputs), fmt, options, names)
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
    detected: dict[Path, Any] = {}  # each file of a folder detected once, while grouping
    skipped: list[tuple[Path, str]] = []  # a folder's exports of a device file beside them, unknown data files
    for p in inputs:
        if p.is_dir():
            groups.extend(files for _, files in sessions(group_directory(p, skipped, detected), detected))
        else:
            groups.append([p])
    if all(not p.is_dir() for p in inputs):
        groups = [list(inputs)]
    if not groups:
        raise click.ClickException(f"no convertible files under {', '.join(map(str, inputs))}")
    reports, failures = [], []
    for files in groups:
        try:
            formats = format_names(files, fmt, options, detected)
            rec = convert_files(files, options=options, formats=formats)
            reports.append(describe(files, formats, rec, unit_warnings(rec), options))
        except ConversionError as e:
            failures.append(str(e))
    if as_json:
        doc = {"inspect": reports, "errors": failures, "skipped": skipped_records(skipped)}
        click.echo(json.dumps(doc, indent=2, default=str))
    else:
        for k, report in enumerate(reports):
            if k:
                click.echo("")
            for line in render(report):
                click.echo(line)
        echo_skipped(skipped)
    if failures:
        if not as_json:
            for msg in failures[:-1]:
                click.echo(f"error: {msg}", err=True)
            raise click.ClickException(failures[-1])
        raise click.exceptions.Exit(1)
