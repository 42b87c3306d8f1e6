"""Attached originals stored compressed (issue 28: bzip2 for text, zstd for binary files): every reader gives back the original bytes and SHA-256,
doctor and salvage agree with imulog.raw, and archives with plain attachments keep reading."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import pytest
from click.testing import CliRunner

from imulog.archive import TrialReader, packing
from imulog.cli import cli

CSV = Path(__file__).parent.parent / ".." / "shared" / "data" / "devices" / "apdm_csv" / "imuData01.csv"


@pytest.fixture()
def csv(tmp_path) -> Path:
    if not CSV.exists():
        pytest.skip(f"{CSV} not available")
    dst = tmp_path / "imuData01.csv"
    dst.write_bytes(CSV.read_bytes())
    return dst


@pytest.mark.parametrize("streamed", [False, True])
def test_packed_csv_reads_back_as_the_original(csv, tmp_path, monkeypatch, streamed):
    if streamed:
        monkeypatch.setattr("imulog.commands.convert_stream.STREAM_MIN_BYTES", 0)
    out = tmp_path / "t.mcap"
    r = CliRunner().invoke(cli, ["convert", str(csv), "-o", str(out), "--attach-original", "always"])
    assert r.exit_code == 0, r.output
    original = csv.read_bytes()
    with TrialReader(out) as t:
        (info,) = t.attachment_infos()
        (att,) = t.attachments()
        stored = t.summary.attachment_indexes[0]
        recorded = t.metadata["imulog.raw"]["attachments"][csv.name]
    assert (
        info["packed"]
        and info["media_type"] == "text/csv"
        and stored.media_type == "application/x-bzip2; imulog-packed=text/csv"
    )
    assert stored.data_size < 0.5 * len(original)  # CSV text packs well
    assert att.data == original and att.media_type == "text/csv"
    assert att.sha256 == hashlib.sha256(original).hexdigest() == recorded
    r = CliRunner().invoke(cli, ["doctor", str(out)])
    assert r.exit_code == 0, r.output


def test_incompressible_original_stays_plain():
    noise = os.urandom(100_000)
    data, media_type = packing.pack(noise, "application/octet-stream")
    assert data == noise and media_type == "application/octet-stream"
    assert packing.unpack(data, media_type) == noise


def test_salvage_keeps_packed_attachment(csv, tmp_path):
    from imulog.archive.salvage import salvage

    out = tmp_path / "t.mcap"
    r = CliRunner().invoke(cli, ["convert", str(csv), "-o", str(out), "--attach-original", "always"])
    assert r.exit_code == 0, r.output
    dst = tmp_path / "s.mcap"
    salvage(out, dst)
    with TrialReader(dst) as t:
        (att,) = t.attachments()
        assert att.data == csv.read_bytes()
        assert t.metadata["imulog.raw"]["attachments"][csv.name] == att.sha256


def test_binary_original_packs_with_zstd(shared_data):
    data = (shared_data / "devices" / "geneactiv_bin" / "GENEActiv_testfile.bin").read_bytes()
    noise = bytes(range(256)) * 64 + b"\0" + data  # a NUL byte: binary, whatever the extension says
    for blob, media_type in ((noise, "application/octet-stream"), (data, "application/x-geneactiv")):
        stored, stored_type = packing.pack(blob, media_type)
        assert packing.is_packed(stored_type) and len(stored) < 0.9 * len(blob)
        assert packing.original_media_type(stored_type) == media_type
        assert packing.unpack(stored, stored_type) == blob
    assert packing.pack(noise, "application/octet-stream")[1].startswith("application/zstd;")
