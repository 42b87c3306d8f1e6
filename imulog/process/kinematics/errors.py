"""Error metrics of Caruso et al. (2024, section II-F): e_tot and e_out, unconstrained and constrained.

    e_tot = rms(q - q_ref) over the whole recording,
    e_out = rms(q(t_out) - q_ref(t_out)),  t_out = samples where the *unconstrained* elbow or wrist
            centre is outside its workspace box,

per joint, in degrees. Angle differences are wrapped to (-180, 180] deg; samples where either
series is NaN are left out.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from imulog.process.kinematics.dh import JOINT_NAMES
from imulog.process.kinematics.solver import Workspace

__all__ = ["kinematics_errors", "outside_workspace", "rms_deg"]


def outside_workspace(elbow_m: np.ndarray, wrist_m: np.ndarray, workspace: Workspace, tol_m: float = 0.0) -> np.ndarray:
    """(N,) True where the elbow is outside its box or the wrist outside its box (the paper's t_out)."""
    out = np.zeros(len(elbow_m), dtype=bool)
    if workspace.elbow is not None:
        out |= ~workspace.elbow.contains(elbow_m, tol_m)
    if workspace.wrist is not None:
        out |= ~workspace.wrist.contains(wrist_m, tol_m)
    return out


def rms_deg(q_rad: np.ndarray, q_ref_rad: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Per-joint RMS (deg) of wrapped differences over ``mask`` (NaN when no sample)."""
    d = np.angle(np.exp(1j * (np.asarray(q_rad) - np.asarray(q_ref_rad))))
    ok = np.all(np.isfinite(d), axis=1)
    if mask is not None:
        ok &= np.asarray(mask, dtype=bool)
    if not ok.any():
        return np.full(d.shape[1], np.nan)
    return np.degrees(np.sqrt(np.mean(d[ok] ** 2, axis=0)))


def kinematics_errors(
    q_unconstrained_rad: np.ndarray,
    q_constrained_rad: np.ndarray,
    q_reference_rad: np.ndarray,
    t_out: np.ndarray,
) -> dict[str, Any]:
    """``e_tot_un``, ``e_tot_con``, ``e_out_un``, ``e_out_con`` (dicts joint -> deg) and ``t_out_fraction``."""
    t_out = np.asarray(t_out, dtype=bool)
    valid = np.all(np.isfinite(q_reference_rad), axis=1) & np.all(np.isfinite(q_unconstrained_rad), axis=1)

    def named(v: np.ndarray) -> dict[str, float | None]:
        return {name: (None if not np.isfinite(x) else float(x)) for name, x in zip(JOINT_NAMES, v, strict=True)}

    return {
        "e_tot_un_deg": named(rms_deg(q_unconstrained_rad, q_reference_rad)),
        "e_tot_con_deg": named(rms_deg(q_constrained_rad, q_reference_rad)),
        "e_out_un_deg": named(rms_deg(q_unconstrained_rad, q_reference_rad, t_out)),
        "e_out_con_deg": named(rms_deg(q_constrained_rad, q_reference_rad, t_out)),
        "t_out_fraction": float(np.mean(t_out[valid])) if valid.any() else None,
        "n_samples": int(valid.sum()),
        "n_out": int((t_out & valid).sum()),
    }
