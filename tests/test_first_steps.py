"""A new user's first steps (issue 30 item 6): help texts, extras named one way, README, long outputs summarised."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from click.testing import CliRunner

from imulog.cli import cli
from imulog.commands.phases import MAX_ROWS, TAIL_ROWS, format_summary
from imulog.export import TARGETS

REPO = Path(__file__).resolve().parents[1]
EXTRAS = set(tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"])


def test_top_level_help_matches_the_commands():
    text = CliRunner().invoke(cli, ["--help"]).output
    export = " ".join(text[text.index("  export") :].split("\n  ")[0].split())
    for target in TARGETS:  # export writes every target, not only "Parquet or CSV"
        assert target.lower() in export.lower().replace(".sto", "sto").replace("bids-motion", "bids"), export
    assert "--overwrite" in text


def test_every_error_that_needs_an_extra_names_it_the_same_way():
    pattern = re.compile(r"pip install ('[^']*'|[^\s\"')`]+)")
    found = []
    for path in [*(REPO / "imulog").rglob("*.py"), *(REPO / "converters").rglob("*.py")]:
        for line in path.read_text().splitlines():
            if "pip install" not in line or line.strip().startswith("#"):
                continue
            for arg in pattern.findall(line):
                if arg == "kineticstoolkit" or arg.startswith(
                    "-e"
                ):  # not an extra (GPL via PyQt5); an editable install
                    continue
                found.append((path.name, arg))
                m = re.fullmatch(r"'imulog\[([a-z0-9,]+)\]'", arg)
                assert m, f"{path}: pip install {arg} (write pip install 'imulog[EXTRA]')"
                assert set(m.group(1).split(",")) <= EXTRAS, f"{path}: unknown extra in {arg}"
    assert len(found) >= 6  # c3d (twice), hdf5, xdf, fusion, report, dask, notebook


def test_readme_activates_the_venv_and_lists_every_extra():
    readme = (REPO / "README.md").read_text()
    assert "source .venv/bin/activate" in readme
    table = readme[readme.index("### Extras") :]
    for extra in EXTRAS:
        assert f"| `{extra}` |" in table, extra
    assert "pip install 'imulog[c3d]'" in readme
    assert "C3D export needs the `c3d` extra: `pip install 'imulog[c3d]'`" in (REPO / "docs" / "export.md").read_text()


def test_phases_table_is_summarised_beyond_a_screenful():
    labels = ["reach", "lift", "return_bottle", "return_hand"]
    rows = [
        {
            "repetition": i // 4 + 1,
            "label": labels[i % 4],
            "start_s": float(i),
            "end_s": i + 0.5,
            "duration_s": 0.25 + 0.01 * i,
            "peak_angular_velocity_rad_s": 1.0,
        }
        for i in range(1000)
    ]
    timing = {
        "protocol": "r2g",
        "n_movements": 1100,
        "n_phases": 1000,
        "n_repetitions": 250,
        "n_corrected_repetitions": 0,
        "imu": "/imu/wrist",
        "method": "dynamos",
        "clock": "reference",
        "static_fraction": 0.3,
        "phases": rows,
    }
    lines = format_summary(timing).splitlines()
    assert len(lines) <= MAX_ROWS + 10
    assert any(f"... {1000 - MAX_ROWS} more phases" in line for line in lines)
    assert lines[-5].startswith(" 250 return_hand") and lines[2].startswith("   1 reach")
    reach = [0.25 + 0.01 * i for i in range(0, 1000, 4)]  # the means are over every phase, not the shown ones
    assert f"mean reach          duration {sum(reach) / len(reach):.3f} s over 250" in lines
    timing["phases"] = rows[:MAX_ROWS]
    assert len(format_summary(timing).splitlines()) == 2 + MAX_ROWS + 4  # up to a screenful: every row
    assert TAIL_ROWS < MAX_ROWS
