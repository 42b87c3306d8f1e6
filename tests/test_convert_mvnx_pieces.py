"""MVNX in pieces (issue 24, point 4): ``imulog convert`` of an Xsens MVN ``.mvnx`` piece by piece (``iterparse``,
pieces of N frames) writes the archive it writes from the whole file, sample by sample (the comparison of
``tests/test_convert_pieces_archive.py``). No redistributable MVNX sample exists (``../shared/data/devices/README.md``),
so the file is written in the published MVNX 4 layout (``tests/test_convert_mvnx.py``). A damaged file fails with the
whole file's one line, piece by piece too, whatever frame the damage is in; memory does not grow with the frames."""

from __future__ import annotations

import re
import tracemalloc
from pathlib import Path

import pytest
from click.testing import CliRunner
from test_convert_mvnx import write_mvnx
from test_convert_pieces_archive import assert_same_trial, convert_twice

from imulog.cli import cli

FRAMES = "imulog.converters.mvnx.PIECE_FRAMES"


def test_mvnx_pieces_write_the_whole_files_archive(tmp_path, monkeypatch):
    src = tmp_path / "reach-001.mvnx"
    write_mvnx(src, n=1000)
    whole, pieces = convert_twice(src, tmp_path, (FRAMES, 97), monkeypatch)
    assert_same_trial(whole, pieces)


def _late(text: str, old: str, new: str) -> str:
    """``text`` with the last frame's ``old`` replaced by ``new`` (damage in the file's last piece)."""
    at = text.rindex('type="normal"')
    return text[:at] + text[at:].replace(old, new, 1)


def _late_drop(text: str, tag: str) -> str:
    """``text`` without the last frame's ``<tag>`` element."""
    at = text.rindex('type="normal"')
    return text[:at] + re.sub(f"<{tag}>[^<]*</{tag}>", "", text[at:], count=1)


DAMAGE = {
    "cut": (lambda s: s[: len(s) * 5 // 6], r"line \d+: XML error: no element found"),
    "late_values": (lambda s: _late(s, "<jointAngle>", "<jointAngle>1 "), r"frame 599 .*<jointAngle> has 13 values"),
    "late_time": (lambda s: s.replace('time="9983"', 'time="10"'), r"frame 599: time 10.0 ms does not increase"),
    "late_missing": (
        lambda s: _late_drop(s, "jointAngleXZY"),
        r"<jointAngleXZY> is missing in 1 of 600 frames",
    ),
    # a late time that does not increase, then a cut: the whole file's first error is the XML error
    "time_then_cut": (
        lambda s: s.replace('time="5000"', 'time="10"')[: len(s) * 9 // 10],
        r"XML error: no element found",
    ),
    "billion_laughs": (
        lambda s: s.replace(
            '<mvnx version="4"',
            '<!DOCTYPE mvnx [<!ENTITY a "aaaaaaaaaa">'
            + "".join(f'<!ENTITY {c} "{("&" + p + ";") * 10}">' for p, c in zip("abcdefgh", "bcdefghi", strict=True))
            + ']><mvnx version="4"',
        ).replace("<comment></comment>", "<comment>&i;</comment>"),
        r"XML error: .*(amplification|entity)",
    ),
}


@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_damaged_mvnx_fails_with_the_whole_files_line_in_pieces(damage, tmp_path, monkeypatch):
    import imulog.commands.convert_stream as cs

    edit, message = DAMAGE[damage]
    good = tmp_path / "good.mvnx"
    write_mvnx(good, n=600)
    bad = tmp_path / "bad.mvnx"
    bad.write_text(edit(good.read_text()))
    lines = []
    for pieces in (False, True):
        out = tmp_path / f"out_{pieces}.mcap"
        monkeypatch.setattr(cs, "STREAM_MIN_BYTES", 0 if pieces else 1 << 60)
        monkeypatch.setattr(FRAMES, 50)
        r = CliRunner().invoke(cli, ["convert", str(bad), "-o", str(out)])
        assert r.exit_code != 0 and not out.exists(), r.output
        assert ("piece by piece" in r.output) is False
        lines.append(r.output.strip().splitlines()[-1])
    assert re.search(message, lines[0]), lines[0]
    assert lines[0] == lines[1]


def _peak_bytes(path: Path, piece_frames: int) -> tuple[int, int]:
    from imulog.converters.mvnx import iter_mvnx

    tracemalloc.start()
    try:
        frames = sum(len(p.poses[0]) for p in iter_mvnx(path, piece_frames=piece_frames))
        return frames, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_mvnx_memory_is_one_piece_not_the_file(tmp_path):
    """Parsing 4x the frames in pieces of 200 frames: Python's peak allocation stays that of a piece (the frame
    elements are cleared and dropped from <frames>; kept, 8000 cleared elements would add ~1 MB)."""
    short, long = tmp_path / "short.mvnx", tmp_path / "long.mvnx"
    write_mvnx(short, n=2000)
    write_mvnx(long, n=8000)
    n_short, peak_short = _peak_bytes(short, 200)
    n_long, peak_long = _peak_bytes(long, 200)
    assert (n_short, n_long) == (2000, 8000)
    assert peak_long < 1.15 * peak_short, (peak_short, peak_long)


def test_pieces_joined_are_the_whole_recording(tmp_path):
    from imulog.converters.mvnx import iter_mvnx, read_mvnx
    from test_convert_pieces import _pieces_equal_whole

    src = tmp_path / "reach-001.mvnx"
    write_mvnx(src, n=500)
    names = {"RightForeArm": "wrist"}
    _pieces_equal_whole(list(iter_mvnx(src, names=names, piece_frames=64)), read_mvnx(src, names=names))
