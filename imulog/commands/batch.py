"""``imulog batch``, ``imulog catalog`` and ``imulog report``: archives at scale."""

from __future__ import annotations

import json
from pathlib import Path

import click

from imulog.batch.registry import STEP_ORDER, STEPS
from imulog.commands.outputs import exists_message, occupied, overwrite_option, refuse_existing


def _is_catalog(path: Path) -> bool:
    """True when ``path`` is a Parquet catalog imulog wrote (one row per trial, keyed by ``path``)."""
    try:
        import pyarrow.parquet as pq

        names = set(pq.ParquetFile(path).schema_arrow.names)
    except Exception:  # noqa: BLE001 - not Parquet, unreadable: not a catalog
        return False
    return {"path", "raw_sha256", "subject"} <= names


def _parse_sets(values: tuple[str, ...]) -> dict[str, dict[str, str]]:
    options: dict[str, dict[str, str]] = {}
    for item in values:
        key, eq, value = item.partition("=")
        step, dot, name = key.partition(".")
        if not eq or not dot or not name:
            raise click.BadParameter(
                f"{item!r}: expected STEP.OPTION=VALUE, e.g. phases.repetitions=25", param_hint="--set"
            )
        if step not in STEPS:
            raise click.BadParameter(f"{item!r}: unknown step {step!r} ({', '.join(STEP_ORDER)})", param_hint="--set")
        options.setdefault(step, {})[name.strip()] = value.strip()
    return options


_STEP_HELP = "\n".join(f"  {name:<12} {STEPS[name].help}" for name in STEP_ORDER)


@click.command(
    "batch",
    epilog="\b\nSteps (run in this order whatever the order given):\n" + _STEP_HELP,
)
@click.argument("inputs", nargs=-1, required=True)
@click.option(
    "--steps",
    default="orientation,align,phases,trajectory,evaluate",
    show_default=True,
    help="Comma-separated steps: " + ", ".join(STEP_ORDER) + ".",
)
@click.option(
    "--set",
    "sets",
    multiple=True,
    metavar="STEP.OPTION=VALUE",
    help="A step option (repeatable), e.g. phases.repetitions=25, trajectory.methods=zupt,kalman, "
    "orientation.backend=vqf, calibrate.calibration=cal.json.",
)
@click.option("--repetitions", type=int, default=None, help="Shortcut for --set phases.repetitions=N.")
@click.option("--imu", default=None, help="IMU name for every step that takes one (default: each step's own choice).")
@click.option("--workers", "-j", type=int, default=1, show_default=True, help="Local worker processes.")
@click.option("--dask-scheduler", default=None, metavar="ADDR", help="Run on a dask.distributed cluster (tcp://...).")
@click.option(
    "--continue-on-error/--fail-fast",
    default=True,
    show_default=True,
    help="Go on with the other files after a failure (default), or stop handing out files at the first one.",
)
@click.option("--force", is_flag=True, help="Recompute every step even when up to date.")
@click.option(
    "--ledger",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Pre-check ledger file (default: .imulog-batch.jsonl in the trials' top folder).",
)
@click.option("--no-ledger", is_flag=True, help="No ledger: every file is opened (steps still skip when up to date).")
@click.option("--json", "json_out", type=click.Path(dir_okay=False, path_type=Path), help="Write the report as JSON.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def batch(
    inputs: tuple[str, ...],
    steps: str,
    sets: tuple[str, ...],
    repetitions: int | None,
    imu: str | None,
    workers: int,
    dask_scheduler: str | None,
    continue_on_error: bool,
    force: bool,
    ledger: Path | None,
    no_ledger: bool,
    json_out: Path | None,
    quiet: bool,
) -> None:
    """Run reprocessing steps over many trials (files, folders or quoted glob patterns).

    Each file is independent: a bad file is reported and skipped, the rest completes, and the exit status is
    non-zero when any file failed. Idempotent and resumable: files already up to date for the same steps,
    options and inputs do no work (a ledger pre-check skips them without opening them; each step also skips
    itself), so an interrupted batch rerun finishes only what is left.

    The default steps are a lab trial's (IMU and an optical reference: align and evaluate need markers or
    poses); an archive of wearables alone takes the steps that need no reference, e.g. the home-monitoring
    line below (metrics and epochs still run on a file whose orientation failed: an accelerometer-only wrist).

    \b
    Examples:
      imulog batch 'archive/**/*.mcap' --steps orientation,align,phases,trajectory,evaluate
      imulog batch wearables/ --steps orientation,metrics,epochs --set epochs.epochs_s=10,60   # home monitoring
      imulog batch archive/ --repetitions 25 --workers 2
      imulog batch 'archive/**/*.mcap' --set trajectory.methods=zupt,optimized --set phases.threshold=otsu
      imulog batch 'archive/**/*.mcap' --dask-scheduler tcp://10.0.0.5:8786
    """
    from imulog.batch.registry import parse_steps
    from imulog.batch.runner import AUTO, expand_paths, run

    if workers < 1:
        raise click.BadParameter("must be at least 1", param_hint="--workers")
    if dask_scheduler and workers != 1:
        raise click.UsageError("use either --workers or --dask-scheduler, not both")
    try:
        names = parse_steps(steps)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--steps") from None
    options = _parse_sets(sets)
    if repetitions is not None:
        if "phases" not in names:
            raise click.UsageError("--repetitions applies to the phases step, which is not in --steps")
        options.setdefault("phases", {})["repetitions"] = str(repetitions)
    if imu is not None:
        for name in names:
            if "imu" in STEPS[name].kwargs:
                options.setdefault(name, {}).setdefault("imu", imu)
    files = expand_paths(inputs)
    if not files:
        raise click.ClickException(f"no trial files match {' '.join(inputs)}")
    try:
        report = run(
            files,
            names,
            workers=workers,
            dask_scheduler=dask_scheduler,
            options=options,
            progress=not quiet,
            force=force,
            continue_on_error=continue_on_error,
            ledger=None if no_ledger else (ledger or AUTO),
        )
    except ValueError as exc:  # bad options: nothing was run
        raise click.ClickException(str(exc)) from None
    except OSError as exc:  # e.g. the Dask scheduler cannot be reached
        raise click.ClickException(f"{dask_scheduler or 'batch'}: {exc}") from None
    if json_out is not None:
        json_out.write_text(json.dumps(report.to_dict(), indent=2, default=str) + "\n")
    click.echo(report.summary())
    if not report.ok:
        raise SystemExit(1)


@click.command("catalog")
@click.argument("inputs", nargs=-1, required=True)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    default=Path("catalog.parquet"),
    show_default=True,
    help="Parquet file to write or update.",
)
@click.option("--full", is_flag=True, help="Re-read every trial (default: only new or changed files).")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
@overwrite_option("Replace OUTPUT when it is not a catalog (an existing catalog is updated, never replaced).")
@click.option("--json", "as_json", is_flag=True, help="Print the counts (rows, read, unchanged, removed...) as JSON.")
@click.option(
    "--epochs",
    "epochs_out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also gather every trial's epoch rows (imulog process epochs) into one study table (.parquet or .csv).",
)
@click.option("--epoch-s", type=float, default=60.0, show_default=True, help="Which epoch length --epochs gathers.")
def catalog(
    inputs: tuple[str, ...],
    output: Path,
    full: bool,
    quiet: bool,
    overwrite: bool = False,
    as_json: bool = False,
    epochs_out: Path | None = None,
    epoch_s: float = 60.0,
) -> None:
    """One Parquet row per trial: subject, task, devices, durations, channels, runs, metrics.

    INPUTS are folders (every *.mcap below), files or quoted glob patterns. The catalog is updated
    incrementally: files whose size and mtime did not change keep their row without being opened.
    Read it with pandas, pyarrow or DuckDB; nested content is in the *_json columns. An existing
    OUTPUT that is not a catalog is refused unless --overwrite.

    \b
    Examples:
      imulog catalog archive/ -o catalog.parquet
      python -c "import pandas as pd; print(pd.read_parquet('catalog.parquet')[['subject','trial','best_mae_cm']])"
      duckdb -c "select subject, avg(best_mae_cm) from 'catalog.parquet' group by subject"
      imulog catalog weeks/ -o catalog.parquet --epochs study_epochs.parquet --epoch-s 60
    """
    from imulog.batch.catalog import build_catalog, build_epoch_table, discover

    if not discover(inputs):
        raise click.ClickException(f"no trial files (*.mcap) in {' '.join(inputs)}")
    if occupied(output) and not overwrite and not _is_catalog(output):  # updating a catalog is what this is for
        raise click.ClickException(exists_message(output) + " (it is not an imulog catalog)")
    if epochs_out is not None:
        refuse_existing(epochs_out, overwrite=overwrite)
    try:
        stats = build_catalog(list(inputs), output, progress=not quiet and not as_json, full=full)
    except OSError as exc:
        raise click.ClickException(f"{output}: {exc}") from None
    epoch_stats = None
    if epochs_out is not None:
        try:
            epoch_stats = build_epoch_table(list(inputs), epochs_out, epoch_s=epoch_s)
        except (OSError, ValueError) as exc:
            raise click.ClickException(f"{epochs_out}: {exc}") from None
    if as_json:
        import dataclasses
        import json

        click.echo(json.dumps({k: str(v) if isinstance(v, Path) else v for k, v in dataclasses.asdict(stats).items()}))
        return
    click.echo(stats.summary())
    if epoch_stats is not None:
        click.echo(
            f"{epochs_out}: {epoch_stats.rows} epochs of {epoch_s:g} s from {epoch_stats.read} trials "
            f"({epoch_stats.dropped} without epochs)"
        )


@click.command("report")
@click.argument("catalog_file", metavar="CATALOG", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "-o",
    "--output",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("report"),
    show_default=True,
    help="Folder for the tables (Markdown, CSV) and plots (PNG).",
)
@click.option("--no-plots", is_flag=True, help="Tables only (no matplotlib needed).")
@overwrite_option("Write into OUTPUT even when it holds files (replacing the report's own).")
def report(catalog_file: Path, output: Path, no_plots: bool, overwrite: bool = False) -> None:
    """Accuracy table (method x axis, mean ± std, cm and % ROM), per-subject error plots, phase timings.

    \b
    Examples:
      imulog report catalog.parquet -o report/
      imulog report catalog.parquet -o report/ --no-plots
      imulog report catalog.parquet -o report/ --overwrite   # again, into the same folder
    """
    from imulog.batch.report import write_report

    refuse_existing(output, overwrite=overwrite)  # an empty or missing folder is fine
    try:
        files = write_report(catalog_file, output, plots=not no_plots)
    except (RuntimeError, OSError, ValueError, KeyError) as exc:
        raise click.ClickException(f"{catalog_file}: {exc}") from None
    click.echo((output / "accuracy.md").read_text().rstrip())
    click.echo(f"wrote {', '.join(sorted(files))} to {output}/")
