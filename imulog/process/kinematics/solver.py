"""Per-sample joint angles from two segment orientations: unconstrained and constrained (Caruso 2024).

At every sample the five free joint angles ``q`` minimise (eq. 4)

    f(q) = gamma_UA^2 + gamma_FA^2,   gamma_S = angle(R_S(q) R_S_hat^T)   (eqs. 2-3, rad^2)

optionally subject to the joint limits g1 (eq. 6) and to the elbow and wrist centres lying inside
axis-aligned workspace boxes g2 (eq. 7), starting from the previous sample's solution (warm start).

The paper solves this with MATLAB's SQP (6.9 / 11.3 ms per sample). Here the same problem is solved
by a Levenberg-Marquardt / SQP iteration compiled with numba: the residual is the stacked rotation
vectors ``r = [log(R_UA(q) R_UA_hat^T), log(R_FA(q) R_FA_hat^T)]`` (so ``|r|^2 = f`` exactly),
with the analytic joint-axis Jacobian (its ``J^T r`` is the exact gradient of ``f / 2``). With
constraints, every iteration solves the linearised problem, a 5-variable QP with up to 22 linear
inequalities, through its dual (projected Gauss-Seidel, then an exact solve on the active set); an
L1 merit function accepts or rejects steps. Joint limits are met exactly (the last iterate is clipped
to them), workspace boxes to ``feasibility_tol_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from imulog.process.kinematics.dh import N_FREE, ArmModel, JointLimits, _fk_kernel, _jac_kernel, forward_kinematics

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


# --------------------------------------------------------------------------------------------
# numba core


@numba.njit(cache=True)
def _log_rel(r_model, r_hat, out, o):
    """``out[o:o+3] = log(r_model @ r_hat.T)`` (rotation vector, rad)."""
    m00 = r_model[0, 0] * r_hat[0, 0] + r_model[0, 1] * r_hat[0, 1] + r_model[0, 2] * r_hat[0, 2]
    m01 = r_model[0, 0] * r_hat[1, 0] + r_model[0, 1] * r_hat[1, 1] + r_model[0, 2] * r_hat[1, 2]
    m02 = r_model[0, 0] * r_hat[2, 0] + r_model[0, 1] * r_hat[2, 1] + r_model[0, 2] * r_hat[2, 2]
    m10 = r_model[1, 0] * r_hat[0, 0] + r_model[1, 1] * r_hat[0, 1] + r_model[1, 2] * r_hat[0, 2]
    m11 = r_model[1, 0] * r_hat[1, 0] + r_model[1, 1] * r_hat[1, 1] + r_model[1, 2] * r_hat[1, 2]
    m12 = r_model[1, 0] * r_hat[2, 0] + r_model[1, 1] * r_hat[2, 1] + r_model[1, 2] * r_hat[2, 2]
    m20 = r_model[2, 0] * r_hat[0, 0] + r_model[2, 1] * r_hat[0, 1] + r_model[2, 2] * r_hat[0, 2]
    m21 = r_model[2, 0] * r_hat[1, 0] + r_model[2, 1] * r_hat[1, 1] + r_model[2, 2] * r_hat[1, 2]
    m22 = r_model[2, 0] * r_hat[2, 0] + r_model[2, 1] * r_hat[2, 1] + r_model[2, 2] * r_hat[2, 2]
    tr = m00 + m11 + m22
    # Shepperd: quaternion with w >= 0
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        w = 0.25 * s
        x = (m21 - m12) / s
        y = (m02 - m20) / s
        z = (m10 - m01) / s
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        w = (m21 - m12) / s
        x = 0.25 * s
        y = (m01 + m10) / s
        z = (m02 + m20) / s
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        w = (m02 - m20) / s
        x = (m01 + m10) / s
        y = 0.25 * s
        z = (m12 + m21) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        w = (m10 - m01) / s
        x = (m02 + m20) / s
        y = (m12 + m21) / s
        z = 0.25 * s
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    vn = math.sqrt(x * x + y * y + z * z)
    k = 2.0 if vn < 1e-12 else 2.0 * math.atan2(vn, w) / vn
    out[o] = x * k
    out[o + 1] = y * k
    out[o + 2] = z * k


@numba.njit(cache=True)
def _evaluate(q, model, rua_hat, rfa_hat, lo, hi, frames_r, frames_p, r):
    """Cost f (rad^2) and L1 constraint violation (rad + m) at ``q``; fills frames and residual ``r``."""
    _fk_kernel(q, model, frames_r, frames_p)
    _log_rel(frames_r[3], rua_hat, r, 0)
    _log_rel(frames_r[6], rfa_hat, r, 3)
    f = 0.0
    for i in range(6):
        f += r[i] * r[i]
    v = 0.0
    for c in range(5):
        if q[c] < lo[c]:
            v += lo[c] - q[c]
        elif q[c] > hi[c]:
            v += q[c] - hi[c]
    for i in range(3):
        pe = frames_p[3, i]
        pw = frames_p[6, i]
        if pe < lo[5 + i]:
            v += lo[5 + i] - pe
        elif pe > hi[5 + i]:
            v += pe - hi[5 + i]
        if pw < lo[8 + i]:
            v += lo[8 + i] - pw
        elif pw > hi[8 + i]:
            v += pw - hi[8 + i]
    return f, v


@numba.njit(cache=True)
def _solve_qp(h, g, a, b, m, sweeps, delta, lam):
    """min 1/2 d'Hd + g'd  s.t.  a[:m] d <= b[:m]  (H 5x5 SPD). Writes ``delta``; returns #active."""
    hinv_g = np.linalg.solve(h, g)
    for j in range(5):
        delta[j] = -hinv_g[j]
    if m == 0:
        return 0
    worst = 0.0
    for i in range(m):
        s = b[i]
        for j in range(5):
            s -= a[i, j] * delta[j]
        if s < worst:
            worst = s
    if worst >= -1e-12:
        return 0
    am = a[:m]
    hinv_at = np.linalg.solve(h, am.T.copy())  # (5, m)
    q = am @ hinv_at  # (m, m)
    d0 = delta.copy()
    c = b[:m] - am @ d0  # slack at lambda = 0
    for i in range(m):
        lam[i] = 0.0
    for _sweep in range(sweeps):
        change = 0.0
        for i in range(m):
            if q[i, i] <= 1e-14:
                continue
            s = c[i]
            for k in range(m):
                s += q[i, k] * lam[k]
            new = lam[i] - s / q[i, i]
            if new < 0.0:
                new = 0.0
            dl = abs(new - lam[i]) * q[i, i]
            if dl > change:
                change = dl
            lam[i] = new
        if change < 1e-15:
            break
    # polish: exact solve on the active set when it is consistent
    idx = np.empty(m, dtype=np.int64)
    na = 0
    for i in range(m):
        if lam[i] > 0.0:
            idx[na] = i
            na += 1
    if 0 < na <= 5:
        qa = np.empty((na, na))
        ca = np.empty(na)
        for u in range(na):
            ca[u] = -c[idx[u]]
            for v in range(na):
                qa[u, v] = q[idx[u], idx[v]]
        if abs(np.linalg.det(qa)) > 1e-18:
            la = np.linalg.solve(qa, ca)
            ok = True
            for u in range(na):
                if la[u] < 0.0:
                    ok = False
            if ok:
                trial = np.zeros(m)
                for u in range(na):
                    trial[idx[u]] = la[u]
                slack = c + q @ trial
                for i in range(m):
                    if slack[i] < -1e-12:
                        ok = False
                if ok:
                    for i in range(m):
                        lam[i] = trial[i]
    for j in range(5):
        s = 0.0
        for i in range(m):
            s += hinv_at[j, i] * lam[i]
        delta[j] = d0[j] - s
    return na


@numba.njit(cache=True)
def _build_constraints(q, lo, hi, frames_p, jp_el, jp_wr, a, b):
    """Linearised constraints ``a[:m] d <= b[:m]`` at ``q`` (frames and Jacobians already at ``q``)."""
    m = 0
    for c in range(5):
        if hi[c] < np.inf:
            for j in range(5):
                a[m, j] = 0.0
            a[m, c] = 1.0
            b[m] = hi[c] - q[c]
            m += 1
        if lo[c] > -np.inf:
            for j in range(5):
                a[m, j] = 0.0
            a[m, c] = -1.0
            b[m] = q[c] - lo[c]
            m += 1
    for i in range(3):
        if hi[5 + i] < np.inf:
            for j in range(5):
                a[m, j] = jp_el[i, j]
            b[m] = hi[5 + i] - frames_p[3, i]
            m += 1
        if lo[5 + i] > -np.inf:
            for j in range(5):
                a[m, j] = -jp_el[i, j]
            b[m] = frames_p[3, i] - lo[5 + i]
            m += 1
        if hi[8 + i] < np.inf:
            for j in range(5):
                a[m, j] = jp_wr[i, j]
            b[m] = hi[8 + i] - frames_p[6, i]
            m += 1
        if lo[8 + i] > -np.inf:
            for j in range(5):
                a[m, j] = -jp_wr[i, j]
            b[m] = frames_p[6, i] - lo[8 + i]
            m += 1
    return m


@numba.njit(cache=True)
def _box_violation(frames_p, lo, hi):
    """Largest distance (m) of the elbow or wrist centre outside its box."""
    worst = 0.0
    for i in range(3):
        for o, k in ((3, 5), (6, 8)):
            p = frames_p[o, i]
            if lo[k + i] - p > worst:
                worst = lo[k + i] - p
            if p - hi[k + i] > worst:
                worst = p - hi[k + i]
    return worst


@numba.njit(cache=True)
def _solve_one(
    q,
    model,
    rua_hat,
    rfa_hat,
    lo,
    hi,
    constrained,
    max_iter,
    step_tol,
    damping0,
    penalty,
    sweeps,
    feas_tol,
    work_r,
    work_p,
    r,
    jw_ua,
    jw_fa,
    jp_el,
    jp_wr,
    a,
    b,
    lam,
    active,
):
    """Refine ``q`` (in place) for one sample; returns (cost, iterations)."""
    f, v = _evaluate(q, model, rua_hat, rfa_hat, lo, hi, work_r, work_p, r)
    if not constrained:
        v = 0.0
    merit = f + penalty * v
    mu = damping0
    h = np.empty((5, 5))
    g = np.empty(5)
    delta = np.empty(5)
    q_new = np.empty(5)
    r_new = np.empty(6)
    jw2_ua = np.empty((3, 5))
    jw2_fa = np.empty((3, 5))
    jp2_el = np.empty((3, 5))
    jp2_wr = np.empty((3, 5))
    a2 = np.zeros((22, 5))
    b2 = np.zeros(22)
    lam2 = np.zeros(22)
    d2 = np.empty(5)
    q_soc = np.empty(5)
    eye = np.eye(5)
    zero5 = np.zeros(5)
    it = 0
    for _k in range(max_iter):
        it += 1
        # frames hold the current q (re-evaluate after a rejected step is unnecessary: q unchanged)
        _fk_kernel(q, model, work_r, work_p)
        _log_rel(work_r[3], rua_hat, r, 0)
        _log_rel(work_r[6], rfa_hat, r, 3)
        _jac_kernel(work_r, work_p, jw_ua, jw_fa, jp_el, jp_wr)
        for i in range(5):
            gi = 0.0
            for k in range(3):
                gi += jw_ua[k, i] * r[k] + jw_fa[k, i] * r[3 + k]
            g[i] = gi
            for j in range(5):
                s = 0.0
                for k in range(3):
                    s += jw_ua[k, i] * jw_ua[k, j] + jw_fa[k, i] * jw_fa[k, j]
                h[i, j] = s
        m = _build_constraints(q, lo, hi, work_p, jp_el, jp_wr, a, b) if constrained else 0
        accepted = False
        for _try in range(12):
            for i in range(5):
                h[i, i] += mu
            _solve_qp(h, g, a, b, m, sweeps, delta, lam)
            for i in range(5):
                h[i, i] -= mu
            for i in range(5):
                q_new[i] = q[i] + delta[i]
            f_new, v_new = _evaluate(q_new, model, rua_hat, rfa_hat, lo, hi, work_r, work_p, r_new)
            if not constrained:
                v_new = 0.0
            merit_new = f_new + penalty * v_new
            if merit_new <= merit + 1e-15:
                accepted = True
                break
            if constrained and v_new > 0.0:
                # second-order correction (Maratos effect): min-norm step back onto the constraints
                # linearised at q_new, then re-test the merit
                _jac_kernel(work_r, work_p, jw2_ua, jw2_fa, jp2_el, jp2_wr)
                m2 = _build_constraints(q_new, lo, hi, work_p, jp2_el, jp2_wr, a2, b2)
                _solve_qp(eye, zero5, a2, b2, m2, sweeps, d2, lam2)
                for i in range(5):
                    q_soc[i] = q_new[i] + d2[i]
                f_soc, v_soc = _evaluate(q_soc, model, rua_hat, rfa_hat, lo, hi, work_r, work_p, r_new)
                merit_soc = f_soc + penalty * v_soc
                if merit_soc <= merit + 1e-15:
                    for i in range(5):
                        q_new[i] = q_soc[i]
                        delta[i] = q_soc[i] - q[i]
                    f_new = f_soc
                    v_new = v_soc
                    merit_new = merit_soc
                    accepted = True
                    break
            mu = mu * 10.0 + 1e-9
        step = 0.0
        for i in range(5):
            if abs(delta[i]) > step:
                step = abs(delta[i])
        if not accepted:
            break
        for i in range(5):
            q[i] = q_new[i]
        merit = merit_new
        f = f_new
        v = v_new
        mu = max(mu / 3.0, 1e-12)
        if step < step_tol:
            break
    if constrained:
        for c in range(5):
            if q[c] < lo[c]:
                q[c] = lo[c]
            elif q[c] > hi[c]:
                q[c] = hi[c]
        f, v = _evaluate(q, model, rua_hat, rfa_hat, lo, hi, work_r, work_p, r)
        # feasibility restoration: min-norm steps onto the linearised boxes until within feas_tol
        for _fix in range(20):
            if _box_violation(work_p, lo, hi) <= feas_tol:
                break
            _jac_kernel(work_r, work_p, jw2_ua, jw2_fa, jp2_el, jp2_wr)
            m2 = _build_constraints(q, lo, hi, work_p, jp2_el, jp2_wr, a2, b2)
            _solve_qp(eye, zero5, a2, b2, m2, sweeps, d2, lam2)
            for c in range(5):
                q[c] = min(max(q[c] + d2[c], lo[c]), hi[c])
            f, v = _evaluate(q, model, rua_hat, rfa_hat, lo, hi, work_r, work_p, r)
        tol_q = 1e-9
        tol_p = max(feas_tol, 1e-9)
        active[0] = False
        active[1] = False
        active[2] = False
        for c in range(5):
            if q[c] <= lo[c] + tol_q or q[c] >= hi[c] - tol_q:
                active[0] = True
        for i in range(3):
            if work_p[3, i] <= lo[5 + i] + tol_p or work_p[3, i] >= hi[5 + i] - tol_p:
                active[1] = True
            if work_p[6, i] <= lo[8 + i] + tol_p or work_p[6, i] >= hi[8 + i] - tol_p:
                active[2] = True
    return f, it


@numba.njit(cache=True)
def _solve_sequence(
    rua_hat,
    rfa_hat,
    q0,
    model,
    lo,
    hi,
    constrained,
    max_iter,
    step_tol,
    damping0,
    penalty,
    sweeps,
    feas_tol,
    out_q,
    out_cost,
    out_iter,
    out_active,
):
    n = rua_hat.shape[0]
    work_r = np.empty((7, 3, 3))
    work_p = np.empty((7, 3))
    r = np.empty(6)
    jw_ua = np.empty((3, 5))
    jw_fa = np.empty((3, 5))
    jp_el = np.empty((3, 5))
    jp_wr = np.empty((3, 5))
    a = np.zeros((22, 5))
    b = np.zeros(22)
    lam = np.zeros(22)
    active = np.zeros(3, dtype=np.bool_)
    q = q0.copy()
    for k in range(n):
        if not np.isfinite(rua_hat[k, 0, 0]) or not np.isfinite(rfa_hat[k, 0, 0]):
            for i in range(5):
                out_q[k, i] = np.nan
            out_cost[k] = np.nan
            out_iter[k] = 0
            for i in range(3):
                out_active[k, i] = False
            continue
        f, it = _solve_one(
            q,
            model,
            rua_hat[k],
            rfa_hat[k],
            lo,
            hi,
            constrained,
            max_iter,
            step_tol,
            damping0,
            penalty,
            sweeps,
            feas_tol,
            work_r,
            work_p,
            r,
            jw_ua,
            jw_fa,
            jp_el,
            jp_wr,
            a,
            b,
            lam,
            active,
        )
        for i in range(5):
            out_q[k, i] = q[i]
        out_cost[k] = f
        out_iter[k] = it
        for i in range(3):
            out_active[k, i] = active[i]


# --------------------------------------------------------------------------------------------
# public API


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
            _solve_sequence(rua[first : first + 1], rfa[first : first + 1], s, packed, lo, hi, *args, tq, tc, ti, ta)
            viol = np.sum(np.maximum(lo[:5] - tq[0], 0) + np.maximum(tq[0] - hi[:5], 0)) if constrained else 0.0
            if tc[0] + viol < best_merit - 1e-12:
                best, best_merit = tq[0].copy(), tc[0] + viol
        q_start = best
    if n:
        _solve_sequence(rua, rfa, q_start, packed, lo, hi, *args, out_q, out_cost, out_iter, out_active)
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
        _solve_sequence(
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
