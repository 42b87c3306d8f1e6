"""``imulog calibrate`` (estimate a calibration file) and ``imulog process calibrate`` (apply one)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click

from imulog.commands.imus import imu_option
from imulog.commands.outputs import overwrite_option, refuse_existing


@click.command("calibrate")
@click.argument("recordings", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True, help="Calibration JSON to write."
)
@click.option("--imu", default=None, help="IMU name (channel /imu/NAME); default: the only IMU, else 'wrist'.")
@click.option(
    "--angle-deg",
    type=float,
    default=360.0,
    show_default=True,
    help="Known angle of each gyroscope rotation between static periods, degrees.",
)
@click.option(
    "--static-threshold", type=float, default=0.1, show_default=True, help="Static if gyro norm < this, rad/s."
)
@click.option("--min-static-s", type=float, default=2.0, show_default=True, help="Shortest static period, s.")
@click.option("--gravity", type=float, default=9.80665, show_default=True, help="Local gravity, m/s^2.")
@overwrite_option()
def calibrate(
    recordings: tuple[Path, ...],
    output: Path,
    imu: str | None,
    angle_deg: float,
    static_threshold: float,
    min_static_s: float,
    gravity: float,
    overwrite: bool,
) -> None:
    """Estimate accelerometer and gyroscope calibration from calibration RECORDINGS (trial .mcap files).

    Accelerometer (R2G thesis eqs. 2.1-2.3): hold the sensor still with each axis pointing up and
    then down (six static periods of >= 2 s, any order). Gyroscope (eqs. 2.4-2.5): a static period,
    then rotations of a known angle (--angle-deg, e.g. one turn) about each axis, separated by static
    periods. Bias and calibration matrix C are written so that calibrated = C (raw - bias). Several
    recordings may be given (e.g. one per sensor); each part is taken from the first recording
    that has it.

    \b
    Examples:
      imulog convert calib_imu.csv -o calib.mcap
      imulog calibrate calib.mcap -o bluebuddy_cal.json
      imulog calibrate six_positions.mcap turntable.mcap -o cal.json --angle-deg 360
      imulog process calibrate trial.mcap --calibration cal.json
    """
    from imulog.archive import TrialReader
    from imulog.archive.errors import ArchiveError
    from imulog.process.calibration import Calibration, SegmentParams
    from imulog.steps.calibrate import calibration_from_arrays
    from imulog.steps.common import error_line, pick_imu

    refuse_existing(output, overwrite=overwrite)
    seg = SegmentParams(static_threshold_rad_s=static_threshold, min_static_s=min_static_s)
    result = Calibration()
    notes = []
    with click.progressbar(recordings, label="calibrating") as bar:
        for path in bar:
            try:
                with TrialReader(path) as reader:
                    name = pick_imu(reader.topics(), imu)
                    s = reader.read(f"/imu/{name}")
                    device = reader.metadata.get(f"imulog.device.{name}", {})
                if s.gyr is None:
                    raise ValueError(f"/imu/{name} has no gyroscope columns")
                c = calibration_from_arrays(
                    s.t_ns, s.acc, s.gyr, angle_rad=math.radians(angle_deg), params=seg, g_m_s2=gravity
                )
            except (ArchiveError, ValueError, KeyError, OSError) as exc:
                notes.append(error_line(path, exc))
                continue
            if result.acc is None and c.acc is not None:
                result.acc = c.acc
                result.info["acc_source"] = str(path)
            if result.gyr is None and c.gyr is not None:
                result.gyr = c.gyr
                result.info["gyr_source"] = str(path)
            result.device = result.device or {k: device[k] for k in ("model", "serial") if k in device}
            result.info.setdefault("imu", name)
    if result.acc is None and result.gyr is None:
        raise click.ClickException("no calibration could be estimated: " + "; ".join(notes))
    if notes:
        result.info["notes"] = notes
    output.write_text(json.dumps(result.to_dict(), indent=2) + "\n")
    parts = [p for p in ("acc", "gyr") if getattr(result, p) is not None]
    click.echo(f"wrote {output} ({' and '.join(parts)})" + (f"; skipped: {'; '.join(notes)}" if notes else ""))


@click.command("calibrate")
@click.argument("trial", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--calibration",
    "calibrations",
    multiple=True,
    required=True,
    metavar="[IMU=]FILE",
    help="Calibration JSON written by `imulog calibrate`: FILE for the IMUs chosen by --imu (default: every IMU), "
    "or IMU=FILE (repeatable) for one sensor's own calibration.",
)
@imu_option("IMU to calibrate with a plain --calibration FILE (repeatable); default: every IMU of the trial.")
@click.option("--force", is_flag=True, help="Recompute even when the same calibration is already applied.")
def process_calibrate(trial: Path, calibrations: tuple[str, ...], imus: tuple[str, ...], force: bool) -> None:
    """Apply a calibration file to TRIAL: writes /derived/calibrated/IMU (acc m/s^2, gyr rad/s).

    The raw channel is never modified; `imulog process orientation` then uses the calibrated
    channel automatically (--source auto). One run per IMU (calibrate:IMU), one summary table.

    \b
    Examples:
      imulog process calibrate trial.mcap --calibration bluebuddy_cal.json
      imulog process calibrate two.mcap --calibration left=left_cal.json --calibration right=right_cal.json
      imulog process orientation trial.mcap
    """
    from imulog.commands.imus import choose_imus, run_per_imu
    from imulog.steps.calibrate import run_calibrate

    files = _calibration_files(calibrations)
    if None in files:
        if len(files) > 1:
            raise click.BadParameter("give one FILE, or IMU=FILE pairs, not both", param_hint="--calibration")
        names = choose_imus(trial, imus)
        files = dict.fromkeys(names, files[None])
    else:
        if imus:
            raise click.BadParameter("IMU=FILE pairs name their IMUs: leave out --imu", param_hint="--calibration")
        choose_imus(trial, list(files))  # every named IMU must exist
    cals = {name: _load_calibration(path) for name, path in files.items()}

    def one(name: str):
        outcome = run_calibrate(trial, cals[name], imu=name, force=force)
        text = ("unchanged: " if outcome.skipped else "wrote ") + ", ".join(outcome.topics)
        return outcome, f"/derived/calibrated/{name} from {files[name].name}", text

    run_per_imu(trial, list(cals), one, what="calibrate")


def _calibration_files(values: tuple[str, ...]) -> dict[str | None, Path]:
    """``FILE`` -> {None: FILE}; ``IMU=FILE`` -> {IMU: FILE}; every file must exist."""
    out: dict[str | None, Path] = {}
    for value in values:
        name, sep, file = value.partition("=")
        key, path = (name.strip(), Path(file)) if sep and not Path(value).exists() else (None, Path(value))
        if not path.is_file():
            raise click.BadParameter(f"no calibration file {path}", param_hint="--calibration")
        if key in out:
            raise click.BadParameter(f"{key or 'FILE'} given twice", param_hint="--calibration")
        out[key] = path
    return out


def _load_calibration(path: Path):
    from imulog.process.calibration import Calibration

    try:
        return Calibration.from_dict(json.loads(path.read_text()))
    except (ValueError, KeyError, OSError) as exc:
        raise click.ClickException(f"{path}: {exc}") from exc
