"""A step never turns a file doctor rejects into one it accepts without saying so (issue 26, point 5).

Each summary defect of ``imulog.archive.summary_check`` is crafted into a sound trial by rewriting its summary
(the data section untouched): ``doctor`` rejects the file; a step's append then either refuses with the message
doctor gives (nothing written) or repairs it, with one line on stderr and an ``imulog.repair.<n>`` record.
"""

from __future__ import annotations

import hashlib
import struct
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_archive_helpers import synthetic_recording

from imulog.archive import TrialReader, append_derived, write_trial
from imulog.archive import _mcap as m
from imulog.archive.doctor import check_file
from imulog.archive.errors import ArchiveCorruptError
from imulog.cli import cli
from imulog.model import SignalStream


@pytest.fixture(scope="module")
def sound(tmp_path_factory) -> Path:
    """A converted trial plus one derived channel, /derived/x (its chunk is the last one)."""
    path = write_trial(tmp_path_factory.mktemp("repair") / "trial.mcap", synthetic_recording(np.random.default_rng(5)))
    append_derived(path, [_derived(path)], run={"step": "x"})
    assert check_file(path).ok
    return path


def with_summary(src: Path, dst: Path, edit, *, break_offset: bool = False) -> Path:
    """``src`` with its summary records replaced by ``edit(records)`` (full records, summary offsets rebuilt,
    CRC right); ``break_offset`` makes the first summary offset one byte short."""
    data = src.read_bytes()
    s = m.read_summary_from_bytes(data)
    footer = len(data) - len(m.MAGIC) - m.FOOTER_SIZE
    end = s.summary_offset_start or footer
    records = [
        bytes(data[s.summary_start + off : s.summary_start + off + 9 + len(body)])
        for _, off, body in m.iter_records(data[s.summary_start : end])
    ]
    records = edit(records)
    body, offsets, k = bytearray(), [], 0
    while k < len(records):
        op, start = records[k][0], s.summary_start + len(body)
        while k < len(records) and records[k][0] == op:
            body += records[k]
            k += 1
        length = s.summary_start + len(body) - start - (1 if break_offset and not offsets else 0)
        offsets.append(m.record(m.Op.SUMMARY_OFFSET, struct.pack("<BQQ", op, start, length)))
    offset_start = s.summary_start + len(body)
    body += b"".join(offsets)
    head = struct.pack("<BQQQ", m.Op.FOOTER, 20, s.summary_start, offset_start)
    crc = zlib.crc32(head, zlib.crc32(body))
    dst.write_bytes(data[: s.summary_start] + bytes(body) + head + struct.pack("<I", crc) + m.MAGIC)
    return dst


def _statistics(records: list[bytes], **changes) -> list[bytes]:
    out = []
    for r in records:
        if r[0] == m.Op.STATISTICS:
            st = replace(m.parse_statistics(memoryview(r)[9:]), **changes)
            r = st.encode()
        out.append(r)
    return out


def _counts(records: list[bytes]) -> dict[int, int]:
    st = next(m.parse_statistics(memoryview(r)[9:]) for r in records if r[0] == m.Op.STATISTICS)
    return dict(st.channel_message_counts)


def _edit_last(op: int, parse, change):
    """Change the last summary record of kind ``op`` (parsed with ``parse``, changed by ``change(rec)``)."""

    def edit(records: list[bytes]) -> list[bytes]:
        k = max(i for i, r in enumerate(records) if r[0] == op)
        rec = parse(memoryview(records[k])[9:])
        change(rec)
        return [*records[:k], rec.encode(), *records[k + 1 :]]

    return edit


def _first_of(op: int):
    def dup(records: list[bytes], n: int) -> list[bytes]:
        k = next(i for i, r in enumerate(records) if r[0] == op)
        return records[: k + 1] + [records[k]] * n + records[k + 1 :]

    return dup


DEFECTS = {  # name -> (edit of the summary records, break a summary offset, repaired)
    "100,000 duplicate chunk indexes": (lambda r: _first_of(m.Op.CHUNK_INDEX)(r, 100_000), False, True),
    "duplicate metadata indexes": (lambda r: _first_of(m.Op.METADATA_INDEX)(r, 3), False, True),
    "a summary offset one byte short": (lambda r: r, True, True),
    "statistics chunk count off by one": (
        lambda r: _statistics(r, chunk_count=sum(x[0] == m.Op.CHUNK_INDEX for x in r) + 1),
        False,
        True,
    ),
    "statistics message count off": (lambda r: _statistics(r, message_count=sum(_counts(r).values()) + 7), False, True),
    "statistics end time off": (lambda r: _statistics(r, message_end_time=1), False, True),
    "statistics count a channel that does not exist": (
        lambda r: _statistics(r, channel_message_counts={**_counts(r), 999: 0}),
        False,
        True,
    ),
    "no statistics record": (lambda r: [x for x in r if x[0] != m.Op.STATISTICS], False, False),
    # the summary against the data section (doctor's checks, from the record heads): refused
    "a chunk index with the wrong start time": (
        _edit_last(m.Op.CHUNK_INDEX, m.parse_chunk_index, lambda c: setattr(c, "message_start_time", 5)),
        False,
        False,
    ),
    "a metadata index with the wrong name": (
        _edit_last(m.Op.METADATA_INDEX, m.parse_metadata_index, lambda x: setattr(x, "name", "imulog.other")),
        False,
        False,
    ),
    "a channel record unlike the data section's": (
        _edit_last(m.Op.CHANNEL, m.parse_channel, lambda c: c.metadata.update(units="furlong")),
        False,
        False,
    ),
    "a chunk left out of the index": (
        lambda r: [x for k, x in enumerate(r) if k != max(i for i, y in enumerate(r) if y[0] == m.Op.CHUNK_INDEX)],
        False,
        False,
    ),
    "a per-channel count off by one": (
        lambda r: _statistics(r, channel_message_counts={k: v + (k == max(_counts(r))) for k, v in _counts(r).items()}),
        False,
        False,
    ),
    "statistics miss a channel's count": (
        lambda r: _statistics(r, channel_message_counts=dict(list(_counts(r).items())[1:])),
        False,
        False,
    ),
}


def _derived(path: Path, topic: str = "/derived/x") -> SignalStream:
    with TrialReader(path) as tr:
        t = tr.read(tr.topics()[0]).t_ns
    return SignalStream(topic, t, ["v"], ["1"], np.random.default_rng(len(topic)).normal(size=len(t)))


@pytest.mark.parametrize("topic", ["/derived/x", "/derived/y"])  # replace the last channel, or append
@pytest.mark.parametrize("name", list(DEFECTS))
def test_each_summary_defect_is_refused_or_repaired_out_loud(name, topic, sound, tmp_path, capfd):
    edit, break_offset, repaired = DEFECTS[name]
    path = with_summary(sound, tmp_path / "t.mcap", edit, break_offset=break_offset)
    before = check_file(path).problems
    assert before, f"doctor accepts the crafted file: {name}"
    if not repaired:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        with pytest.raises(ArchiveCorruptError) as exc:
            append_derived(path, [_derived(sound, topic)], run={"step": "x"})
        assert any(p in str(exc.value) for p in before), (str(exc.value), before)  # doctor's own message
        assert "nothing was written" in str(exc.value)
        assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
        return
    capfd.readouterr()
    append_derived(path, [_derived(sound, topic)], run={"step": "x"})
    err = capfd.readouterr().err.strip().splitlines()
    assert err and all("repaired the summary: " in line for line in err), err
    assert check_file(path).ok  # it passes now, and the file says why
    with TrialReader(path) as tr:
        run = tr.runs()[max(tr.runs())]
        repair = tr.metadata[run["repair"]]
        assert repair["repaired"] == [
            line.split("repaired the summary: ", 1)[1].rsplit(" (imulog.repair.", 1)[0] for line in err
        ]
    if name.startswith(("100,000", "duplicate", "a summary offset")):  # worded as doctor words them
        assert set(repair["repaired"]) <= set(before), (repair, before)


def test_a_step_on_the_issue_example_says_what_it_repaired(sound, tmp_path):
    """The issue's case, through the command line: 100,000 duplicate chunk indexes, then a processing step."""
    path = with_summary(sound, tmp_path / "dup.mcap", DEFECTS["100,000 duplicate chunk indexes"][0])
    assert "summary indexes the same chunk more than once (100000 extra entries)" in check_file(path).problems
    res = CliRunner().invoke(cli, ["process", "orientation", str(path), "--backend", "madgwick"])
    assert res.exit_code == 0, res.output
    assert "repaired the summary: summary indexes the same chunk more than once (100000 extra entries)" in res.stderr
    assert check_file(path).ok


def test_salvage_of_a_file_with_a_summary_defect_says_so(sound, tmp_path):
    from imulog.archive.salvage import salvage

    path = with_summary(sound, tmp_path / "dup.mcap", DEFECTS["100,000 duplicate chunk indexes"][0])
    report = salvage(path, tmp_path / "fixed.mcap")
    assert check_file(tmp_path / "fixed.mcap").ok
    with TrialReader(tmp_path / "fixed.mcap") as tr:
        notes = tr.metadata["imulog.salvage"]["notes"]
    assert any("summary indexes the same chunk more than once (100000 extra entries)" in n for n in notes), notes
    assert report.notes == notes
