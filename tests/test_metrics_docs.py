"""The Python example of docs/metrics.md runs and prints what the page says."""

from __future__ import annotations

import contextlib
import io
import re


def test_docs_python_example_prints_the_documented_numbers(repo_root):
    text = (repo_root / "docs" / "metrics.md").read_text()
    block = re.search(r"## Python example\s+```python\n(.*?)```", text, re.S).group(1)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(block, "docs/metrics.md", "exec"), {})
    lines = out.getvalue().splitlines()
    assert f"{float(lines[0]):.2f}" == "13.67"
    floor, count = lines[1].split()[:2]
    assert (floor, count) == ("0.0149", "5")
    assert lines[-1] == "287"
