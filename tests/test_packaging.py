"""The package layout: converters are imulog.converters (from the top-level converters/ folder), every package
folder is listed in pyproject.toml, and no top-level `converters` module is installed."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_every_package_folder_is_listed():
    conf = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(conf["packages"])
    found = {".".join(p.parent.relative_to(REPO).parts) for p in (REPO / "imulog").rglob("__init__.py")}
    assert found | {"imulog.converters"} == listed
    assert conf["package-dir"] == {"imulog.converters": "converters"}


def test_converters_are_imulog_converters_and_not_a_top_level_module(tmp_path):
    code = (
        "import importlib.util, imulog.converters.registry as r, imulog.converters as c; "
        "print(importlib.util.find_spec('converters') is None, len(r.available()) > 20, c.__name__)"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "True", "imulog.converters"]


def test_entry_points_name_imulog_converters():
    eps = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["entry-points"]["imulog.converters"]
    assert eps and all(v.startswith("imulog.converters.") for v in eps.values())
