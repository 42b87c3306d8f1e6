"""``imulog simulate``: synthetic trials with ground truth, written in the raw export formats."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import click

from imulog.commands.outputs import overwrite_option, refuse_existing


def parse_value(text: str) -> Any:
    """``3`` -> 3, ``0.01`` -> 0.01, ``true`` -> True, ``[0.1, 0.5]`` -> list; anything else stays a string."""
    try:
        return json.loads(text)
    except ValueError:
        return text


def _bad_settings(error: Exception, settings: tuple[str, ...]) -> str:
    """The simulator's message, plus the --set values when a type error may come from one of them."""
    if isinstance(error, TypeError) and settings:
        return f"{error} (check the types of --set {' --set '.join(settings)}; --list-parameters names them)"
    return str(error)


PROTOCOL_CHOICES = ("r2g", "slide", "nhpt", "adl", "continuous", "arm", "home")
ARM_ONLY = ("--seconds", "--trunk-imu")


def _planned(out_dir: Path, protocol: str, subjects: int, trials: int) -> list[Path]:
    """The existing files a run would replace: every ``<protocol>_sSS_tTT*`` of the planned trials in ``out_dir``."""
    if not out_dir.is_dir():
        return []
    stems = {f"{protocol}_s{s:02d}_t{t:02d}" for s in range(subjects) for t in range(trials)}
    return sorted(p for p in out_dir.iterdir() if any(p.name.startswith((st + "_", st + ".")) for st in stems))


def _overrides(pairs: tuple[str, ...]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise click.BadParameter(f"{pair!r} is not NAME=VALUE", param_hint="--set")
        out[key.strip()] = parse_value(value)
    return out


@click.command(context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("protocol", type=click.Choice(PROTOCOL_CHOICES))
@click.option(
    "-o",
    "--output",
    "out_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder for the trial files (created).",
)
@click.option("--subjects", type=click.IntRange(1), default=1, show_default=True, help="Number of simulated subjects.")
@click.option("--trials", type=click.IntRange(1), default=1, show_default=True, help="Trials per subject.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed: same seed, same files.")
@click.option(
    "--repetitions",
    type=click.IntRange(1),
    help="Repetitions per trial (protocol default: r2g 25, slide 30, nhpt 1, adl 10).",
)
@click.option("--noise-free", is_flag=True, help="Ideal sensors: no noise, bias, quantisation, drops or marker gaps.")
@click.option(
    "--set",
    "settings",
    multiple=True,
    metavar="NAME=VALUE",
    help="Any model parameter (repeatable), e.g. --set drift_ppm=40 --set residual_velocity_mps=0.01.",
)
@click.option("--list-parameters", is_flag=True, help="List the parameters PROTOCOL accepts with --set and exit.")
@click.option(
    "--seconds",
    type=click.FloatRange(min=5.0),
    help="arm only: trial duration, s (default 60; at least the 3 s neutral posture + 2 s blend).",
)
@click.option("--trunk-imu", is_flag=True, help="arm only: add a trunk IMU and its marker cluster.")
@click.option(
    "--days",
    type=click.FloatRange(min=1 / 1440),
    help="home only: recording length in days (default 1; a week at 100 Hz is a 770 MB .cwa, written chunk by chunk).",
)
@overwrite_option("Replace trial files of the same names in OUTPUT (without it, they are refused).")
@click.option(
    "--lsl",
    is_flag=True,
    help="Then stream the first trial live as Lab Streaming Layer outlets, in real time (imulog record records it).",
)
def simulate(
    protocol: str,
    out_dir: Path,
    subjects: int,
    trials: int,
    seed: int,
    repetitions: int | None,
    noise_free: bool,
    settings: tuple[str, ...],
    list_parameters: bool,
    seconds: float | None,
    trunk_imu: bool,
    days: float | None,
    overwrite: bool = False,
    lsl: bool = False,
) -> None:
    """Simulate PROTOCOL trials with known ground truth.

    Each trial is written as a lab would have it -- a BlueBuddy-style IMU text file with its
    mapping file (<stem>_imu.csv, <stem>_imu.mapping.json), a Vicon Nexus CSV (<stem>_vicon.csv),
    for adl also raw ADC text (<stem>_adc.txt) -- plus the trial metadata for `imulog convert
    --meta-file` (<stem>_meta.json) and the ground truth (<stem>_truth.json + .npz: true wrist
    position, velocity, orientation, phases, IMU-to-Vicon clock offset and drift, rotations).

    \b
    Protocols:
      r2g    drinking task (R2G thesis ch. 3): 25 x reach, lift, return_bottle, return_hand
      slide  uniaxial cart on rails (R2G thesis ch. 2): 30 constant-acceleration slides
      nhpt   nine-hole peg test (Bai et al. 2023): 9 pegs in, 9 pegs out
      adl    repetitive activities of daily living (Doshi 2011)
      continuous  60 s of continuous motion with one 0.3 s rest and glides where the wrist stops
             turning while it translates (a hand-moved chain; tests rest detection, issue 32)
      arm    two-segment arm (Caruso et al. 2024): upper-arm and forearm IMUs (optionally trunk),
             known shoulder and elbow angles, for `imulog process kinematics`
      home   days of wrist data at home (Doshi 2011 ch. 5) as an Axivity AX6 .cwa, --days 7 for a week

    \b
    Examples:
      imulog simulate r2g -o sim/                         # one 25-task drinking trial
      imulog simulate r2g -o sim/ --subjects 3 --trials 2 --seed 1
      imulog simulate r2g -o sim/ --repetitions 5 --noise-free
      imulog simulate r2g -o sim/ --set residual_velocity_mps=0.01 --set extra_submovement_probability=0.1
      imulog simulate slide -o sim/ --set drift_ppm=0
      imulog convert sim/r2g_s00_t00_imu.csv sim/r2g_s00_t00_vicon.csv \\
          --meta-file sim/r2g_s00_t00_meta.json -o r2g.mcap

    For arm, both IMUs of the synchronised station are in <stem>_imu.csv (a sensor row names each
    IMU's columns), both marker clusters (upper_arm_O, ..., forearm_O, ...) in <stem>_vicon.csv,
    the imulog.kinematics record in <stem>_meta.json and the true joint angles in the truth files
    (read them with imulog.simulate.arm.load_arm_truth):

    \b
      imulog simulate arm -o sim/ --seconds 30 --seed 2 [--trunk-imu] [--noise-free]
      imulog convert sim/ -o trials/
      imulog process orientation trials/arm_s00_t00.mcap --imu upper_arm
      imulog process orientation trials/arm_s00_t00.mcap --imu forearm
      imulog process kinematics trials/arm_s00_t00.mcap

    With --lsl the first trial is then streamed live as LSL outlets (docs/record.md):

    \b
      imulog simulate r2g -o sim/ --repetitions 5 --lsl     # terminal 1
      imulog record -o live.mcap --meta-file sim/r2g_s00_t00_meta.json   # terminal 2
    """
    if not list_parameters:
        refuse_existing(_planned(out_dir, protocol, subjects, trials), overwrite=overwrite)
    if lsl and protocol == "home":
        raise click.UsageError("--lsl streams a lab trial (IMU + Vicon); not the home protocol")
    if protocol == "home":
        _simulate_home(out_dir, subjects, trials, seed, settings, list_parameters, days)
        return
    if days is not None:
        raise click.UsageError("--days applies to the home protocol only")
    if protocol == "arm":
        written = _simulate_arm(
            out_dir, subjects, trials, seed, repetitions, noise_free, settings, list_parameters, seconds, trunk_imu
        )
        if lsl and written:
            _stream_live(written[0], out_dir)
        return
    for flag, value in zip(ARM_ONLY, (seconds, trunk_imu), strict=True):
        if value:
            raise click.UsageError(f"{flag} applies to the arm protocol only")
    from imulog.simulate import parameter_names, simulate_to_folder

    if list_parameters:
        for group, names in parameter_names(protocol).items():
            click.echo(f"{group}: {', '.join(names)}")
        return
    overrides = _overrides(settings)
    if repetitions is not None:
        overrides["repetitions"] = repetitions
    if noise_free:
        overrides["noise_free"] = True
    total = subjects * trials
    try:
        with click.progressbar(length=total, label=f"simulating {protocol}", show_pos=True) as bar:

            def advance(done: int, _total: int, stem: str) -> None:
                bar.update(1)

            written = simulate_to_folder(
                protocol, out_dir, subjects=subjects, trials=trials, seed=seed, progress=advance, **overrides
            )
    except (TypeError, ValueError) as e:
        raise click.ClickException(_bad_settings(e, settings)) from None
    except OSError as e:
        raise click.ClickException(f"{out_dir}: cannot write the trial files ({e.strerror or e})") from None
    for paths in written:
        click.echo(
            f"{paths['imu'].name[: -len('_imu.csv')]}: "
            + ", ".join(p.name for k, p in paths.items() if k != "truth_npz")
        )
    click.echo(f"wrote {len(written)} trial(s) to {out_dir}")
    if lsl and written:
        _stream_live(written[0], out_dir)


def _stream_live(paths: dict[str, Path], out_dir: Path) -> None:
    """``--lsl``: the trial converted (IMU and Vicon files) into OUT_DIR/<stem>_lsl.mcap, then replayed live."""
    from imulog.archive import write_trial
    from imulog.commands.record import stream_trial
    from imulog.converters import ConversionError
    from imulog.converters.registry import convert_files

    stem = paths["imu"].name[: -len("_imu.csv")]
    trial = out_dir / f"{stem}_lsl.mcap"
    try:
        rec = convert_files([paths["imu"], paths["vicon"]])
        write_trial(trial, rec, attach_sources=False, overwrite=True)
    except ConversionError as e:
        raise click.ClickException(str(e)) from None
    click.echo(f"streaming {stem} live (Ctrl-C stops)")
    stream_trial(trial)


def _simulate_arm(
    out_dir: Path,
    subjects: int,
    trials: int,
    seed: int,
    repetitions: int | None,
    noise_free: bool,
    settings: tuple[str, ...],
    list_parameters: bool,
    seconds: float | None,
    trunk_imu: bool,
) -> list[dict[str, Path]]:
    """``imulog simulate arm``: the two-segment arm of :mod:`imulog.simulate.arm` as raw exports."""
    from imulog.simulate.arm import arm_parameter_names, simulate_arm_to_folder

    if list_parameters:
        for group, names in arm_parameter_names().items():
            click.echo(f"{group}: {', '.join(names)}")
        return []
    if repetitions is not None:
        raise click.UsageError("--repetitions does not apply to arm (use --seconds)")
    overrides = _overrides(settings)
    if seconds is not None:
        overrides["duration_s"] = seconds
    if noise_free:
        overrides["noise_free"] = True
    if trunk_imu:
        overrides["trunk_imu"] = True
    try:
        with click.progressbar(length=subjects * trials, label="simulating arm", show_pos=True) as bar:
            written = simulate_arm_to_folder(
                out_dir, subjects=subjects, trials=trials, seed=seed, progress=lambda *_: bar.update(1), **overrides
            )
    except (TypeError, ValueError) as e:
        raise click.ClickException(_bad_settings(e, settings)) from None
    except OSError as e:
        raise click.ClickException(f"{out_dir}: cannot write the trial files ({e.strerror or e})") from None
    for paths in written:
        click.echo(
            f"{paths['imu'].name[: -len('_imu.csv')]}: "
            + ", ".join(p.name for k, p in paths.items() if k != "truth_npz")
        )
    click.echo(f"wrote {len(written)} trial(s) to {out_dir}")
    return written


def _simulate_home(
    out_dir: Path,
    subjects: int,
    trials: int,
    seed: int,
    settings: tuple[str, ...],
    list_parameters: bool,
    days: float | None,
) -> None:
    """``imulog simulate home``: :mod:`imulog.simulate.home` written as ``.cwa`` files, chunk by chunk."""
    import dataclasses

    from imulog.simulate.home import HomeParams, simulate_home_to_folder

    if list_parameters:
        click.echo("home: " + ", ".join(f.name for f in dataclasses.fields(HomeParams)))
        return
    overrides = _overrides(settings)
    if days is not None:
        overrides["days"] = days
    total = subjects * trials * HomeParams(**{k: v for k, v in overrides.items() if k == "days"}).minutes
    try:
        with click.progressbar(length=total, label="simulating home (minutes)", file=sys.stderr) as bar:
            done = {"n": 0}

            def advance(minutes: int, _total: int) -> None:
                bar.update(minutes - done["n"] if minutes > done["n"] else minutes)
                done["n"] = minutes

            written = simulate_home_to_folder(
                out_dir, subjects=subjects, trials=trials, seed=seed, progress=advance, **overrides
            )
    except (TypeError, ValueError) as e:
        raise click.ClickException(_bad_settings(e, settings)) from None
    except OSError as e:
        raise click.ClickException(f"{out_dir}: cannot write the trial files ({e.strerror or e})") from None
    for paths in written:
        click.echo(f"{paths['cwa'].name}: {paths['cwa'].stat().st_size / 1e6:.1f} MB, truth {paths['truth_npz'].name}")
    click.echo(f"wrote {len(written)} recording(s) to {out_dir}")
