"""``imulog demo``: simulate a drinking-task trial, convert it, run every reprocessing step, write the view.

The demo runs the very commands a user would type (printed as it goes, so they can be replayed one by
one), in this process, and stops at the first failure with that command's error.
"""

from __future__ import annotations

import os
import shlex
import shutil
import time
from pathlib import Path

import click

from imulog.commands.outputs import exists_message, occupied, overwrite_option

DEFAULT_OUTPUT = Path("demo-output")
STEM = "r2g_s00_t00"


def demo_commands(
    out_dir: Path, *, repetitions: int, seed: int, view: bool = True, spawn: bool = False
) -> list[tuple[str, list[str]]]:
    """The demo's pipeline as (what it does, imulog argv) pairs, in order."""
    raw = out_dir / "raw"
    trial = out_dir / "trial.mcap"
    steps: list[tuple[str, list[str]]] = [
        (
            "simulate a drinking-task (R2G) trial with ground truth, in raw export formats",
            ["simulate", "r2g", "-o", str(raw), "--repetitions", str(repetitions), "--seed", str(seed)],
        ),
        (
            "convert the wrist-IMU text and the Vicon Nexus CSV into one MCAP trial",
            [
                "convert",
                str(raw / f"{STEM}_imu.csv"),
                str(raw / f"{STEM}_vicon.csv"),
                "--meta-file",
                str(raw / f"{STEM}_meta.json"),
                "-o",
                str(trial),
            ],
        ),
        ("orientation (VQF offline) and gravity-free acceleration", ["process", "orientation", str(trial)]),
        ("IMU-to-Vicon time lag, drift and frame rotation", ["process", "align", str(trial)]),
        ("movements, phases and static intervals (DynAMoS + event correction)", ["process", "phases", str(trial)]),
        ("wrist trajectories by every method", ["process", "trajectory", str(trial)]),
        ("clinical metrics", ["process", "metrics", str(trial)]),
        ("errors against the Vicon cluster (thesis Table 3.1)", ["evaluate", str(trial)]),
        ("integrity check", ["doctor", str(trial)]),
        ("what the trial now holds", ["info", str(trial)]),
    ]
    if view:
        view_args = ["view", str(trial), "--save", str(out_dir / "trial.rrd")]
        if spawn:
            view_args.append("--spawn")
        steps.append(("the Rerun view: IMU and Vicon on one timeline", view_args))
    return steps


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


@click.command("demo")
@click.option(
    "-o",
    "--output",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=DEFAULT_OUTPUT,
    show_default=True,
    help="Folder for everything the demo writes (created; an existing one is refused unless --overwrite).",
)
@click.option("--repetitions", type=click.IntRange(1, 25), default=25, show_default=True, help="Drinking tasks.")
@click.option("--seed", type=int, default=0, show_default=True, help="Simulation seed.")
@click.option("--no-view", is_flag=True, help="Skip writing the Rerun view.")
@click.option(
    "--open/--no-open",
    "open_viewer",
    default=None,
    help="Open the native Rerun viewer (default: only when a display is available).",
)
@overwrite_option("Replace an earlier demo in OUTPUT (a folder that does not hold one is never removed).")
def demo(
    out_dir: Path, repetitions: int, seed: int, no_view: bool, open_viewer: bool | None, overwrite: bool = False
) -> None:
    """Simulate, convert, process and view one trial, printing each command it runs.

    A new user's first command: it simulates a seated subject drinking from a bottle (the R2G
    protocol: 25 x reach, lift, return bottle, return hand) as a wrist IMU text export and a Vicon
    Nexus CSV with known ground truth, converts both into one MCAP trial, runs every reprocessing
    step, evaluates the IMU trajectories against Vicon, and writes a Rerun recording.

    \b
    Examples:
      imulog demo                       # everything under ./demo-output
      imulog demo -o /tmp/demo --repetitions 5 --seed 3
      imulog demo --overwrite           # run it again into ./demo-output
      rerun demo-output/trial.rrd       # look at the result
    """
    from imulog.cli import cli

    if occupied(out_dir):
        if not overwrite:
            raise click.ClickException(exists_message(out_dir))
        if not (out_dir / "raw").is_dir():  # --overwrite removes an earlier demo, never another folder
            raise click.ClickException(f"{out_dir}: exists and does not hold an earlier demo; choose another -o")
    if out_dir.exists():
        shutil.rmtree(out_dir)
    out_dir.mkdir(parents=True)
    spawn = has_display() if open_viewer is None else open_viewer
    steps = demo_commands(out_dir, repetitions=repetitions, seed=seed, view=not no_view, spawn=spawn)
    started = time.perf_counter()
    for number, (what, argv) in enumerate(steps, start=1):
        click.secho(f"\n[{number}/{len(steps)}] {what}", bold=True)
        click.secho("$ imulog " + shlex.join(argv), fg="cyan")
        try:
            cli.main(argv, prog_name="imulog", standalone_mode=False)
        except click.ClickException as error:
            raise click.ClickException(f"demo step {number} ({argv[0]}) failed: {error.format_message()}") from None
    elapsed = time.perf_counter() - started
    click.secho(f"\nDone in {elapsed:.1f} s. Outputs in {out_dir}/:", bold=True)
    click.echo(f"  raw/          simulated exports + ground truth ({STEM}_truth.json/.npz)")
    click.echo("  trial.mcap    the archive: raw channels, attachments, derived channels, provenance")
    if not no_view:
        click.echo("  trial.rrd     the Rerun recording")
        click.echo(f"\nLook at it:   rerun {out_dir / 'trial.rrd'}")
        click.echo(f"or in a browser:  imulog view {out_dir / 'trial.mcap'} --web")
