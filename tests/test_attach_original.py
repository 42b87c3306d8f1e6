"""--attach-original always|never|auto: small originals attached, large ones recorded by name, size and SHA-256;
imulog doctor --original checks a file kept apart against the record."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from imulog.cli import cli

SAMPLE = Path(__file__).parent.parent / ".." / "shared" / "data" / "devices" / "axivity_cwa" / "ax6_sample.cwa"


@pytest.fixture()
def cwa(tmp_path) -> Path:
    if not SAMPLE.exists():
        pytest.skip(f"{SAMPLE} not available")
    dst = tmp_path / "ax6.cwa"
    dst.write_bytes(SAMPLE.read_bytes())
    return dst


def _convert(src: Path, out: Path, *args: str, env: dict | None = None) -> dict:
    r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out), *args], env=env)
    assert r.exit_code == 0, r.output
    from imulog.archive import TrialReader

    with TrialReader(out) as t:
        return {"raw": t.metadata["imulog.raw"], "attachments": [a.name for a in t.iter_attachments()]}


@pytest.mark.parametrize("streamed", [False, True])
def test_modes(cwa, tmp_path, monkeypatch, streamed):
    if streamed:
        monkeypatch.setattr("imulog.commands.convert_stream.STREAM_MIN_BYTES", 0)
    digest = hashlib.sha256(cwa.read_bytes()).hexdigest()
    auto = _convert(cwa, tmp_path / "auto.mcap")
    assert auto["attachments"] == ["ax6.cwa"] and "originals" not in auto["raw"]
    never = _convert(cwa, tmp_path / "never.mcap", "--attach-original", "never")
    assert never["attachments"] == []
    assert never["raw"]["originals"] == [{"name": "ax6.cwa", "size": cwa.stat().st_size, "sha256": digest}]
    monkeypatch.setattr("imulog.archive.writer.ATTACH_MAX_BYTES", 1000)  # the sample is larger: recorded only
    small_limit = _convert(cwa, tmp_path / "limit.mcap")
    assert small_limit["attachments"] == [] and small_limit["raw"]["originals"][0]["sha256"] == digest
    always = _convert(cwa, tmp_path / "always.mcap", "--attach-original", "always")
    assert always["attachments"] == ["ax6.cwa"]
    r = CliRunner().invoke(cli, ["doctor", str(tmp_path / "never.mcap")])
    assert r.exit_code == 0, r.output


def test_doctor_original(cwa, tmp_path):
    out = tmp_path / "t.mcap"
    _convert(cwa, out, "--attach-original", "never")
    r = CliRunner().invoke(cli, ["doctor", str(out), "--original", str(cwa), "--json"])
    assert r.exit_code == 0, r.output
    assert any("is the original 'ax6.cwa'" in c for c in json.loads(r.output)["checks"])
    changed = tmp_path / "other" / "ax6.cwa"
    changed.parent.mkdir()
    data = bytearray(cwa.read_bytes())
    data[5000] ^= 1
    changed.write_bytes(bytes(data))
    r = CliRunner().invoke(cli, ["doctor", str(out), "--original", str(changed)])
    assert r.exit_code == 1 and "differs from the original 'ax6.cwa'" in r.output
    attached = tmp_path / "a.mcap"
    _convert(cwa, attached)
    r = CliRunner().invoke(cli, ["doctor", str(attached), "--original", str(cwa)])
    assert r.exit_code == 0, r.output
