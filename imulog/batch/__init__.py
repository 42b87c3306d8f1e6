"""imulog.batch: archives at scale -- run steps over many trials, catalog them, report on them.

    from imulog.batch import run, build_catalog, write_report
    report = run("archive/**/*.mcap", "orientation,align,phases,trajectory,evaluate", workers=2,
                 options={"phases": {"repetitions": 25}})
    build_catalog("archive/", "catalog.parquet")          # one row per trial, incremental
    write_report("catalog.parquet", "report/")            # accuracy table, per-subject plots, timings

See docs/batch.md.
"""

from typing import TYPE_CHECKING

from imulog.batch.registry import STEP_ORDER, STEPS, FileResult, StepSpec, call_step, parse_steps, run_file, run_params
from imulog.batch.runner import BatchReport, expand_paths, run

if TYPE_CHECKING:  # imported when first used (pyarrow, pandas): typed for a user's checker all the same
    from imulog.batch.catalog import build_catalog
    from imulog.batch.report import write_report

__all__ = [
    "STEPS",
    "STEP_ORDER",
    "BatchReport",
    "FileResult",
    "StepSpec",
    "build_catalog",
    "call_step",
    "expand_paths",
    "parse_steps",
    "run",
    "run_file",
    "run_params",
    "write_report",
]


def __getattr__(name: str):  # catalog/report import pyarrow/pandas lazily
    if name == "build_catalog":
        from imulog.batch.catalog import build_catalog

        return build_catalog
    if name == "write_report":
        from imulog.batch.report import write_report

        return write_report
    raise AttributeError(name)
