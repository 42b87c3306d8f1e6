"""An Empatica E4 session folder converts in time windows across its files (issue 24, point 4): ``imulog convert
FOLDER`` streams the session (``Converter.iter_session``, every piece one time window [t0, t1) of every file) and the
whole-folder conversion is the one-piece case. Every shared E4 folder is converted whole and in tiny pieces and the
two archives are compared sample by sample (the helpers of ``test_convert_pieces_archive.py``); a folder written here
adds what the shared one lacks (tags, an IBI file without beats, a final row cut short); damaged files give the same
one-line error both ways and leave no archive. The gaitmap stride borders, read through the same text cutter, too."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import convert_file, detect
from imulog.converters._binary import concat_chunks
from imulog.converters.empatica_e4 import CONVERTER as E4
from test_convert_pieces_archive import assert_same_trial, convert_twice

from imulog.cli import cli
from imulog.model import PIECES_RECORD

SHARED_DATA = Path(os.environ.get("IMULOG_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
TEXT = "imulog.converters._pieces.PIECE_BYTES"
#: every shared folder holding an E4 session (an ACC.csv whose format is empatica-e4)
E4_FOLDERS = sorted(p.parent.relative_to(SHARED_DATA).as_posix() for p in SHARED_DATA.rglob("ACC.csv"))


def _convert_folder(folder: Path, out: Path, monkeypatch, piece_bytes: int | None) -> CliRunner:
    """``imulog convert FOLDER -o out`` whole (``piece_bytes`` None: the streaming threshold out of reach) or piece by
    piece with text pieces of ``piece_bytes``."""
    import imulog.commands.convert_stream as cs

    monkeypatch.setattr(cs, "STREAM_MIN_BYTES", 1 << 60 if piece_bytes is None else 0)
    if piece_bytes is not None:
        monkeypatch.setattr(TEXT, piece_bytes)
    return CliRunner().invoke(cli, ["convert", str(folder), "-o", str(out)])


def folder_twice(folder: Path, tmp: Path, piece_bytes: int, monkeypatch) -> tuple[Path, Path]:
    """(the session converted whole, converted in pieces of ``piece_bytes``) through ``imulog convert FOLDER``."""
    whole, pieces = tmp / "whole.mcap", tmp / "pieces.mcap"
    r = _convert_folder(folder, whole, monkeypatch, None)
    assert r.exit_code == 0 and "piece by piece" not in r.output, r.output
    r = _convert_folder(folder, pieces, monkeypatch, piece_bytes)
    assert r.exit_code == 0 and "converted piece by piece" in r.output, r.output
    return whole, pieces


def session_pieces(folder: Path) -> list:
    files = sorted(p for p in folder.iterdir() if p.suffix == ".csv" and p.stat().st_size)
    return list(E4.iter_session(files))


def test_the_shared_e4_folder_is_found(shared_data):
    assert E4_FOLDERS == ["devices/empatica_e4"]
    assert detect(shared_data / E4_FOLDERS[0] / "ACC.csv").name == "empatica-e4"


@pytest.mark.parametrize("rel", E4_FOLDERS)
def test_every_shared_e4_folder_whole_equals_tiny_pieces(rel, shared_data, tmp_path, monkeypatch):
    folder = shared_data / rel
    monkeypatch.setattr(TEXT, 2048)
    pieces = session_pieces(folder)
    assert len(pieces) > 100  # 2 KiB of text in all: windows of a few seconds
    # each piece is one time window of every stream: every stream's samples of piece k lie before those of piece k+1
    topics = [s.topic for s in pieces[0].streams()]
    assert topics == ["/imu/e4", *(f"/signals/e4_{k}" for k in ("bvp", "eda", "hr", "ibi", "temp"))]
    ends = [max((int(s.t_ns[-1]) for s in p.streams() if len(s)), default=None) for p in pieces]
    starts = [min((int(s.t_ns[0]) for s in p.streams() if len(s)), default=None) for p in pieces]
    assert all(e < s for e, s in zip(ends[:-1], starts[1:], strict=True))
    assert all([s.topic for s in p.streams()] == topics for p in pieces)
    # the first piece declares the spans the pieces hold
    joined = concat_chunks(pieces)
    declared = pieces[0].metadata[PIECES_RECORD]["spans"]
    assert declared == {s.topic: [int(s.t_ns[0]), int(s.t_ns[-1])] for s in joined.streams()}
    assert_same_trial(*folder_twice(folder, tmp_path, 2048, monkeypatch))


def _small_session(src: Path, dst: Path, rows: int = 3000) -> Path:
    """The shared session's files cut to their header and first ``rows`` rows (beats within that time), in ``dst``."""
    dst.mkdir()
    for p in sorted(src.glob("*.csv")):
        lines = p.read_text().splitlines()
        keep = lines[: (1 if p.stem == "IBI" else 2) + rows]
        if p.stem == "IBI":
            keep = [x for i, x in enumerate(lines) if i == 0 or float(x.split(",")[0]) < 600]
        (dst / p.name).write_text("\n".join(keep) + "\n")
    return dst


def test_session_with_tags_an_empty_ibi_and_a_cut_final_row(shared_data, tmp_path, monkeypatch):
    """What the shared folder lacks: button presses (tags.csv, cut by time like the beats), an IBI.csv without beats
    (left out with a warning), a final row cut short in BVP.csv (dropped with the whole file's warning), EDA.csv
    without a final line break."""
    folder = _small_session(shared_data / "devices/empatica_e4", tmp_path / "s")
    (folder / "IBI.csv").write_text("1680686620.000000, IBI\n")
    (folder / "tags.csv").write_text("1680686625.250000\n1680686650.000000\n1680686650.000000\n1680686700.500000\n")
    bvp = (folder / "BVP.csv").read_text()
    (folder / "BVP.csv").write_text(bvp[: bvp.rstrip().rfind("\n") + 3])  # "-1" of the last row "-12.34"
    (folder / "EDA.csv").write_text((folder / "EDA.csv").read_text().rstrip("\n"))
    monkeypatch.setattr(TEXT, 1024)
    pieces = session_pieces(folder)
    assert len(pieces) > 10
    rec = concat_chunks(pieces)
    (tags,) = rec.events
    np.testing.assert_array_equal(tags.start_ns, [5_250_000_000, 30 * 10**9, 30 * 10**9, 80_500_000_000])
    assert tags.labels == ["tag 1", "tag 2", "tag 3", "tag 4"]
    assert sum(len(p.events[0]) > 0 for p in pieces) >= 2  # the presses fall in different windows
    assert "/signals/e4_ibi" not in [s.topic for s in rec.streams()]
    assert rec.warnings[0] == "IBI.csv: no data rows: left out"
    assert any("BVP.csv: line" in w and "last row cut short" in w for w in rec.warnings), rec.warnings
    assert not any(p.warnings for p in pieces[:-1])  # the warnings come with the last piece
    whole, streamed = folder_twice(folder, tmp_path, 1024, monkeypatch)
    assert_same_trial(whole, streamed)
    declared = pieces[0].metadata[PIECES_RECORD]["spans"]
    real = {s.topic: [int(s.t_ns[0]), int(s.t_ns[-1])] for s in rec.streams() if hasattr(s, "t_ns")}
    assert declared == {**real, "/events/e4_tags": [5_250_000_000, 80_500_000_000]}


def _errors_both_ways(folder: Path, tmp: Path, monkeypatch) -> str:
    """The one-line error of ``imulog convert FOLDER`` whole and in pieces of 1 KiB: the same, no archive."""
    out = []
    for piece_bytes in (None, 1024):
        target = tmp / f"out_{piece_bytes}.mcap"
        r = _convert_folder(folder, target, monkeypatch, piece_bytes)
        assert r.exit_code != 0 and not target.exists(), r.output
        out.append(r.output.strip().splitlines()[-1])
    assert out[0] == out[1]
    return out[0]


@pytest.mark.parametrize(
    ("file", "damage", "expected"),
    [
        ("ACC.csv", lambda lines: lines.__setitem__(2500, "-34,-23"), "ACC.csv: line 2501: truncated line: 2 fields"),
        (
            "BVP.csv",
            lambda lines: lines.__setitem__(2800, "nan"),
            "BVP.csv: line 2801, column 'bvp': non-finite value 'nan'",
        ),
        ("EDA.csv", lambda lines: lines.pop(0), "EDA.csv: line 1: first row is not the session start"),
        ("TEMP.csv", lambda lines: lines.__delitem__(slice(1, None)), "TEMP.csv: line 2: second row is not the sample"),
        ("IBI.csv", lambda lines: lines.__setitem__(-3, "1.0,0.5"), "IBI.csv: line"),
    ],
    ids=["truncated-line", "nan-line", "missing-header", "cut-in-header", "beat-goes-back"],
)
def test_damaged_file_same_error_both_ways(file, damage, expected, shared_data, tmp_path, monkeypatch):
    """A damaged file stops the session (no file is silently left out): the same line whole and in pieces."""
    folder = _small_session(shared_data / "devices/empatica_e4", tmp_path / "s")
    lines = (folder / file).read_text().splitlines()
    damage(lines)
    (folder / file).write_text("\n".join(lines) + "\n")
    msg = _errors_both_ways(folder, tmp_path, monkeypatch)
    assert msg.startswith("error: ") and expected in msg, msg
    if file == "IBI.csv":
        assert "beat time does not increase" in msg


def test_a_file_converted_alone_is_a_session_of_one(shared_data, monkeypatch):
    """``iter_chunks`` of one file is the session reader on that file: its time windows join to the whole file."""
    path = shared_data / "devices/empatica_e4/HR.csv"
    monkeypatch.setattr(TEXT, 512)
    pieces = list(detect(path).iter_chunks(path))
    whole = convert_file(path)
    assert len(pieces) > 10
    joined = concat_chunks(pieces)
    assert joined.signals[0].t_ns.tobytes() == whole.signals[0].t_ns.tobytes()
    assert joined.signals[0].values.tobytes() == whole.signals[0].values.tobytes()
    assert joined.metadata == whole.metadata and whole.signals[0].t_ns[0] == 10 * 10**9


def test_gaitmap_stride_borders_pieces_equal_whole(shared_data, tmp_path, monkeypatch):
    """The stride file (a row per stride, its ``foot`` cell text) through the text cutter: pieces of 100 bytes join to
    the whole file, and ``imulog convert`` writes the same archive both ways; a bad row names its line both ways."""
    path = shared_data / "gaitmap_foot/stride_borders_sample.csv"
    monkeypatch.setattr(TEXT, 100)
    pieces = list(detect(path).iter_chunks(path))
    assert len(pieces) > 5
    whole, joined = convert_file(path), concat_chunks(pieces)
    (a,), (b,) = whole.events, joined.events
    for field in ("start_ns", "end_ns", "task_index"):
        assert getattr(a, field).tobytes() == getattr(b, field).tobytes()
    assert a.labels == b.labels and len(a) == 58 and a.labels[0] == "left_sensor"
    assert_same_trial(*convert_twice(path, tmp_path, (TEXT, 100), monkeypatch))
    bad = tmp_path / "stride_borders_sample.csv"
    lines = path.read_text().splitlines()
    lines[40] = "39,right,900,x,1"
    bad.write_text("\n".join(lines) + "\n")
    import imulog.commands.convert_stream as cs

    out = []
    for threshold in (1 << 60, 0):
        monkeypatch.setattr(cs, "STREAM_MIN_BYTES", threshold)
        target = tmp_path / f"bad_{threshold}.mcap"
        r = CliRunner().invoke(cli, ["convert", str(bad), "-o", str(target)])
        assert r.exit_code != 0 and not target.exists()
        out.append(r.output.strip().splitlines()[-1])
    assert out[0] == out[1] and "line 41: s_id, start and end must be numbers" in out[0]


def _short_row_reference(block: bytes, ncols: int) -> int | None:
    """The first short row of ``block`` as the field check found it before it counted from delimiter positions: a
    running count of delimiters per byte (the reference), None when every row is complete or the short one blank."""
    raw = np.frombuffer(block, dtype=np.uint8)
    ends = np.flatnonzero(raw == 10)
    delims = np.cumsum(raw == ord(","))
    at_end = np.concatenate([delims[ends], [delims[-1]]]) if len(raw) else np.zeros(1, dtype=np.int64)
    fields = np.diff(np.concatenate([[0], at_end])) + 1
    short = np.flatnonzero(fields < ncols)
    return int(short[0]) if len(short) and block.split(b"\n")[short[0]].strip(b" \t\r") else None


@pytest.mark.parametrize("seed", range(40))
def test_field_counts_from_delimiter_positions_equal_the_running_count(seed, tmp_path):
    """``_table._check_field_counts`` (the row check of a parse with skipped columns, e.g. ActiLife epochs' Date/Time)
    names the same short row as the running count it replaced, on random blocks with short, long, blank rows."""
    from imulog.converters._table import TableSpec, _block, _check_field_counts
    from imulog.converters.errors import ConversionError

    rng = np.random.default_rng(seed)
    ncols = int(rng.integers(2, 6))
    rows = []
    for _ in range(int(rng.integers(1, 40))):
        k = ncols if rng.random() < 0.9 else int(rng.integers(0, ncols + 2))
        rows.append(",".join(str(int(x)) for x in rng.integers(0, 99, k)) if k else rng.choice(["", " ", "\r"]))
    if seed % 2:  # a short final row (the last line, after no line break or one)
        rows.append(",".join(["7"] * (ncols - 1)))
    block = ("\n".join(rows) + ("\n" if rng.random() < 0.5 else "")).encode()
    spec = TableSpec(path=tmp_path / "t.csv", delimiter=",", skip_lines=3, names=[f"c{i}" for i in range(ncols)])
    data = b"a\nb\nc\n" + block
    expected = _short_row_reference(_block(spec, data), ncols)  # the numeric block the check is given
    try:
        _check_field_counts(spec, data)
        found = None
    except ConversionError as e:
        found = e.line - 4
    assert found == expected
