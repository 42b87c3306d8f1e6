"""APDM CSV in pieces (issue 24, point 4): both shared APDM CSV exports (``../shared/data/devices/apdm_csv``: the
labelled layout with a ``Sample Rate`` row, and Format=7, whose rate is estimated from all its times) convert
through ``imulog convert`` whole and in tiny pieces of text to the same archive, sample by sample (the comparison
of ``tests/test_convert_pieces_archive.py``)."""

from __future__ import annotations

import pytest
from test_convert_pieces_archive import assert_same_trial, convert_twice

TEXT = "imulog.converters._pieces.PIECE_BYTES"
CASES = [("imuData01.csv", 32768), ("apdm_format7.csv", 64)]


def test_every_shared_apdm_csv_is_a_case(shared_data):
    assert sorted(p.name for p in (shared_data / "devices" / "apdm_csv").glob("*.csv")) == sorted(c for c, _ in CASES)


@pytest.mark.parametrize(("name", "piece_bytes"), CASES)
def test_apdm_csv_pieces_write_the_whole_files_archive(name, piece_bytes, shared_data, tmp_path, monkeypatch):
    src = shared_data / "devices" / "apdm_csv" / name
    whole, pieces = convert_twice(src, tmp_path, (TEXT, piece_bytes), monkeypatch)
    assert_same_trial(whole, pieces)


@pytest.mark.parametrize(("name", "piece_bytes"), CASES)
def test_pieces_joined_are_the_whole_recording(name, piece_bytes, shared_data, monkeypatch):
    from imulog.converters.registry import get
    from test_convert_pieces import _pieces_equal_whole

    src = shared_data / "devices" / "apdm_csv" / name
    conv = get("apdm")
    whole = conv.convert(src)
    monkeypatch.setattr(TEXT, piece_bytes)
    _pieces_equal_whole(list(conv.iter_chunks(src)), whole)
