"""The 5-variable QP of each iteration of the joint-angle solver (:mod:`.solver_core`), compiled with numba.

``min 1/2 d'Hd + g'd  s.t.  A d <= b`` with H 5x5 SPD (the damped Gauss-Newton matrix) and up to 22 linearised
constraints, solved through its dual (projected Gauss-Seidel, then an exact solve on the active set). The small
systems are solved by an inline LU with partial pivoting (:func:`_lu_factor`, :func:`_lu_solve`) in scratch
arrays allocated once per sequence (:func:`_qp_work`): no LAPACK call and no allocation per iteration.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _lu_factor(a, n, lu, piv):
    """LU factorisation with partial pivoting of ``a[:n, :n]`` into ``lu``/``piv`` (n <= 5, no allocation);
    returns the determinant (0.0 when a pivot is exactly zero)."""
    for i in range(n):
        for j in range(n):
            lu[i, j] = a[i, j]
    det = 1.0
    for k in range(n):
        p = k
        big = abs(lu[k, k])
        for i in range(k + 1, n):
            if abs(lu[i, k]) > big:
                big = abs(lu[i, k])
                p = i
        piv[k] = p
        if p != k:
            det = -det
            for j in range(n):
                lu[k, j], lu[p, j] = lu[p, j], lu[k, j]
        pk = lu[k, k]
        det *= pk
        if pk == 0.0:
            return 0.0
        for i in range(k + 1, n):
            f = lu[i, k] / pk
            lu[i, k] = f
            for j in range(k + 1, n):
                lu[i, j] -= f * lu[k, j]
    return det


@numba.njit(cache=True)
def _lu_solve(lu, piv, n, x):
    """Solve in place ``A x = x`` with the factors of :func:`_lu_factor`."""
    for k in range(n):
        p = piv[k]
        if p != k:
            x[k], x[p] = x[p], x[k]
    for i in range(1, n):
        s = x[i]
        for j in range(i):
            s -= lu[i, j] * x[j]
        x[i] = s
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, n):
            s -= lu[i, j] * x[j]
        x[i] = s / lu[i, i]


@numba.njit(cache=True)
def _qp_work():
    """Scratch arrays of :func:`_solve_qp` (allocated once per sequence, not per call)."""
    return (
        np.empty((5, 5)),  # LU of H
        np.empty(5, dtype=np.int64),  # its pivots
        np.empty((5, 22)),  # H^-1 A^T
        np.empty((22, 22)),  # A H^-1 A^T
        np.empty(22),  # slack at lambda = 0
        np.empty(22),  # trial multipliers
        np.empty(22, dtype=np.int64),  # active rows
        np.empty((5, 5)),  # active block of the dual
        np.empty((5, 5)),  # its LU
        np.empty(5, dtype=np.int64),  # its pivots
        np.empty(5),  # its right-hand side, then multipliers
        np.empty(5),  # unconstrained step
    )


@numba.njit(cache=True)
def _on_active_set(qm, c, m, idx, na, lam, trial, qa, lua, piva, ca):
    """Multipliers of the dual ``min 1/2 l'Q l + c'l, l >= 0`` with the rows ``idx[:na]`` active, solved exactly;
    written to ``lam`` and True when they are >= 0 and leave every slack >= 0 (the optimum), else False."""
    if na == 0 or na > 5:
        return False
    for u in range(na):
        ca[u] = -c[idx[u]]
        for v in range(na):
            qa[u, v] = qm[idx[u], idx[v]]
    if abs(_lu_factor(qa, na, lua, piva)) <= 1e-18:
        return False
    _lu_solve(lua, piva, na, ca)
    for u in range(na):
        if ca[u] < 0.0:
            return False
    for i in range(m):
        trial[i] = 0.0
    for u in range(na):
        trial[idx[u]] = ca[u]
    for i in range(m):
        s = c[i]
        for k in range(m):
            s += qm[i, k] * trial[k]
        if s < -1e-12:
            return False
    for i in range(m):
        lam[i] = trial[i]
    return True


@numba.njit(cache=True)
def _solve_qp(h, g, a, b, m, sweeps, delta, lam, work):
    """min 1/2 d'Hd + g'd  s.t.  a[:m] d <= b[:m]  (H 5x5 SPD). Writes ``delta``; returns #active."""
    lu, piv, hat, qm, c, trial, idx, qa, lua, piva, ca, d0 = work
    if _lu_factor(h, 5, lu, piv) == 0.0:
        raise ValueError("singular 5x5 system in the joint-angle QP")
    for j in range(5):
        d0[j] = -g[j]
    _lu_solve(lu, piv, 5, d0)
    for j in range(5):
        delta[j] = d0[j]
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
    col = ca  # (5,) scratch for one column of H^-1 A^T
    for i in range(m):
        for j in range(5):
            col[j] = a[i, j]
        _lu_solve(lu, piv, 5, col)
        for j in range(5):
            hat[j, i] = col[j]
    for i in range(m):
        for k in range(m):
            s = 0.0
            for j in range(5):
                s += a[i, j] * hat[j, k]
            qm[i, k] = s
    for i in range(m):  # slack at lambda = 0
        s = 0.0
        for j in range(5):
            s += a[i, j] * d0[j]
        c[i] = b[i] - s
        lam[i] = 0.0
    # the rows the unconstrained step violates are usually the active set: the exact solve on them is the
    # optimum when its multipliers are >= 0 and it violates no other row (KKT); else projected Gauss-Seidel
    na = 0
    for i in range(m):
        if c[i] < -1e-12:
            idx[na] = i
            na += 1
    if not _on_active_set(qm, c, m, idx, na, lam, trial, qa, lua, piva, ca):
        for _sweep in range(sweeps):
            change = 0.0
            for i in range(m):
                if qm[i, i] <= 1e-14:
                    continue
                s = c[i]
                for k in range(m):
                    s += qm[i, k] * lam[k]
                new = lam[i] - s / qm[i, i]
                if new < 0.0:
                    new = 0.0
                dl = abs(new - lam[i]) * qm[i, i]
                if dl > change:
                    change = dl
                lam[i] = new
            if change < 1e-15:
                break
        # polish: exact solve on the active set when it is consistent
        na = 0
        for i in range(m):
            if lam[i] > 0.0:
                idx[na] = i
                na += 1
        _on_active_set(qm, c, m, idx, na, lam, trial, qa, lua, piva, ca)
    for j in range(5):
        s = 0.0
        for i in range(m):
            s += hat[j, i] * lam[i]
        delta[j] = d0[j] - s
    return na
