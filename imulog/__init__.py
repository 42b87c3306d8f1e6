"""imulog: wearable-IMU rehabilitation trials as self-describing MCAP archives.

Every ``imulog`` command is a Python call with the same defaults (docs/python.md has the table):

    from imulog.archive import TrialReader, write_trial          # open / write a trial (imulog info, convert)
    from imulog.steps.orientation import run_orientation          # imulog process orientation (run_align_trial,
    from imulog.process.orientation import OrientationParams      #   run_phases, run_trajectory, run_evaluate ...)
    from imulog.batch import run, build_catalog, run_params       # imulog batch / catalog; a run's parameters back

    run_orientation("trial.mcap", params=OrientationParams(backend="madgwick", beta=0.03))  # -> StepOutcome
    with TrialReader("trial.mcap") as trial:
        q = trial.read("/derived/orientation/wrist")              # SignalStream: t_ns (int64 ns), values (N, 4)

Errors are exceptions whose one line names the file and what failed (``imulog.archive.ArchiveError``,
``imulog.steps.common.StepError``, ``imulog.params.ParamError``); the command line prints the same line.
"""

from imulog import numba_cache as _numba_cache

__version__ = "0.1.0"

_numba_cache.install()  # compiled kernels' cache stamped with every module they depend on (docs/kinematics.md)
