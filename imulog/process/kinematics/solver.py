"""Per-sample joint angles from two segment orientations: unconstrained and constrained (Caruso 2024).

At every sample the five free joint angles ``q`` minimise (eq. 4)

    f(q) = gamma_UA^2 + gamma_FA^2,   gamma_S = angle(R_S(q) R_S_hat^T)   (eqs. 2-3, rad^2)

optionally subject to the joint limits g1 (eq. 6) and to the elbow and wrist centres lying inside
axis-aligned workspace boxes g2 (eq. 7), starting from the previous sample's solution (warm start).

The paper solves this with MATLAB's SQP (6.9 / 11.3 ms per sample). Here the same problem is solved
by a damped Newton / SQP iteration compiled with numba: the residual is the stacked rotation
vectors ``r = [log(R_UA(q) R_UA_hat^T), log(R_FA(q) R_FA_hat^T)]`` (so ``|r|^2 = f`` exactly),
with the analytic joint-axis Jacobian (its ``J^T r`` is the exact gradient of ``f / 2``) and the
exact Hessian of ``f / 2`` where it is positive definite (Gauss-Newton's ``J^T J`` elsewhere), with
Levenberg-Marquardt damping: a few iterations per sample from the previous solution. With
constraints, every iteration solves the linearised problem, a 5-variable QP with up to 22 linear
inequalities, through its dual (projected Gauss-Seidel, then an exact solve on the active set); an
L1 merit function accepts or rejects steps. Joint limits are met exactly (the last iterate is clipped
to them), workspace boxes to ``feasibility_tol_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from imulog.param_rules import check_rules
from imulog.process.kinematics.dh import N_FREE, ArmModel, JointLimits, forward_kinematics
from imulog.process.kinematics.solver_core import solve_packed_sequence

__all__ = [
    "RealTimeSolver",
    "SolveResult",
    "SolverParams",
    "Workspace",
    "WorkspaceBox",
    "constraint_arrays",
    "solve_sample_scipy",
    "solve_sequence",
]

DEFAULT_MODEL = ArmModel()
DEFAULT_LIMITS = JointLimits()
N_CON = 22  # 10 joint-limit rows + 6 elbow-box rows + 6 wrist-box rows


@dataclass(frozen=True)
class WorkspaceBox:
    """Axis-aligned box in the trunk frame (m); ``None`` or +-inf bounds leave that side open."""

    lower_m: tuple[float, float, float] = (-math.inf, -math.inf, -math.inf)
    upper_m: tuple[float, float, float] = (math.inf, math.inf, math.inf)

    def __post_init__(self) -> None:
        lo = [(-math.inf if v is None else float(v)) for v in self.lower_m]
        hi = [(math.inf if v is None else float(v)) for v in self.upper_m]
        if len(lo) != 3 or len(hi) != 3:
            raise ValueError("workspace box bounds need three coordinates (x, y, z) in metres")
        if any(a > b for a, b in zip(lo, hi, strict=True)):
            raise ValueError(f"workspace box lower {lo} exceeds upper {hi} (m)")
        object.__setattr__(self, "lower_m", tuple(lo))
        object.__setattr__(self, "upper_m", tuple(hi))

    def contains(self, p_m: np.ndarray, tol_m: float = 0.0) -> np.ndarray:
        """(N,) True where points (N, 3) m lie inside the box (``tol_m`` outside still counts)."""
        p = np.atleast_2d(p_m)
        return np.all((p >= np.asarray(self.lower_m) - tol_m) & (p <= np.asarray(self.upper_m) + tol_m), axis=1)

    def as_list(self) -> list[list[float | None]]:
        """``[[xlo, ylo, zlo], [xhi, yhi, zhi]]`` with ``None`` for open sides (JSON-friendly)."""
        return [
            [None if math.isinf(v) else v for v in self.lower_m],
            [None if math.isinf(v) else v for v in self.upper_m],
        ]

    @classmethod
    def from_list(cls, value) -> WorkspaceBox:
        """From ``[[xlo, ylo, zlo], [xhi, yhi, zhi]]`` (m, ``None`` = open)."""
        lo, hi = value
        return cls(tuple(lo), tuple(hi))


@dataclass(frozen=True)
class Workspace:
    """Task workspace g2 (eq. 7): boxes for the elbow and wrist centres (``None``: unconstrained)."""

    elbow: WorkspaceBox | None = None
    wrist: WorkspaceBox | None = None

    @classmethod
    def from_metadata(cls, record: dict) -> Workspace:
        """From an ``imulog.kinematics`` record's ``workspace_elbow_m`` / ``workspace_wrist_m``."""
        e = record.get("workspace_elbow_m")
        w = record.get("workspace_wrist_m")
        return cls(WorkspaceBox.from_list(e) if e else None, WorkspaceBox.from_list(w) if w else None)


@dataclass(frozen=True)
class SolverParams:
    """Iteration settings of the per-sample solver.

    ``max_iterations``: LM/SQP iterations per sample (50).
    ``step_tol_rad``: stop when the largest joint update is below this (1e-9 rad).
    ``feasibility_tol_m``: accepted workspace-box violation (1e-6 m, MATLAB's default constraint
    tolerance); a sample still further out after the iterations gets min-norm restoration steps.
    ``initial_damping``: Levenberg-Marquardt damping at the first iteration (1e-6, relative to rad^2).
    ``penalty``: weight of the L1 constraint violation in the merit function (1e4 per rad or m).
    ``qp_sweeps``: projected Gauss-Seidel sweeps on the QP dual (200).
    ``restarts``: extra starting points tried at the first sample (8) besides ``q0``.
    """

    max_iterations: int = 50
    step_tol_rad: float = 1e-9
    feasibility_tol_m: float = 1e-6
    initial_damping: float = 1e-6
    penalty: float = 1e4
    qp_sweeps: int = 200
    restarts: int = 8
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES


@dataclass
class SolveResult:
    """Per-sample solution: ``q_rad`` (N, 5), ``cost_rad2`` (N,) = f, ``iterations`` (N,),
    ``active`` (N, 3) bool: a joint limit / the elbow box / the wrist box is active (constrained only)."""

    q_rad: np.ndarray
    cost_rad2: np.ndarray
    iterations: np.ndarray
    active: np.ndarray
    constrained: bool
    extra: dict = field(default_factory=dict)

    @property
    def any_active(self) -> np.ndarray:
        return np.any(self.active, axis=1)


def constraint_arrays(limits: JointLimits, workspace: Workspace) -> tuple[np.ndarray, np.ndarray]:
    """``(lower, upper)`` (11,) arrays: 5 joint limits (rad) then elbow xyz and wrist xyz (m), +-inf = open."""
    lo_q, hi_q = limits.as_rad()
    e = workspace.elbow or WorkspaceBox()
    w = workspace.wrist or WorkspaceBox()
    lo = np.concatenate([lo_q, e.lower_m, w.lower_m]).astype(np.float64)
    hi = np.concatenate([hi_q, e.upper_m, w.upper_m]).astype(np.float64)
    return lo, hi


def _as_matrices(r: np.ndarray, what: str) -> np.ndarray:
    a = np.ascontiguousarray(r, dtype=np.float64)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[1:] != (3, 3):
        raise ValueError(f"{what} must be rotation matrices (N, 3, 3), got shape {a.shape}")
    return a


def _start_points(q0: np.ndarray, lo: np.ndarray, hi: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    lo_f = np.where(np.isfinite(lo[:5]), lo[:5], -np.pi)
    hi_f = np.where(np.isfinite(hi[:5]), hi[:5], np.pi)
    rng = np.random.default_rng(seed)
    extra = lo_f + (hi_f - lo_f) * rng.random((n, 5))
    return np.vstack([q0[None], 0.5 * (lo_f + hi_f)[None], extra])


def solve_sequence(
    r_upper_arm: np.ndarray,
    r_forearm: np.ndarray,
    model: ArmModel = DEFAULT_MODEL,
    *,
    constrained: bool = False,
    limits: JointLimits = DEFAULT_LIMITS,
    workspace: Workspace = Workspace(),
    q0_rad: np.ndarray | None = None,
    params: SolverParams = SolverParams(),
) -> SolveResult:
    """Joint angles (rad) at every sample from measured segment orientations in the trunk frame.

    ``r_upper_arm``/``r_forearm``: (N, 3, 3) segment-to-trunk rotation matrices (the R_hat of eq. 2);
    NaN samples give NaN angles and keep the warm start. ``q0_rad``: starting configuration of the
    first sample, used as given (a warm start, e.g. the previous solution when streaming). Default: the
    paper's neutral ``[0, 0, 0, 0, 0]``, the mid-range configuration and ``params.restarts`` random
    starts within the limits are tried on the first sample and the best is kept. Every later sample
    starts from the previous sample's solution.
    """
    rua = _as_matrices(r_upper_arm, "r_upper_arm")
    rfa = _as_matrices(r_forearm, "r_forearm")
    if len(rua) != len(rfa):
        raise ValueError(f"r_upper_arm has {len(rua)} samples but r_forearm {len(rfa)}")
    n = len(rua)
    lo, hi = constraint_arrays(limits, workspace)
    if not constrained:
        lo = np.full(11, -np.inf)
        hi = np.full(11, np.inf)
    packed = model.packed()
    q_start = np.zeros(N_FREE) if q0_rad is None else np.asarray(q0_rad, dtype=np.float64).reshape(N_FREE)
    out_q = np.empty((n, N_FREE))
    out_cost = np.empty(n)
    out_iter = np.empty(n, dtype=np.int64)
    out_active = np.zeros((n, 3), dtype=bool)
    args = (
        bool(constrained),
        int(params.max_iterations),
        float(params.step_tol_rad),
        float(params.initial_damping),
        float(params.penalty),
        int(params.qp_sweeps),
        float(params.feasibility_tol_m),
    )
    if n and q0_rad is None:
        finite = np.flatnonzero(np.isfinite(rua[:, 0, 0]) & np.isfinite(rfa[:, 0, 0]))
        first = int(finite[0]) if len(finite) else 0
        best, best_merit = q_start, np.inf
        for s in _start_points(q_start, lo, hi, params.restarts):
            tq, tc = np.empty((1, N_FREE)), np.empty(1)
            ti, ta = np.empty(1, dtype=np.int64), np.zeros((1, 3), dtype=bool)
            solve_packed_sequence(
                rua[first : first + 1], rfa[first : first + 1], s, packed, lo, hi, *args, tq, tc, ti, ta
            )
            viol = np.sum(np.maximum(lo[:5] - tq[0], 0) + np.maximum(tq[0] - hi[:5], 0)) if constrained else 0.0
            if tc[0] + viol < best_merit - 1e-12:
                best, best_merit = tq[0].copy(), tc[0] + viol
        q_start = best
    if n:
        solve_packed_sequence(rua, rfa, q_start, packed, lo, hi, *args, out_q, out_cost, out_iter, out_active)
    return SolveResult(out_q, out_cost, out_iter, out_active, bool(constrained))


class RealTimeSolver:
    """Streaming use: one call per incoming sample, warm-started from the previous one.

    >>> rt = RealTimeSolver(ArmModel(), constrained=True, q0_rad=np.radians([90, 30, 0, 90, 90]))
    >>> q_rad, cost_rad2, active = rt.update(r_upper_arm, r_forearm)   # (3, 3) each, trunk frame
    """

    def __init__(
        self,
        model: ArmModel = DEFAULT_MODEL,
        *,
        constrained: bool = False,
        limits: JointLimits = DEFAULT_LIMITS,
        workspace: Workspace = Workspace(),
        q0_rad: np.ndarray | None = None,
        params: SolverParams = SolverParams(),
    ) -> None:
        self._packed = model.packed()
        lo, hi = constraint_arrays(limits, workspace)
        if not constrained:
            lo, hi = np.full(11, -np.inf), np.full(11, np.inf)
        self._lo, self._hi = lo, hi
        self._args = (
            bool(constrained),
            int(params.max_iterations),
            float(params.step_tol_rad),
            float(params.initial_damping),
            float(params.penalty),
            int(params.qp_sweeps),
            float(params.feasibility_tol_m),
        )
        self.q_rad = np.zeros(N_FREE) if q0_rad is None else np.asarray(q0_rad, dtype=np.float64).reshape(N_FREE)
        self._q = np.empty((1, N_FREE))
        self._c = np.empty(1)
        self._i = np.empty(1, dtype=np.int64)
        self._a = np.zeros((1, 3), dtype=bool)

    def update(self, r_upper_arm: np.ndarray, r_forearm: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
        """Joint angles (5,) rad, cost f (rad^2) and active flags (joint limit, elbow box, wrist box)."""
        rua = np.ascontiguousarray(r_upper_arm, dtype=np.float64).reshape(1, 3, 3)
        rfa = np.ascontiguousarray(r_forearm, dtype=np.float64).reshape(1, 3, 3)
        solve_packed_sequence(
            rua, rfa, self.q_rad, self._packed, self._lo, self._hi, *self._args, self._q, self._c, self._i, self._a
        )
        if np.all(np.isfinite(self._q[0])):
            self.q_rad = self._q[0].copy()
        return self._q[0].copy(), float(self._c[0]), self._a[0].copy()


def solve_sample_scipy(
    r_upper_arm: np.ndarray,
    r_forearm: np.ndarray,
    model: ArmModel = DEFAULT_MODEL,
    *,
    constrained: bool = False,
    limits: JointLimits = DEFAULT_LIMITS,
    workspace: Workspace = Workspace(),
    q0_rad: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Reference solution of one sample with SciPy (SLSQP, the paper's SQP; numerical derivatives).

    Slow (milliseconds); used in tests and as the benchmark baseline. Returns ``(q_rad (5,), f rad^2)``.
    """
    from scipy.optimize import minimize

    from imulog.process.quaternion import angle, conjugate, from_rotation_matrix, multiply

    q_hat_ua = from_rotation_matrix(np.asarray(r_upper_arm))
    q_hat_fa = from_rotation_matrix(np.asarray(r_forearm))

    def cost(q: np.ndarray) -> float:
        fk = forward_kinematics(q, model)
        g1 = angle(multiply(from_rotation_matrix(fk.r_upper_arm), conjugate(q_hat_ua)))
        g2 = angle(multiply(from_rotation_matrix(fk.r_forearm), conjugate(q_hat_fa)))
        return float(g1**2 + g2**2)

    x0 = np.zeros(N_FREE) if q0_rad is None else np.asarray(q0_rad, dtype=np.float64)
    if not constrained:
        res = minimize(cost, x0, method="BFGS", options={"gtol": 1e-10})
        return res.x, float(res.fun)
    lo, hi = limits.as_rad()
    lo_all, hi_all = constraint_arrays(limits, workspace)

    def box(q: np.ndarray) -> np.ndarray:
        fk = forward_kinematics(q, model)
        p = np.concatenate([fk.elbow_m, fk.wrist_m])
        parts = []
        for k in range(6):
            if np.isfinite(lo_all[5 + k]):
                parts.append(p[k] - lo_all[5 + k])
            if np.isfinite(hi_all[5 + k]):
                parts.append(hi_all[5 + k] - p[k])
        return np.asarray(parts) if parts else np.zeros(1)

    res = minimize(
        cost,
        np.clip(x0, lo, hi),
        method="SLSQP",
        bounds=list(zip(lo, hi, strict=True)),
        constraints=[{"type": "ineq", "fun": box}],
        options={"ftol": 1e-12, "maxiter": 500},
    )
    return res.x, float(res.fun)
