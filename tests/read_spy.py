"""Which channel spans a step reads: every ``TrialReader.read`` recorded (the tests of bounded reads, issue 24)."""

from __future__ import annotations

from imulog.archive import TrialReader


def record_reads(monkeypatch) -> list[tuple[str, int | None, int | None]]:
    """Patch ``TrialReader.read`` (through pytest's ``monkeypatch``) to append ``(topic, start_ns, end_ns)`` of each
    read to the returned list, then read as before."""
    reads: list[tuple[str, int | None, int | None]] = []
    original = TrialReader.read

    def spy(self, topic, start_ns=None, end_ns=None):
        reads.append((topic, start_ns, end_ns))
        return original(self, topic, start_ns, end_ns)

    monkeypatch.setattr(TrialReader, "read", spy)
    return reads
