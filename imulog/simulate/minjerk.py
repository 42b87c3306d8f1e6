"""Minimum-jerk (Hogan & Flash 1985) fifth-order profile and its derivatives.

``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5`` for ``tau`` in [0, 1]: the normalised position of a
point-to-point movement that minimises integrated squared jerk, with zero velocity and zero
acceleration at both ends (R2G thesis section 3.3.7 uses it for its reference trajectory, [43]).
"""

from __future__ import annotations

import numpy as np


def profile(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``s, ds/dtau, d2s/dtau2`` at ``tau`` (clipped to [0, 1], so constant outside)."""
    tau = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    t2 = tau * tau
    t3 = t2 * tau
    s = t3 * (10.0 - 15.0 * tau + 6.0 * t2)
    ds = 30.0 * t2 * (1.0 - 2.0 * tau + t2)
    dds = 60.0 * tau * (1.0 - 3.0 * tau + 2.0 * t2)
    return s, ds, dds


PEAK_SPEED_FACTOR = 1.875
"""Peak of ds/dtau: a movement of length D in T seconds peaks at 1.875 D / T."""


def bump(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lift profile ``b(tau) = 64 tau^3 (1 - tau)^3`` (peak 1 at mid-movement, zero velocity and
    acceleration at both ends) and its first two derivatives with respect to ``tau``."""
    tau = np.clip(np.asarray(tau, dtype=float), 0.0, 1.0)
    u = 1.0 - tau
    b = 64.0 * tau**3 * u**3
    db = 192.0 * tau**2 * u**2 * (u - tau)
    ddb = 384.0 * tau * u * ((u - tau) ** 2 - tau * u)
    return b, db, ddb
