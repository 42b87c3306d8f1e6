"""The edges of piece-wise conversion (issue 24, item 4): the whole file is the one-piece case, so pieces of any size
give the same values, the same warnings and the same one-line error as the whole file. Random piece sizes from
1 byte up (seeded) over the shared Vicon Nexus CSVs with a cut last row, and small crafted tables with a blank line
at every border position."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from imulog.converters._binary import concat_chunks
from imulog.converters._pieces import iter_table, text_pieces
from imulog.converters.errors import ConversionError
from imulog.converters.vicon_csv import iter_vicon_csv, read_vicon_csv
from test_convert_vicon_pieces import assert_same_nexus


def piece_sizes(size: int, n: int, seed: int) -> list[int]:
    """1 byte, then ``n`` random piece sizes up to ``size`` (log-uniform: most of them smaller than a row)."""
    rng = np.random.default_rng(seed)
    return [1, *sorted({int(x) for x in np.exp(rng.uniform(0, np.log(size), n))})]


def outcome(read) -> tuple:  # noqa: ANN001 - a callable returning a Recording
    """("ok", recording) or ("error", the one-line message)."""
    try:
        return "ok", read()
    except ConversionError as e:
        return "error", str(e)


def assert_same_outcome(whole: tuple, pieces: tuple) -> None:
    assert whole[0] == pieces[0], (whole, pieces)
    if whole[0] == "error":
        assert pieces[1] == whole[1] and "\n" not in whole[1]
    else:
        assert_same_nexus(pieces[1], whole[1])


# ------------------------------------------------------------------------------------ a cut last row, Vicon CSV
@pytest.mark.parametrize("name", ["markers.csv", "analogs.csv"])
@pytest.mark.parametrize("cut", [1, 7, 40, 200])
def test_nexus_csv_with_a_cut_last_row_in_any_pieces_is_the_whole_file(shared_data, tmp_path, name, cut):
    """The last row cut ``cut`` bytes short (an interrupted export): the whole file drops it with a warning; pieces
    smaller than a row (the last piece a fraction of a row) kept it or refused it before the last piece was judged
    with the rows above it."""
    lines = (shared_data / "vicon_nexus" / name).read_bytes().rstrip(b"\r\n").split(b"\n")
    text = b"\n".join(lines[:5] + lines[-400:])  # the header and the last 400 rows (fewer tiny pieces to parse)
    path = tmp_path / name
    path.write_bytes(text[:-cut])
    whole = outcome(lambda: read_vicon_csv(path))
    if cut >= 7:  # a cut of a decimal or two cannot be told from a complete row (_final_row.final_row_cut)
        assert whole[0] == "ok" and any("last row cut short" in w for w in whole[1].warnings)
    for piece_bytes in piece_sizes(len(text) // 4, 6, seed=cut):
        assert_same_outcome(
            whole, outcome(lambda pb=piece_bytes: concat_chunks(list(iter_vicon_csv(path, piece_bytes=pb))))
        )


def test_the_last_piece_holds_the_last_two_rows(tmp_path):
    """Whatever the piece size, the text's last two rows (the last complete but short, with a line break and blank
    lines after it) are in the last piece, so the cut-row check drops the last one there and a row remains to carry
    its warning (``_pieces.text_pieces``); the pieces join to the text."""
    path = tmp_path / "t.csv"
    path.write_bytes(b"h\n" + b"".join(b"%d,%d.5\n" % (i, i) for i in range(30)) + b"30\n\n \n")
    for piece_bytes in range(1, 80):
        pieces = list(text_pieces(path, 1, piece_bytes))
        assert b"".join(p[0] for p in pieces) == path.read_bytes()[2:]
        assert b"\n29,29.5\n30\n" in b"\n" + pieces[-1][0] and pieces[-1][3]  # the last two rows
        assert all(p[0].endswith(b"\n") for p in pieces[:-1])


# --------------------------------------------------------------------------------- a blank line, iter_table
def _table(path: Path, piece_bytes: int | None) -> tuple:
    warnings: list[str] = []

    def read():
        rows = list(
            iter_table(
                path, delimiter=",", skip_lines=1, names=["a", "b", "c"], piece_bytes=piece_bytes, warnings=warnings
            )
        )
        return np.concatenate([v for v, _ in rows]), [first for _, first in rows]

    result = outcome(read)
    return result if result[0] == "error" else ("ok", (result[1][0], warnings))


@pytest.mark.parametrize(
    ("blank", "problem"),
    [
        (b"\n", "empty line inside the data"),
        (b"\r\n", "empty line inside the data"),
        (b" \t\n", "truncated line: 1 fields, expected 3"),
    ],
)
def test_a_blank_line_at_any_piece_border_is_reported_by_iter_table(tmp_path, blank, problem):
    """A blank line inside the rows is an error naming its line, wherever the pieces are cut (before: a piece
    that ended with it dropped it as trailing blank lines, and the pieces read on)."""
    rows = [b"%d,%.3f,%.3f\n" % (i, i * 0.5, i * 0.25) for i in range(40)]
    rows.insert(20, blank)
    path = tmp_path / "blank.csv"
    path.write_bytes(b"a,b,c\n" + b"".join(rows))
    whole = _table(path, None)
    assert whole == ("error", f"{path}: line 22: {problem}")
    for piece_bytes in range(1, len(path.read_bytes()) + 2):
        assert _table(path, piece_bytes) == whole, piece_bytes


def test_blank_lines_ending_the_file_are_no_error_in_any_pieces(tmp_path):
    path = tmp_path / "end.csv"
    path.write_bytes(
        b"a,b,c\n" + b"".join(b"%d,%.3f,%.3f\n" % (i, i * 0.5, i * 0.25) for i in range(30)) + b"\n\r\n \n"
    )
    whole = _table(path, None)
    assert whole[0] == "ok" and len(whole[1][0]) == 30
    for piece_bytes in range(1, 400):
        got = _table(path, piece_bytes)
        assert got[0] == "ok" and got[1][0].tobytes() == whole[1][0].tobytes() and got[1][1] == whole[1][1]


# ---------------------------------------------------------------------------------- the IMU unit check in pieces
def _slices(n: int, rng: np.random.Generator, most: int) -> list[slice]:
    """Random consecutive slices of ``n`` samples, from 1 sample up to ``most`` (log-uniform)."""
    bounds, at = [0], 0
    while at < n:
        at = min(n, at + int(np.exp(rng.uniform(0, np.log(most)))))
        bounds.append(at)
    return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


@pytest.mark.parametrize("hours", [0.5, 3.0])
def test_unit_check_excerpts_are_the_same_in_any_pieces(hours):
    """The streaming path's IMU unit check (``plausibility.PieceExcerpts``) sees the samples the whole recording's
    check sees (``recording_warnings``), whatever the pieces, on a recording that fits the check (0.5 h at 25 Hz)
    and one that is judged on excerpts (3 h, with a 10-minute gap): same samples, same warnings. The gyroscope is
    deg/s numbers declared rad/s, a bias at rest: the whole recording warns."""
    from imulog.converters import plausibility as plaus

    from imulog.model import ImuStream, Recording

    rng = np.random.default_rng(int(hours * 10))
    n = int(hours * 3600 * 25)
    t = np.arange(n, dtype=np.int64) * 40_000_000
    t[n // 2 :] += 600 * 10**9  # a gap of 10 minutes
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 0.02, (n, 3))
    gyr = rng.normal(0, 0.05, (n, 3)) + [0.6, -0.4, 0.2]
    whole = Recording(imus=[ImuStream(name="wrist", t_ns=t, acc=acc, gyr=gyr)])
    expected = plaus.recording_warnings(whole)
    assert len(expected) == 1 and "at rest the gyroscope reads" in expected[0]
    t_whole, arrays_whole = plaus.excerpts(t, acc, gyr)
    for seed, most in enumerate([n // 3, 5000, 20]):  # pieces under 1 s (20 samples): the old per-piece
        # excerpts, a NaN row after each, left no 1 s rest window and missed the warning
        spread, ex = plaus.PieceExcerpts(), plaus.Excerpts()
        for sl in _slices(n, np.random.default_rng(seed), most):
            spread.add(ImuStream(name="wrist", t_ns=t[sl], acc=acc[sl], gyr=gyr[sl]))
            ex.add(t[sl], acc[sl], gyr[sl])
        t_ex, arrays = ex.result()
        assert t_ex.tobytes() == t_whole.tobytes()
        for a, b in zip(arrays, arrays_whole, strict=True):
            assert np.array_equal(a, b, equal_nan=True)
        assert spread.warnings() == expected


# ------------------------------------------------------------------------- HDF5 through the Python API in pieces
def test_a_long_broad_trial_converts_through_the_python_api_in_a_child_per_piece(shared_data, tmp_path, monkeypatch):
    """``Converter.convert`` of an HDF5 reader is its pieces joined, each piece's rows read in a guarded child of its
    own: a BROAD trial four times the shared one (27 MB of samples) converts with the children capped at 8 MiB, in
    children that read at most a piece of rows each (before: one child read every row, which fails at that cap
    when the child's heap must grow for them)."""
    h5py = pytest.importorskip("h5py")
    import imulog.converters._h5pieces as h5pieces
    from imulog.converters import broad

    src = shared_data / "broad" / "02_undisturbed_slow_rotation_B.hdf5"
    path = tmp_path / "long_B.hdf5"
    with h5py.File(src, "r") as f, h5py.File(path, "w") as out:
        out.attrs.update(dict(f.attrs))
        for key in f:
            out[key] = np.concatenate([np.asarray(f[key])] * 4)
        n = 4 * len(f["imu_acc"])
    monkeypatch.setattr(broad, "READER_MEMORY_BYTES", 8 << 20)
    monkeypatch.setattr(h5pieces, "SCAN_ROWS", 4096)
    monkeypatch.setattr(h5pieces, "PIECE_BYTES", 256 << 10)
    reads: list[tuple[int, int]] = []
    guarded = broad._guarded

    def recorded(p, fn, *args):
        if fn is broad._rows:
            reads.append(args[-2:])
        return guarded(p, fn, *args)

    monkeypatch.setattr(broad, "_guarded", recorded)
    rec = broad.CONVERTER.convert(path)
    assert len(rec.imus[0]) == n
    rows = (256 << 10) // (8 * 16)  # 16 float64 values a row (imu acc, gyr, mag; optical position, quaternion)
    assert reads == [(a, min(n, a + rows)) for a in range(0, n, rows)] and len(reads) > 100
    joined = concat_chunks(list(broad.CONVERTER.iter_chunks(path)))
    assert rec.imus[0].acc.tobytes() == joined.imus[0].acc.tobytes() and rec.metadata == joined.metadata


# ------------------------------------------------------------------- what the header does not say, in pieces
def test_read_ahead_stops_at_the_piece_that_completes_the_rows():
    """``imulog.model.first_pieces``, the read-ahead of the delimited reader (``DECIDE_ROWS``) and of the viewer
    twins rebuilt block by block (``twin_blocks.MEDIAN_SAMPLES``): the pieces up to the one that reaches the rows,
    their row count, and the rest left in the iterator; all pieces when they hold fewer rows."""
    from imulog.model import first_pieces

    pieces = iter([np.zeros(3), np.zeros(4), np.zeros(5), np.zeros(6)])
    ahead, rows = first_pieces(pieces, 7, len)
    assert [len(p) for p in ahead] == [3, 4] and rows == 7
    assert [len(p) for p in pieces] == [5, 6]
    ahead, rows = first_pieces(iter([np.zeros(2), np.zeros(2)]), 100, len)
    assert [len(p) for p in ahead] == [2, 2] and rows == 4
    assert first_pieces(iter([]), 1, len) == ([], 0)


@pytest.mark.parametrize("gyr_peak", [200.0, 0.03])
def test_units_a_header_lacks_are_decided_on_the_same_rows_in_any_pieces(tmp_path, gyr_peak):
    """A unit-less table (time, acc in g, gyr): the time unit and the axes' units are decided on the first
    ``delimited.DECIDE_ROWS`` rows, whole and in pieces (the first pieces read ahead). Before, a first piece of one
    row had no time step (``a step of 0 fits no unit``) and the gyroscope's evidence (its peaks) came from the
    first piece alone. A gyroscope of 200 deg/s peaks is told deg/s; one of 0.03 cannot be told: the same error."""
    from imulog.converters import _pieces
    from imulog.converters.registry import get

    rng = np.random.default_rng(1)
    n = 600
    t = np.arange(n) * 0.01 + rng.normal(0, 0.0005, n)
    acc = np.tile([0.0, 0.0, 1.0], (n, 1)) + rng.normal(0, 0.002, (n, 3))
    gyr = gyr_peak * np.sin(np.arange(n) / 50.0)[:, None] * [1.0, 0.5, 0.2] + rng.normal(0, 0.001, (n, 3))
    path = tmp_path / "unitless.csv"
    header = "time,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z"
    np.savetxt(path, np.column_stack([t, acc, gyr]), delimiter=",", header=header, comments="", fmt="%.5f")
    conv = get("delimited")
    whole = outcome(lambda: conv.convert(path))
    if gyr_peak > 100:
        assert whole[0] == "ok" and "gyr in deg/s" in whole[1].warnings[0]
    else:
        assert whole[0] == "error" and "values cannot tell" in whole[1]
    for piece_bytes in piece_sizes(len(path.read_bytes()) // 3, 8, seed=int(gyr_peak)):
        _pieces.PIECE_BYTES, saved = piece_bytes, _pieces.PIECE_BYTES
        try:
            got = outcome(lambda: concat_chunks(list(conv.iter_chunks(path))))
        finally:
            _pieces.PIECE_BYTES = saved
        assert_same_outcome(whole, got)


# ------------------------------------------------------------------------------ through imulog convert, archives
@pytest.mark.parametrize("defect", ["cut last row", "blank line", "NaN field"])
def test_imulog_convert_in_pieces_writes_the_same_archive_or_fails_alike(shared_data, tmp_path, monkeypatch, defect):
    """``imulog convert`` of a defective Nexus CSV whole and in 1-byte pieces (``convert_stream``): the same archive
    and warnings, or the same one-line error and no archive left behind."""
    from click.testing import CliRunner
    from test_convert_pieces_archive import assert_same_trial
    from test_convert_pieces_defects import DEFECTS, _sample

    import imulog.commands.convert_stream as cs
    from imulog.cli import cli

    src = shared_data / "vicon_nexus" / "markers.csv"
    path = tmp_path / "markers.csv"
    path.write_bytes(DEFECTS[defect](_sample(src)))
    runs = {}
    for how, min_bytes, piece_bytes in (("whole", 1 << 60, 1 << 24), ("pieces", 0, 1)):
        monkeypatch.setattr(cs, "STREAM_MIN_BYTES", min_bytes)
        monkeypatch.setattr("imulog.converters._pieces.PIECE_BYTES", piece_bytes)
        out = tmp_path / f"{how}.mcap"
        r = CliRunner().invoke(cli, ["convert", str(path), "-o", str(out)])
        assert ("piece by piece" in r.output) == (how == "pieces" and r.exit_code == 0)
        runs[how] = (r.exit_code, out, [ln for ln in r.output.splitlines() if "warning" in ln or "Error" in ln])
    (code_w, whole, lines_w), (code_p, pieces, lines_p) = runs["whole"], runs["pieces"]
    assert code_w == code_p and [ln.replace("pieces.mcap", "whole.mcap") for ln in lines_p] == lines_w
    if code_w:
        assert len(lines_w) == 1 and not whole.exists() and not pieces.exists()
    else:
        assert_same_trial(whole, pieces)
        assert defect != "cut last row" or any("last row cut short" in ln for ln in lines_w)
