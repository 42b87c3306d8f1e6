"""What every ``imulog convert`` path shares: metadata records, the format of a file, the atomic write, option parsing, JSON output."""

from __future__ import annotations

import hashlib
import json
import tomllib
from pathlib import Path
from typing import Any

import click

from imulog.converters import ConversionError, ConvertOptions, UnknownFormatError
from imulog.converters.registry import (
    convert_files,
    detect,
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


def _convert_group(
    files: list[Path], fmt: str | None, options: ConvertOptions, names: list[str] | None = None
) -> tuple[Recording, dict[str, str]]:
    """``files`` as one recording, and each file's format; ``names``: the formats when already detected."""
    if names is None:
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


def skipped_records(skipped: list[tuple[Path, str]]) -> list[dict[str, str]]:
    """The files a folder's conversion left out, for ``--json``: ``{"path", "reason"}`` each."""
    return [{"path": str(p), "reason": why} for p, why in skipped]


def echo_skipped(skipped: list[tuple[Path, str]]) -> None:
    """The files a folder's conversion left out, one line each on stderr (as warnings and errors):
    ``skipped PATH: reason``; ``convert FOLDER`` and ``convert --inspect FOLDER`` both print them so."""
    for path, why in skipped:
        click.echo(f"skipped {path}: {why}", err=True)


def _echo_json(
    trials: list[dict[str, Any]], failures: list[str], skipped: list[tuple[Path, str]] | None = None
) -> None:
    """``--json``: the trials written (path, samples per channel, warnings), the failures, the files skipped."""
    import json

    doc: dict[str, Any] = {"trials": trials, "failures": failures}
    if skipped:
        doc["skipped"] = skipped_records(skipped)
    click.echo(json.dumps(doc, indent=2))


def _channel_list(counts: dict[str, int]) -> str:
    """``/imu/a 3369, /markers/vicon 700`` (samples per channel)."""
    return ", ".join(f"{t} {n}" for t, n in counts.items())


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
