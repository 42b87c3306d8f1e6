"""The fast text path of ``imulog.converters._table.read_numeric`` (issue 17: convert within 1.5x its floor).

* pyarrow's CSV reader parses the numeric block from the bytes in memory; whatever it would read differently from
  the pandas C parser (other NaN spellings, ``-0`` in whole-number columns, ragged or blank rows, quotes, spaces,
  line endings) goes to the pandas path, so every value, gap, warning and error message is what it was;
* the source is read once and its SHA-256 computed from those bytes (the conversion record does not re-read it);
* the plausibility checks' shortcuts (shared rest windows, excerpts copied as slices, the marker percentile
  settled by counts) give exactly what the direct computation gives.
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import imulog.converters._common as common
import imulog.converters._table as table
import numpy as np
import pytest
from imulog.converters import ConversionError, convert_file
from imulog.converters import plausibility as plaus

from imulog.commands.convert import conversion_record

REPO = Path(__file__).resolve().parents[1]
TEXT_SAMPLES = [  # (path under ../shared/data or the repository, whether the fast path must take it)
    "imu_text/fusion_sensor_data.csv",
    "imu_text/shimmer_consensys_export.csv",
    "vicon_nexus/markers.csv",
    "vicon_nexus/analogs.csv",
    "gaitmap_foot/imu_sample.csv",
    "gaitmap_foot/mocap_sample.csv",
    "devices/actigraph_gt3x/exampleRAW.csv",
]
HEADER = "Time (s)," + ",".join(
    [f"Gyroscope {a} (deg/s)" for a in "XYZ"] + [f"Accelerometer {a} (g)" for a in "XYZ"] + ["Count"]
)


def _arrays(rec) -> dict[str, np.ndarray]:
    out = {}
    for s in rec.streams():
        for f in dataclasses.fields(s):
            v = getattr(s, f.name)
            if isinstance(v, np.ndarray):
                out[f"{s.topic}.{f.name}"] = v
    return out


def _outcome(path: Path, monkeypatch, *, arrow: bool):
    """(arrays, warnings) or the error message of converting ``path`` with or without the pyarrow path."""
    with monkeypatch.context() as m:
        if not arrow:
            m.setattr(table, "_parse_arrow", lambda *a: None)
        try:
            rec = convert_file(path)
        except ConversionError as e:
            return str(e)
    return _arrays(rec), rec.warnings


def _same(a, b) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    (xa, wa), (xb, wb) = a, b
    if wa != wb or set(xa) != set(xb):
        return False
    for k in xa:  # bit for bit: the sign of zero and the place of every NaN included
        x, y = xa[k], xb[k]
        if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
            return False
    return True


def _spy_arrow(monkeypatch) -> list[bool]:
    """Record whether each ``_parse_arrow`` call returned values (True) or left the block to pandas (False)."""
    taken: list[bool] = []
    real = table._parse_arrow

    def spy(*args):
        out = real(*args)
        taken.append(out is not None)
        return out

    monkeypatch.setattr(table, "_parse_arrow", spy)
    return taken


@pytest.mark.parametrize("rel", TEXT_SAMPLES)
def test_real_text_exports_parse_identically_and_take_the_fast_path(rel, shared_data, monkeypatch):
    path = shared_data / rel
    slow = _outcome(path, monkeypatch, arrow=False)
    taken = _spy_arrow(monkeypatch)
    fast = _outcome(path, monkeypatch, arrow=True)
    assert not isinstance(fast, str)
    assert _same(fast, slow)
    assert taken and all(taken)  # the fast path really parsed it (it did not silently fall back)


def _imu_text(rows: int = 300, seed: int = 0) -> list[str]:
    rng = np.random.default_rng(seed)
    lines = [HEADER]
    for i in range(rows):
        g = rng.normal(0, 20, 3)
        a = rng.normal(0, 0.3, 3) + [0, 0, 1]
        lines.append(f"{i / 100:.2f}," + ",".join(f"{v:.4f}" for v in [*g, *a]) + f",{i}")
    return lines


def _damage(lines: list[str], row: int, col: int, cell: str) -> list[str]:
    out = list(lines)
    cells = out[row].split(",")
    cells[col] = cell
    out[row] = ",".join(cells)
    return out


CASES = {
    "plain": lambda L: L,
    "NaN gap": lambda L: _damage(L, 50, 2, "NaN"),
    "empty gap": lambda L: _damage(L, 50, 5, ""),
    "'Nan' (pandas refuses it)": lambda L: _damage(L, 50, 2, "Nan"),
    "'+nan'": lambda L: _damage(L, 50, 2, "+nan"),
    "inf": lambda L: _damage(L, 50, 3, "inf"),
    "'Infinity' in the time column": lambda L: _damage(L, 50, 0, "Infinity"),
    "-0 in the whole-number column": lambda L: _damage(L, 50, 7, "-0"),
    "-0.0000 in a float column": lambda L: _damage(L, 50, 1, "-0.0000"),
    "leading space": lambda L: _damage(L, 50, 1, " 1.5"),
    "trailing space": lambda L: _damage(L, 50, 1, "1.5 "),
    "quoted number": lambda L: _damage(L, 50, 1, '"1.5"'),
    "underscore": lambda L: _damage(L, 50, 1, "1_5"),
    "text cell": lambda L: _damage(L, 50, 4, "abc"),
    "short row inside": lambda L: L[:50] + [",".join(L[50].split(",")[:5])] + L[51:],
    "long row inside": lambda L: L[:50] + [L[50] + ",7"] + L[51:],
    "blank line inside": lambda L: L[:50] + [""] + L[50:],
    "empty-cells row at the end": lambda L: L + [",,,,,,,"],
    "time goes backwards": lambda L: _damage(L, 60, 0, "0.01"),
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("ending", ["\n", "\r\n", "\r"])
def test_damaged_imu_text_gives_the_same_values_or_error_on_both_paths(case, ending, tmp_path, monkeypatch):
    path = tmp_path / "wrist.csv"
    path.write_bytes((ending.join(CASES[case](_imu_text())) + ending).encode())
    slow = _outcome(path, monkeypatch, arrow=False)
    fast = _outcome(path, monkeypatch, arrow=True)
    assert _same(fast, slow), (fast if isinstance(fast, str) else "values", slow if isinstance(slow, str) else "values")


def test_cut_final_row_and_trailing_blank_lines_on_the_fast_path(tmp_path, monkeypatch):
    lines = _imu_text()
    path = tmp_path / "wrist.csv"
    path.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:12])  # the last row cut inside a number
    taken = _spy_arrow(monkeypatch)
    fast = _outcome(path, monkeypatch, arrow=True)
    assert taken == [True]
    arrays, warnings = fast
    assert len(arrays["/imu/imu.t_ns"]) == len(lines) - 2 and "last row cut short" in warnings[0]
    path.write_text("\n".join(lines) + "\n\n \n\t\n")
    arrays, warnings = _outcome(path, monkeypatch, arrow=True)
    assert len(arrays["/imu/imu.t_ns"]) == len(lines) - 1 and warnings == []


def _nexus(rows: int = 120, markers: int = 3, seed: int = 2) -> list[str]:
    rng = np.random.default_rng(seed)
    width = 2 + 3 * markers
    lines = [
        "Trajectories" + "," * (width - 1),
        "100" + "," * (width - 1),
        ",," + ",".join(f"S:M{m},," for m in range(markers))[:-1],
        "Frame,Sub Frame," + ",".join(["X,Y,Z"] * markers),
        ",," + ",".join(["mm"] * 3 * markers),
    ]
    for i in range(rows):
        cells = [f"{v:.3f}" for v in rng.normal(500, 300, 3 * markers)]
        if i % 17 == 5:
            cells[3:6] = ["", "", ""]  # an occluded marker: a gap
        lines.append(f"{i + 1},0," + ",".join(cells))
    return lines


NEXUS_CASES = {
    "plain": lambda L: L,
    "short row inside (its cells are gaps)": lambda L: L[:40] + [",".join(L[40].split(",")[:6])] + L[41:],
    "'Nan' marker cell": lambda L: _damage(L, 40, 4, "Nan"),
    "padding comma on every row": lambda L: L[:5] + [x + "," for x in L[5:]],
    "Devices section after a blank line": lambda L: (
        L
        + ["", "Devices,,", "1000,,", ",,Force", "Frame,Sub Frame,Fz", ",,N"]
        + [f"{i // 10 + 1},{i % 10},{i * 0.5:.1f}" for i in range(1200)]
    ),
}


@pytest.mark.parametrize("case", sorted(NEXUS_CASES))
def test_nexus_csv_gives_the_same_values_or_error_on_both_paths(case, tmp_path, monkeypatch):
    path = tmp_path / "markers.csv"
    path.write_bytes(("\r\n".join(NEXUS_CASES[case](_nexus())) + "\r\n").encode())
    slow = _outcome(path, monkeypatch, arrow=False)
    fast = _outcome(path, monkeypatch, arrow=True)
    assert not isinstance(slow, str) or case.startswith("'Nan'"), slow
    assert _same(fast, slow)


# ------------------------------------------------------------------------------------------- source hash
def test_source_is_hashed_once_from_the_bytes_parsed(tmp_path, monkeypatch):
    path = tmp_path / "wrist.csv"
    path.write_text("\n".join(_imu_text()) + "\n")
    rec = convert_file(path)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    assert common.known_sha256(path) == digest
    calls = []
    real = hashlib.sha256
    monkeypatch.setattr(hashlib, "sha256", lambda *a: calls.append(1) or real(*a))
    assert conversion_record(rec.sources, {path.name: "delimited"})["sha256"] == {path.name: digest}
    assert calls == []  # not read and hashed a second time
    with open(path, "a") as f:  # the file changed since: hashed again, from the file
        f.write("3.00,1,2,3,0,0,1,300\n")
    assert common.known_sha256(path) is None
    new = conversion_record(rec.sources, {path.name: "delimited"})["sha256"][path.name]
    assert new == real(path.read_bytes()).hexdigest() != digest and calls


# ----------------------------------------------------------------------------------- plausibility shortcuts
def _marker_warnings_direct(topic: str, p: np.ndarray) -> list[str]:
    """The check as written before the shortcut: the 99th percentile of |finite coordinates|."""
    finite = p[np.isfinite(p)]
    if finite.size == 0:
        return []
    big = float(np.quantile(np.abs(finite), 0.99))
    if big > plaus.MARKER_MAX_M:
        return [
            f"{topic}: marker coordinates reach {big:.3g} m, larger than any lab: are they mm declared m? "
            "--unit markers=mm"
        ]
    if big < plaus.MARKER_MIN_SPAN_M:
        return [
            f"{topic}: every marker stays within {big * 1000:.2g} mm of the origin: are the numbers m declared mm? "
            "--unit markers=m"
        ]
    return []


@pytest.mark.parametrize("seed", range(40))
def test_marker_check_shortcut_matches_the_percentile(seed):
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(1, 400)), int(rng.integers(1, 5))
    scale = [0.004, 0.0099, 0.0101, 0.5, 49.5, 50.0, 50.5, 600.0][seed % 8]
    pos = rng.normal(0, 1, (n, m, 3)) * scale * rng.choice([0.9, 1.0, 1.1])
    if seed % 3 == 0:
        pos[rng.random((n, m)) < 0.3] = np.nan
    if seed % 5 == 0:
        pos[0, 0, 0] = np.inf
    if seed % 7 == 0:  # exactly 1 % of the coordinates far away: the percentile sits on the boundary
        k = max(1, pos.size // 100)
        pos.reshape(-1)[rng.choice(pos.size, k, replace=False)] = 60.0
    assert plaus.marker_warnings("/markers/x", pos) == _marker_warnings_direct("/markers/x", pos)


def test_marker_check_of_all_nan_positions_says_nothing():
    assert plaus.marker_warnings("/markers/x", np.full((10, 2, 3), np.nan)) == []


@pytest.mark.parametrize("n", [plaus.MAX_CHECK_SAMPLES + 1, 360_000, 1_000_003])
def test_excerpts_are_every_stride_th_minute_with_a_nan_row_after_each(n):
    """A long recording at 100 Hz is checked on the 60 s blocks of time whose number is a multiple of the smallest
    power of two that makes them fit MAX_CHECK_SAMPLES (with a NaN row between two), computed here directly."""
    t = np.arange(n, dtype=np.int64) * 10_000_000 + 123
    x = np.random.default_rng(n).normal(size=(n, 3))
    t_ex, (x_ex, none) = plaus.excerpts(t, x, None)
    block = np.arange(n) // 6000
    stride = 1
    while np.sum(block % stride == 0) + (len(np.unique(block[block % stride == 0])) - 1) * (stride > 1) > 120_000:
        stride *= 2
    idx = np.flatnonzero(block % stride == 0)
    cut = np.flatnonzero(np.diff(block[idx])) + 1
    ref_x = np.insert(x[idx], cut, np.nan, axis=0)
    ref_t = np.insert(t[idx], cut, t[idx][cut - 1] + 1)
    assert none is None and len(cut) > 0 and stride > 1
    assert np.array_equal(x_ex, ref_x, equal_nan=True) and np.array_equal(t_ex, ref_t)
    assert len(t_ex) <= plaus.MAX_CHECK_SAMPLES and np.all(np.diff(t_ex) > 0)


# --------------------------------------------------------------------------------- text piece by piece
def _pieces_or_error(path: Path, piece_bytes: int, **kw):
    from imulog.converters.delimited import iter_delimited

    try:
        return list(iter_delimited(path, piece_bytes=piece_bytes, **kw))
    except ConversionError as e:
        return str(e)


def _whole_or_error(path: Path, **kw):
    from imulog.converters.delimited import read_delimited

    try:
        return read_delimited(path, **kw)
    except ConversionError as e:
        return str(e)


def _assert_pieces_equal_whole(pieces, whole) -> None:
    assert len(pieces) > 1
    for stream in whole.streams():
        parts = [next(s for s in p.streams() if s.topic == stream.topic) for p in pieces]
        for f in dataclasses.fields(stream):
            value = getattr(stream, f.name)
            if isinstance(value, np.ndarray):
                joined = np.concatenate([getattr(p, f.name) for p in parts])
                assert joined.dtype == value.dtype and joined.tobytes() == value.tobytes(), (stream.topic, f.name)
    assert [w for p in pieces for w in p.warnings] == whole.warnings
    assert pieces[-1].metadata == whole.metadata  # the device record (rate from the median step of every piece)


@pytest.mark.parametrize("piece_bytes", [3000, 65536])
def test_text_pieces_join_to_the_whole_file_conversion(piece_bytes, shared_data, tmp_path):
    from imulog.converters.mapping import load_mapping

    _assert_pieces_equal_whole(
        _pieces_or_error(shared_data / "imu_text/fusion_sensor_data.csv", piece_bytes),
        _whole_or_error(shared_data / "imu_text/fusion_sensor_data.csv"),
    )
    sim = REPO / "recordings/sim/r2g_s00_t00_imu.csv"  # no time column: a rate and a mapping file
    mapping = load_mapping(sim.with_name("r2g_s00_t00_imu.mapping.json"))
    _assert_pieces_equal_whole(
        _pieces_or_error(sim, piece_bytes, mapping=mapping), _whole_or_error(sim, mapping=mapping)
    )
    lines = _imu_text(8000)
    cut = tmp_path / "cut.csv"  # gaps, CRLF, a cut final row
    lines = _damage(_damage(lines, 700, 3, ""), 1500, 2, "NaN")
    cut.write_bytes(("\r\n".join(lines[:-1]) + "\r\n" + lines[-1][:14]).encode())
    pieces, whole = _pieces_or_error(cut, piece_bytes), _whole_or_error(cut)
    assert "last row cut short" in whole.warnings[0]
    _assert_pieces_equal_whole(pieces, whole)


def _damaged(case: str, lines: list[str], row: int) -> list[str]:
    if case == "text cell":
        return _damage(lines, row, 4, "abc")
    if case == "time goes backwards":
        return _damage(lines, row, 0, "0.01")
    if case == "blank line inside":
        return lines[:row] + [""] + lines[row:]
    if case == "short row inside":
        return lines[:row] + [",".join(lines[row].split(",")[:4])] + lines[row + 1 :]
    return _damage(lines, row, 2, "Infinity")


@pytest.mark.parametrize(
    "case", ["text cell", "time goes backwards", "blank line inside", "short row inside", "Infinity"]
)
def test_damage_in_a_later_piece_names_the_same_line(case, tmp_path):
    lines = _imu_text(1200)
    for row in (233, 700, 1101):  # in different pieces, some next to a piece border
        damaged = _damaged(case, lines, row)
        path = tmp_path / f"wrist_{row}.csv"
        path.write_text("\n".join(damaged) + "\n")
        whole = _whole_or_error(path)
        assert isinstance(whole, str) and f"line {row + 1}" in whole, whole
        for piece_bytes in (1500, 4096, 10_000):
            assert _pieces_or_error(path, piece_bytes) == whole


def test_imulog_convert_streams_large_text_files(tmp_path, monkeypatch):
    from click.testing import CliRunner

    import imulog.commands.convert_stream as convert_stream
    from imulog.archive import TrialReader
    from imulog.cli import cli

    path = tmp_path / "wrist.csv"
    path.write_text("\n".join(_imu_text(30_000)) + "\n")
    runner = CliRunner()
    whole = runner.invoke(cli, ["convert", str(path), "-o", str(tmp_path / "whole.mcap")])
    assert whole.exit_code == 0 and "piece by piece" not in whole.output
    monkeypatch.setattr(convert_stream, "STREAM_MIN_BYTES", 100_000)
    monkeypatch.setattr("imulog.converters._pieces.PIECE_BYTES", 200_000)
    streamed = runner.invoke(cli, ["convert", str(path), "-o", str(tmp_path / "streamed.mcap")])
    assert streamed.exit_code == 0 and "piece by piece" in streamed.output, streamed.output
    with TrialReader(tmp_path / "whole.mcap") as a, TrialReader(tmp_path / "streamed.mcap") as b:
        assert a.topics() == b.topics() == ["/imu/imu", "/signals/imu"]
        for topic in a.topics():
            x, y = a.read(topic), b.read(topic)
            for f in dataclasses.fields(x):
                if isinstance(getattr(x, f.name), np.ndarray):
                    assert getattr(x, f.name).tobytes() == getattr(y, f.name).tobytes(), (topic, f.name)
        assert b.channels[0].message_count > 8  # pieces of 200 kB: several pieces, not one
        # (the channels' content hashes may differ: pieces of 200 kB end blocks early, so the messages differ)
        assert a.metadata["imulog.device.imu"] == b.metadata["imulog.device.imu"]
        assert a.metadata["imulog.conversion"]["sha256"] == b.metadata["imulog.conversion"]["sha256"]
        assert b.metadata["imulog.conversion"]["streamed"] is True
    assert runner.invoke(cli, ["doctor", str(tmp_path / "streamed.mcap")]).exit_code == 0


def test_source_hash_on_a_worker_thread_survives_fork(tmp_path):
    """read_source hashes large sources on a worker thread; a forked batch worker must not wait for the parent's."""
    import hashlib
    import os

    from imulog.converters._common import BACKGROUND_HASH_BYTES, known_sha256, read_source

    path = tmp_path / "big.bin"
    path.write_bytes(os.urandom(BACKGROUND_HASH_BYTES + 1))
    want = hashlib.sha256(path.read_bytes()).hexdigest()
    read_source(path)
    assert known_sha256(path) == want
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: hash again on its own (new) worker thread, report, exit at once
        os.close(r)
        read_source(path)
        os.write(w, (known_sha256(path) or "").encode())
        os._exit(0)
    os.close(w)
    got = os.read(r, 100).decode()
    os.waitpid(pid, 0)
    assert got == want
