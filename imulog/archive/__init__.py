"""imulog.archive: one trial = one self-describing MCAP file.

    from imulog.archive import write_trial, TrialReader, append_derived

    write_trial("trial.mcap", recording)                 # raw channels, metadata, attachments (atomic)
    with TrialReader("trial.mcap") as trial:
        imu = trial.read("/imu/wrist")                   # -> imulog.model.ImuStream (numpy arrays)
        df = trial.read_pandas("/imu/wrist", start_ns=0, end_ns=10**10)
    append_derived("trial.mcap", [signal], run={"step": "orientation", "algorithm": "vqf",
                                                "params": {...}, "inputs": ["/imu/wrist"]})

See docs/archive.md for the file layout, the append design and the CLI.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from imulog.archive.errors import ArchiveCorruptError, ArchiveError, ArchiveExistsError, ArchiveLockedError

if TYPE_CHECKING:
    from imulog.archive.append import append_derived, remove_derived
    from imulog.archive.doctor import DoctorReport
    from imulog.archive.reader import Attachment, ChannelInfo, TrialReader
    from imulog.archive.tables import stream_columns
    from imulog.archive.writer import write_trial

# Imported when first used: `imulog info` needs the reader only, not the writer, appender and twins.
_LAZY = {
    "append_derived": "append",
    "remove_derived": "append",
    "Attachment": "reader",
    "ChannelInfo": "reader",
    "TrialReader": "reader",
    "stream_columns": "tables",
    "write_trial": "writer",
}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'imulog.archive' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f"imulog.archive.{module}"), name)
    globals()[name] = value
    return value


def check_file(path: str | os.PathLike[str], *, decode: bool = True) -> DoctorReport:
    """Validate a trial (see :func:`imulog.archive.doctor.check_file`); returns a DoctorReport."""
    from imulog.archive.doctor import check_file as _check

    return _check(path, decode=decode)


__all__ = [
    "ArchiveCorruptError",
    "ArchiveError",
    "ArchiveExistsError",
    "ArchiveLockedError",
    "Attachment",
    "ChannelInfo",
    "TrialReader",
    "append_derived",
    "check_file",
    "remove_derived",
    "stream_columns",
    "write_trial",
]
