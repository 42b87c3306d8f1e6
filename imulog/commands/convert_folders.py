"""``imulog convert`` of folders: one trial per session (an IMU recording with the optical exports beside it)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from imulog.commands import convert_stream
from imulog.commands.convert_common import (
    _channel_list,
    _convert_group,
    _echo_json,
    _format_name,
    _write,
    conversion_warnings,
    echo_skipped,
    finish_recording,
    load_meta_file,
)
from imulog.commands.convert_stream import session_converter
from imulog.converters import ConversionError, ConvertOptions
from imulog.converters.base import Converter
from imulog.converters.registry import (
    detect,
    group_directory,
    reader_errors,
    recording_key,
)
from imulog.converters.values import check_recording
from imulog.model import Recording

#: formats of optical (motion capture) exports: beside one IMU recording in a folder, they are its session's
OPTICAL_FORMATS = frozenset({"c3d", "vicon-csv", "motive", "qualisys", "opensim-trc"})


Detected = dict[Path, Converter]  # each file's converter, as group_directory(..., detected=) found it


def _detected(path: Path, detected: Detected | None) -> Converter:
    """The converter of ``path``: the one already detected (``detected``), else :func:`detect` now."""
    if detected is not None and path in detected:
        return detected[path]
    return detect(path)


def format_names(files: list[Path], fmt: str | None, options: ConvertOptions, detected: Detected | None) -> list[str]:
    """The format each file converts with: forced (``fmt``), already detected, else ``_format_name`` (detects)."""
    if fmt:
        return [fmt] * len(files)
    return [detected[p].name if detected and p in detected else _format_name(p, fmt, options) for p in files]


def _is_optical(files: list[Path], detected: Detected | None = None) -> bool:
    """True when every file of a recording is an optical export (:data:`OPTICAL_FORMATS`)."""
    try:
        return all(_detected(p, detected).name in OPTICAL_FORMATS for p in files)
    except ConversionError:
        return False


def sessions(groups: list[tuple[str, list[Path]]], detected: Detected | None = None) -> list[tuple[str, list[Path]]]:
    """One trial per session: in each folder, a single recording with IMU data (e.g. 11 per-sensor Xsens files)
    and the optical exports beside it (C3D, Nexus CSV, Motive, Qualisys, TRC) are one trial, named after the
    IMU recording. A folder with several IMU recordings keeps one trial per recording. ``detected``: each
    file's converter when already known (:func:`~imulog.converters.registry.group_directory`)."""
    by_folder: dict[Path, list[tuple[str, list[Path]]]] = {}
    for name, files in groups:
        by_folder.setdefault(files[0].parent, []).append((name, files))
    out: list[tuple[str, list[Path]]] = []
    for found in by_folder.values():
        optical = [_is_optical(files, detected) for _, files in found]
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


def unique_names(groups: list[tuple[str, list[Path]]]) -> list[tuple[str, list[Path]]]:
    """Each trial its own output name. The rule (docs/converters.md): a trial is named by its recording's stem
    (``ax3_sample.cwa`` -> ``ax3_sample``, ``s01_t02_imu.csv`` + ``s01_t02_vicon.csv`` -> ``s01_t02``); every
    trial of a stem shared by several (``s01.c3d`` and ``s01.h5`` in a folder with a second IMU recording, both
    ``s01``) keeps its first file's extension (``s01.c3d``, ``s01.h5``), then a counter (``s01.csv_2``) when
    even those collide; before, the second was refused as existing, or with --overwrite replaced the first."""
    count: dict[str, int] = {}
    for name, _ in groups:
        count[name] = count.get(name, 0) + 1
    taken: set[str] = set()
    out = []
    for name, files in groups:
        if count[name] > 1 and files[0].suffix:
            name += files[0].suffix.lower()
        unique, k = name, 1
        while unique in taken:
            k += 1
            unique = f"{name}_{k}"
        taken.add(unique)
        out.append((unique, files))
    return out


def _convert_folder_group(
    files: list[Path], fmt: str | None, options: ConvertOptions, names: list[str]
) -> tuple[Recording, dict[str, str], list[tuple[Path, str]]]:
    """Convert the files of one folder trial (``names``: their formats, :func:`format_names`); a file that fails
    to convert is left out and returned with its reason (the others still make the trial). Files that convert but
    cannot be combined are an error."""
    skipped: list[tuple[Path, str]] = []
    todo = dict(zip(files, names, strict=True))
    while True:
        try:
            rec, formats = _convert_group(list(todo), fmt, options, list(todo.values()))
            return rec, formats, skipped
        except ConversionError as e:
            bad = next((p for p in todo if e.path == str(p)), None)
            if bad is None or len(todo) == 1 or e.problem.startswith("cannot combine"):
                raise
            skipped.append((bad, e.problem))
            del todo[bad]


def _sibling_meta(files: list[Path], detected: Detected | None = None) -> dict[str, dict[str, Any]]:
    """Per-recording metadata beside the exports: ``<key>_meta.json`` / ``<key>.meta.toml`` (as the simulator writes)."""
    try:
        conv = _detected(files[0], detected)
    except ConversionError:
        conv = None
    key = recording_key(files[0], conv)  # the format's own key (Xsens: MT_<master>_<trial>) when it has one
    for suffix in ("_meta.json", "_meta.toml", ".meta.json", ".meta.toml"):
        candidate = files[0].parent / f"{key}{suffix}"
        if key and candidate.is_file():
            return load_meta_file(candidate)
    return {}


def convert_session(files: list[Path], conv: Converter, options: ConvertOptions) -> Recording:
    """The files of one session as one recording (``conv.iter_session`` in one piece), value-checked as
    :func:`~imulog.converters.registry.convert_file` checks a file; errors name the file (or the folder)."""
    folder = files[0].parent
    with reader_errors(folder, conv):
        (rec,) = conv.iter_session(files, options, whole=True)
        check_recording(rec, folder)
    return rec


def _stream_session(
    files: list[Path], target: Path, fmt: str, options: ConvertOptions, meta: dict, attach: str, overwrite: bool
) -> dict[str, Any]:
    """One session's files converted piece by piece (time windows of every file) into ``target``: its JSON entry.
    ``fmt``: the session's format (forced or already detected: nothing is detected again)."""
    from imulog.commands.outputs import exists_message

    if target.exists() and not overwrite:  # the whole-folder path's line (_write), before anything is read
        raise ConversionError(None, exists_message(target))
    try:
        counts, notes = convert_stream._convert_streaming(
            files[0].parent, target, fmt, options, meta, attach=attach, overwrite=overwrite, files=files
        )
    except click.ClickException as e:  # its one line, a failure of this trial as in the whole-folder path
        raise ConversionError(None, e.message) from None
    return {
        "path": str(target),
        "channels": counts,
        "warnings": notes,
        "inputs": [p.name for p in files],
        "streamed": True,
    }


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
    named: list[tuple[str, list[Path]]] = []
    skipped: list[tuple[Path, str]] = []
    detected: Detected = {}  # each file's format is detected once, while grouping; everything below reuses it
    for d in dirs:
        for name, files in sessions(group_directory(d, skipped, detected), detected):
            named.append((f"{d.name}/{name}" if len(dirs) > 1 else name, files))
    # unique over every folder given (two folders named data/ share the prefix)
    jobs = [(out_dir / f"{name}.mcap", files) for name, files in unique_names(named)]
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
                trial_meta = _sibling_meta(files, detected)
                for name, values in meta.items():
                    trial_meta.setdefault(name, {}).update(values)
                names = format_names(files, fmt, options, detected)
                session = session_converter(files, fmt, options, names)
                if session is not None and sum(p.stat().st_size for p in files) >= convert_stream.STREAM_MIN_BYTES:
                    target.parent.mkdir(parents=True, exist_ok=True)
                    trials.append(_stream_session(files, target, session.name, options, trial_meta, attach, overwrite))
                    warnings.extend(f"{target}: {msg}" for msg in trials[-1]["warnings"])
                    written += 1
                    continue
                if session is not None:  # a session read as one: a damaged file fails it (as in pieces)
                    rec, left_out = convert_session(files, session, options), []
                    formats = {p.name: session.name for p in files}
                else:
                    rec, formats, left_out = _convert_folder_group(files, fmt, options, names)
                skipped.extend(left_out)
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
        how = "; converted piece by piece" if trials[0].get("streamed") else ""
        click.echo(
            f"wrote {out_dir} from {len(trials[0]['inputs'])} files ({_channel_list(trials[0]['channels'])}{how})"
        )
    else:
        click.echo(f"wrote {written} trial(s) to {out_dir}")
    echo_skipped(skipped)
    for msg in warnings:
        click.echo(f"warning: {msg}", err=True)
    for msg in failures:
        click.echo(f"error: {msg}", err=True)
    if failures:
        raise click.exceptions.Exit(1)
