"""``imulog convert`` piece by piece writes the archive it writes from the whole file (issue 24, point 4) for the lab
and device text exports: Motive CSV, Qualisys TSV, OpenSim TRC, ``.sto``/``.mot``, Delsys CSV, Empatica E4 files and
ActiLife epoch CSV. Every shared file of those formats (``../shared/data/devices``) is converted through the command
twice, once whole and once in tiny pieces through the streaming writer (the threshold ``STREAM_MIN_BYTES`` at 0, as
``IMULOG_STREAM_MIN_BYTES=1`` sets it), and the two trials are compared sample by sample, channel metadata and
records (the helpers of ``test_convert_pieces_archive.py``). Formats without a shared file (Qualisys) and what the
whole file decides but the first piece cannot see (a time column with holes, a marker never seen, rates estimated
from every time) are checked on files written here. Bad input (a truncated row, a missing column) gives the same
one-line error in pieces as whole."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, convert_file, detect
from imulog.converters._binary import concat_chunks
from test_convert_pieces_archive import assert_same_trial, convert_twice

from imulog.cli import cli

SHARED_DATA = Path(os.environ.get("IMULOG_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
TEXT = "imulog.converters._pieces.PIECE_BYTES"
DEV = SHARED_DATA / "devices"

#: every shared file of the formats (folder, file name pattern), the acceptance list
FOLDERS = {
    "optitrack_motive": "*.csv",
    "opensim_trc": "*.trc",
    "opensim_mot": "*.mot",
    "opensense_sto": "*.sto",
}
CASES = [(f"{folder}/{p.name}", 2048) for folder, pat in FOLDERS.items() for p in sorted((DEV / folder).glob(pat))]


def test_every_shared_file_of_these_formats_is_a_case(shared_data):
    found = {f"{folder}/{p.name}" for folder, pat in FOLDERS.items() for p in (shared_data / "devices" / folder).glob(pat)}
    assert found == {rel for rel, _ in CASES} and len(found) >= 1


@pytest.mark.parametrize(("rel", "piece_bytes"), CASES, ids=[Path(c[0]).name for c in CASES])
def test_pieces_write_the_whole_files_archive(rel, piece_bytes, shared_data, tmp_path, monkeypatch):
    whole, pieces = convert_twice(shared_data / "devices" / rel, tmp_path, (TEXT, piece_bytes), monkeypatch)
    assert_same_trial(whole, pieces)


def pieces_equal_whole(path: Path, piece_bytes: int, monkeypatch) -> list:
    """The converter's pieces at ``piece_bytes`` joined equal its whole-file recording (every array, meta, record,
    warning); returns the pieces."""
    import dataclasses

    monkeypatch.setattr(TEXT, piece_bytes)
    conv = detect(path)
    pieces = list(conv.iter_chunks(path))
    assert len(pieces) > 1
    whole, joined = convert_file(path), concat_chunks(pieces)
    assert joined.metadata == whole.metadata and joined.warnings == whole.warnings
    assert [s.topic for s in joined.streams()] == [s.topic for s in whole.streams()]
    for a, b in zip(whole.streams(), joined.streams(), strict=True):
        for f in dataclasses.fields(a):
            va, vb = getattr(a, f.name), getattr(b, f.name)
            if isinstance(va, np.ndarray):
                assert va.dtype == vb.dtype and va.shape == vb.shape and va.tobytes() == vb.tobytes(), (a.topic, f)
            else:
                assert va == vb, (a.topic, f.name)
    return pieces


def same_error(path: Path, piece_bytes: int, monkeypatch) -> str:
    """The one-line error of the whole file and of its pieces (through ``imulog convert`` both ways): the same."""
    import imulog.commands.convert_stream as cs

    out = []
    for threshold in (1 << 60, 0):
        monkeypatch.setattr(cs, "STREAM_MIN_BYTES", threshold)
        monkeypatch.setattr(TEXT, piece_bytes)
        target = path.parent / f"out_{threshold}.mcap"
        r = CliRunner().invoke(cli, ["convert", str(path), "-o", str(target)])
        assert r.exit_code != 0 and not target.exists(), r.output
        out.append(r.output.strip().splitlines()[-1])
    assert out[0] == out[1]
    return out[0]
