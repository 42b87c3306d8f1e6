"""benchmarks/bench_long.py's final table and summary file (issue 24's "Done when" in one run): the verdicts
against 1 GB and 1.15x, and a real (tiny) run writing its summary."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

import bench_long  # noqa: E402
from long_table import format_table, markdown, summary, table_rows, write_summary  # noqa: E402

DAYS = [1.0, 7.0]
RESULTS = {  # (wall s, peak RSS MB, CPU s) or the failure
    1.0: {
        "flat": (10.0, 500.0, 9.0),
        "grows": (5.0, 400.0, 4.0),
        "big": (3.0, 1100.0, 2.0),
        "breaks": (1.0, 90.0, 1.0),
    },
    7.0: {"flat": (70.0, 540.0, 60.0), "grows": (30.0, 500.0, 28.0), "big": (20.0, 1100.0, 19.0), "breaks": "oops"},
}


def test_rows_pass_and_fail_on_each_limit():
    rows = {r["command"]: r for r in table_rows(["flat", "grows", "big", "breaks", "absent"], RESULTS, DAYS)}
    assert rows["flat"]["verdict"] == "PASS" and rows["flat"]["growth"] == 1.08 and rows["flat"]["peak_mb"] == 540
    assert rows["flat"]["runs"]["7"] == {"wall_s": 70.0, "rss_mb": 540.0, "cpu_s": 60.0}
    assert rows["grows"]["verdict"] == "FAIL" and rows["grows"]["growth"] == 1.25
    assert "growth 1.25x > 1.15x" in rows["grows"]["why"]
    assert (
        rows["big"]["verdict"] == "FAIL" and rows["big"]["growth"] == 1.0 and "1100 MB > 1024 MB" in rows["big"]["why"]
    )
    assert rows["breaks"]["verdict"] == "FAIL" and rows["breaks"]["growth"] is None
    assert rows["breaks"]["runs"]["7"] == {"failed": "oops"} and "7 d failed: oops" in rows["breaks"]["why"]
    assert rows["absent"]["verdict"] == "FAIL" and rows["absent"]["runs"] == {"1": None, "7": None}
    text = format_table(list(rows.values()), DAYS)
    assert text.splitlines()[1].split()[:7] == ["flat", "500", "540", "9.0", "60.0", "10.0", "70.0"]
    assert "FAILED" in text and "not run" in text


def test_one_length_has_no_growth_but_keeps_the_1_gb_limit():
    rows = table_rows(["flat", "big"], {7.0: RESULTS[7.0]}, [7.0])
    assert [(r["growth"], r["verdict"]) for r in rows] == [(None, "PASS"), (None, "FAIL")]


def test_summary_file_as_json_and_markdown(tmp_path):
    rows = table_rows(["flat", "grows"], RESULTS, DAYS)
    doc = summary(rows, DAYS, {"commit": "abc", "argv": "python benchmarks/bench_long.py", "load": "1.0-2.0"})
    assert doc["passed"] is False and doc["limits"] == {"rss_mb": 1024.0, "growth": 1.15}
    write_summary(tmp_path / "s.json", doc)
    assert json.loads((tmp_path / "s.json").read_text())["commands"] == json.loads(json.dumps(rows))
    write_summary(tmp_path / "s.md", doc)
    lines = (tmp_path / "s.md").read_text().splitlines()
    assert "commit abc" in lines[0]
    assert lines[4] == "| `flat` | 500 MB | 540 MB | 1.08x | 9.0 / 10.0 s | 60.0 / 70.0 s | PASS |"
    assert lines[5].endswith("| FAIL: growth 1.25x > 1.15x |")
    assert markdown(doc) == (tmp_path / "s.md").read_text()


def test_a_tiny_run_writes_its_table_and_summary(tmp_path, capsys):
    """Two simulated lengths of a few minutes, ``info`` measured on each (the wrist converted unmeasured)."""
    out = tmp_path / "summary.json"
    code = bench_long.main(
        ["--days", "0.002", "0.004", "--commands", "info", "--dir", str(tmp_path), "--summary", str(out)]
        + ["--warm-days", "0.001"]
    )
    doc = json.loads(out.read_text())
    assert doc["warm_days"] == 0.001 and "warmed by a 0.001-day run first" in markdown(doc).splitlines()[0]
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True).stdout
    assert doc["commit"] == (head.strip() or None)
    assert doc["days"] == [0.002, 0.004] and "--summary" in doc["argv"]
    (row,) = doc["commands"]
    assert row["command"] == "info" and set(row["runs"]) == {"0.002", "0.004"}
    for run in row["runs"].values():
        assert run["rss_mb"] > 5 and run["cpu_s"] > 0 and run["wall_s"] > 0
    assert abs(row["growth"] - row["runs"]["0.004"]["rss_mb"] / row["runs"]["0.002"]["rss_mb"]) < 0.01
    assert code == (0 if row["verdict"] == "PASS" else 1)
    assert "\ninfo  " in capsys.readouterr().out.split("growth  verdict")[-1]
    assert list(tmp_path.iterdir()) == [out]  # the scratch folder is removed


def test_an_interrupted_run_still_writes_what_it_measured(tmp_path, monkeypatch):
    """SIGTERM or Ctrl-C during the second command: the first is in the table, the second "not run"."""
    calls = []

    def run(args, limit_gb=None):
        calls.append(args)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return 1.0, 100.0, 0.5

    monkeypatch.setattr(bench_long, "run", run)
    out = tmp_path / "summary.json"
    code = bench_long.main(
        ["--days", "0.002", "--commands", "info", "export", "--dir", str(tmp_path), "--summary", str(out)]
        + ["--warm-days", "0"]
    )
    doc = json.loads(out.read_text())
    assert doc["interrupted"] is True and code == 1
    assert "no warm-up" in markdown(doc).splitlines()[0]
    assert [(r["command"], r["verdict"], r["runs"]["0.002"]) for r in doc["commands"]] == [
        ("info", "PASS", {"wall_s": 1.0, "rss_mb": 100.0, "cpu_s": 0.5}),
        ("export", "FAIL", None),
    ]
    assert [a[3] for a in calls] == ["info", "export"]
    assert "interrupted" in markdown(doc).splitlines()[0]
    assert list(tmp_path.iterdir()) == [out]


def test_every_command_runs_once_on_the_warm_up_before_the_measured_lengths(tmp_path, monkeypatch):
    """numba compiles a kernel in the first process that needs it and the compiler's memory stays resident (about
    135 MB for the kinematics kernels): every command runs first on the short warm-up recording, unmeasured, and
    the table holds only the measured lengths, each trial of ``--trials`` copied for its own length."""
    calls = []

    def run(args, limit_gb=None):
        trial = Path(args[-1])
        calls.append((trial.parent.name, args[3], trial.read_bytes()[:4]))
        return 1.0, 999.0 if trial.parent.name == "warm" else 100.0 + len(calls), 0.5

    monkeypatch.setattr(bench_long, "run", run)
    trials = [tmp_path / "a.mcap", tmp_path / "b.mcap"]
    for t, text in zip(trials, (b"AAAA", b"BBBB"), strict=True):
        t.write_bytes(text)
    out = tmp_path / "summary.json"
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    argv = ["--days", "0.002", "0.004", "--trials", *map(str, trials), "--commands", "info", "--warm-days", "0.001"]
    bench_long.main([*argv, "--dir", str(scratch), "--summary", str(out)])
    # the warm-up simulates and converts its own recording (an MCAP file), then each length gets its trial
    assert calls == [("warm", "info", b"\x89MCA"), ("d0.002", "info", b"AAAA"), ("d0.004", "info", b"BBBB")]
    doc = json.loads(out.read_text())
    assert doc["days"] == [0.002, 0.004] and doc["warm_days"] == 0.001
    (row,) = doc["commands"]
    assert [r["rss_mb"] for r in row["runs"].values()] == [102.0, 103.0]  # not the warm-up's 999 MB
    assert list(scratch.iterdir()) == []


def test_a_command_is_measured_apart_from_the_benchmark_s_own_memory():
    """A child's ru_maxrss starts at the RSS of the process that forked it: with 300 MB held here, a command of a
    few MB must still measure a few MB (it measured over 300 MB when the benchmark forked the commands itself)."""
    held = bytearray(300 * 2**20)
    held[::4096] = b"\1" * len(held[::4096])  # resident
    wall, mb, cpu = bench_long.run([sys.executable, "-S", "-c", "pass"])
    assert mb < 100 and wall > 0 and cpu >= 0
    big = "b = bytearray(400 * 2**20); b[::4096] = b'\\1' * len(b[::4096])"
    assert 400 < bench_long.run([sys.executable, "-S", "-c", big])[1] < 600
    del held


def test_the_memory_cap_still_applies_to_the_command():
    try:
        bench_long.run([sys.executable, "-S", "-c", "b = bytearray(2 * 2**30)"], limit_gb=0.5)
    except bench_long.CommandFailed as exc:
        assert "MemoryError" in str(exc)
    else:
        raise AssertionError("a command over the cap must fail")
