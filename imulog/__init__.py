"""imulog: wearable-IMU rehabilitation trials as self-describing MCAP archives."""

from imulog import numba_cache as _numba_cache

__version__ = "0.1.0"

_numba_cache.install()  # compiled kernels' cache stamped with every module they depend on (docs/kinematics.md)
