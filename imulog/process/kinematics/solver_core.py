"""The compiled core of the constrained joint-angle solver (Caruso 2024), see :mod:`.solver`.

Damped Newton / SQP iterations in numba: the stacked rotation-vector residual of both segments, its analytic
Jacobian and the exact Hessian of the cost (:func:`_newton_matrix`; Gauss-Newton's ``J'J`` where that is not
positive definite), the workspace-box constraints linearised for the 5-variable QP (:mod:`.solver_qp`), and
:func:`solve_packed_sequence`, the warm-started loop over samples. Every scratch array is allocated once per
sequence (:func:`_sample_work`), none per sample. Angles in rad, positions in m.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from imulog.process.kinematics.dh import _fk_kernel, _jac_kernel
from imulog.process.kinematics.solver_qp import _qp_work, _solve_qp


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
def _newton_matrix(r, jw_ua, jw_fa, h, ll):
    """Exact Hessian of ``f / 2`` (rad^2 / rad^2) into ``h`` (5x5) from the residual ``r`` (6,) and the joint axes
    ``jw_ua``/``jw_fa`` (3, 5); ``ll`` scratch for its Cholesky factor. True when it is positive definite (use it:
    Newton's step), False when it is not or a residual angle is near pi (use Gauss-Newton's ``J'J`` instead).

    ``H_jk = sum_s w_sk' Jl^-T(r_s) w_sj + [k < j] r_s . (z_k x z_j)``: the change of ``J'r`` with ``q_k`` through
    the residual (``dr_s/dq_k = Jl^-1(r_s) w_sk``) and through axis j turning with joint k (``dz_j/dq_k = z_k x
    z_j``); checked against finite differences of ``J'r`` in the tests."""
    for i in range(5):
        for j in range(5):
            h[i, j] = 0.0
    for seg in range(2):
        o = 3 * seg
        w = jw_ua if seg == 0 else jw_fa
        n_j = 3 if seg == 0 else 5
        rx, ry, rz = r[o], r[o + 1], r[o + 2]
        th2 = rx * rx + ry * ry + rz * rz
        th = math.sqrt(th2)
        if th > 3.0:
            return False
        # Jl^-T(r) = I + [r]x / 2 + c [r]x^2 (SO(3) left Jacobian, inverse transposed); c -> 1/12 at r -> 0
        c = 1.0 / 12.0 if th < 1e-4 else 1.0 / th2 - (1.0 + math.cos(th)) / (2.0 * th * math.sin(th))
        for j in range(n_j):
            wj0, wj1, wj2 = w[0, j], w[1, j], w[2, j]
            rwj = rx * wj0 + ry * wj1 + rz * wj2
            # r x w_j
            cx = ry * wj2 - rz * wj1
            cy = rz * wj0 - rx * wj2
            cz = rx * wj1 - ry * wj0
            for k in range(j + 1):
                wk0, wk1, wk2 = w[0, k], w[1, k], w[2, k]
                dot = wk0 * wj0 + wk1 * wj1 + wk2 * wj2
                rwk = rx * wk0 + ry * wk1 + rz * wk2
                val = dot + c * (rwk * rwj - th2 * dot)
                if k < j:
                    # Jl^-T's skew part, w_k . (r x w_j) / 2, plus the turning of axis j with joint k,
                    # r . (w_k x w_j) = -w_k . (r x w_j): together -w_k . (r x w_j) / 2
                    val -= 0.5 * (wk0 * cx + wk1 * cy + wk2 * cz)
                h[j, k] += val
    for j in range(5):
        for k in range(j):
            h[k, j] = h[j, k]
    # positive definite? (Cholesky without storing)
    for j in range(5):
        s = h[j, j]
        for k in range(j):
            s -= ll[j, k] * ll[j, k]
        if s <= 1e-12:
            return False
        ll[j, j] = math.sqrt(s)
        for i in range(j + 1, 5):
            t = h[i, j]
            for k in range(j):
                t -= ll[i, k] * ll[j, k]
            ll[i, j] = t / ll[j, j]
    return True


@numba.njit(cache=True)
def _sample_work():
    """Scratch arrays of :func:`_solve_one` (allocated once per sequence, not per sample)."""
    return (
        np.empty((7, 3, 3)),  # frames' rotations
        np.empty((7, 3)),  # frames' origins
        np.empty(6),  # residual at q
        np.empty(6),  # residual at a trial point
        np.empty((4, 3, 5)),  # Jacobians at q: UA, FA orientation; elbow, wrist position
        np.empty((4, 3, 5)),  # Jacobians at a trial point
        np.zeros((22, 5)),  # linearised constraints at q
        np.zeros(22),
        np.zeros(22),  # their multipliers
        np.zeros((22, 5)),  # linearised constraints at a trial point
        np.zeros(22),
        np.zeros(22),
        np.empty((5, 5)),  # J'J
        np.empty(5),  # J'r
        np.empty(5),  # step
        np.empty(5),  # trial point
        np.empty(5),  # restoration step
        np.empty(5),  # second-order-corrected point
        np.eye(5),
        np.zeros(5),
        _qp_work(),
        np.empty((5, 5)),  # exact Hessian
        np.empty((5, 5)),  # its Cholesky factor
    )


@numba.njit(cache=True)
def _solve_one(
    q, model, rua_hat, rfa_hat, lo, hi, constrained, max_iter, step_tol, damping0, penalty, sweeps, feas_tol, ws, active
):
    """Refine ``q`` (in place) for one sample; returns (cost, iterations). ``ws``: :func:`_sample_work`."""
    (
        work_r,
        work_p,
        r,
        r_new,
        jac,
        jac2,
        a,
        b,
        lam,
        a2,
        b2,
        lam2,
        h,
        g,
        delta,
        q_new,
        d2,
        q_soc,
        eye,
        zero5,
        qp,
        hn,
        ll,
    ) = ws
    jw_ua, jw_fa, jp_el, jp_wr = jac[0], jac[1], jac[2], jac[3]
    jw2_ua, jw2_fa, jp2_el, jp2_wr = jac2[0], jac2[1], jac2[2], jac2[3]
    f, v = _evaluate(q, model, rua_hat, rfa_hat, lo, hi, work_r, work_p, r)
    if not constrained:
        v = 0.0
    merit = f + penalty * v
    mu = damping0
    it = 0
    for _k in range(max_iter):
        it += 1
        # the frames and the residual hold the current q: from the evaluation above, or of the accepted step
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
        if _newton_matrix(r, jw_ua, jw_fa, hn, ll):  # Newton where the Hessian is positive definite, else GN
            for i in range(5):
                for j in range(5):
                    h[i, j] = hn[i, j]
        m = _build_constraints(q, lo, hi, work_p, jp_el, jp_wr, a, b) if constrained else 0
        accepted = False
        for _try in range(12):
            for i in range(5):
                h[i, i] += mu
            _solve_qp(h, g, a, b, m, sweeps, delta, lam, qp)
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
                _solve_qp(eye, zero5, a2, b2, m2, sweeps, d2, lam2, qp)
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
        for i in range(6):
            r[i] = r_new[i]
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
            _solve_qp(eye, zero5, a2, b2, m2, sweeps, d2, lam2, qp)
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
def solve_packed_sequence(
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
    """Every sample of ``rua_hat``/``rfa_hat`` (N, 3, 3), each warm-started from the previous solution (``q0`` for
    the first); non-finite samples give NaN and keep the warm start. Writes the ``out_*`` arrays."""
    n = rua_hat.shape[0]
    ws = _sample_work()
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
            ws,
            active,
        )
        for i in range(5):
            out_q[k, i] = q[i]
        out_cost[k] = f
        out_iter[k] = it
        for i in range(3):
            out_active[k, i] = active[i]
