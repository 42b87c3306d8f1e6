"""Exports the field reads: typed tables (Parquet/CSV), OpenSense ``.sto``, BIDS-motion, C3D, and adapters.

Every export puts the trial on one clock (``device`` or ``reference``, :mod:`imulog.archive.trial_clock`) and
writes atomically (temporary name, then rename). One module per target; ``imulog export`` is a thin
click layer over these functions (docs/export.md).
"""

from typing import TYPE_CHECKING

from imulog.archive.trial_clock import CLOCKS, ClockError, TrialClock, trial_clock
from imulog.export._atomic import ExportError
from imulog.export.table import ExportResult, channel_table, export_table

TARGETS = ("parquet", "csv", "sto", "trc", "bids", "c3d")  # imulog export --to (tests/test_python_api.py)


if TYPE_CHECKING:  # a user's type checker sees the real signatures; at run time each imports its module when called
    from imulog.export.bids import export_bids
    from imulog.export.c3d import export_c3d
    from imulog.export.sto import export_sto
    from imulog.export.trc import export_trc
else:

    def export_sto(*args, **kwargs) -> ExportResult:
        """See :func:`imulog.export.sto.export_sto`."""
        from imulog.export.sto import export_sto as f

        return f(*args, **kwargs)

    def export_trc(*args, **kwargs) -> ExportResult:
        """See :func:`imulog.export.trc.export_trc`."""
        from imulog.export.trc import export_trc as f

        return f(*args, **kwargs)

    def export_bids(*args, **kwargs) -> ExportResult:
        """See :func:`imulog.export.bids.export_bids`."""
        from imulog.export.bids import export_bids as f

        return f(*args, **kwargs)

    def export_c3d(*args, **kwargs) -> ExportResult:
        """See :func:`imulog.export.c3d.export_c3d`."""
        from imulog.export.c3d import export_c3d as f

        return f(*args, **kwargs)


__all__ = [
    "CLOCKS",
    "TARGETS",
    "ClockError",
    "ExportError",
    "ExportResult",
    "TrialClock",
    "channel_table",
    "export_bids",
    "export_c3d",
    "export_sto",
    "export_table",
    "export_trc",
    "trial_clock",
]
