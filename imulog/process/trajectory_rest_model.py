"""Each repetition's own rest positions from the IMU, with their uncertainty (issue 31 point 2).

The trial-wide reference puts every repetition's bottle and mouth at the same place relative to its start, while
the hand's grasp, mouth and home scatter by about a centimetre per repetition. Each movement between two rests is
short (about 1 s), so the start's rest-to-rest displacement (ZUPT between zero-velocity rests) has a small error of
its own, far smaller than a trial-long drift. :func:`repetition_rests` chains those displacements through every
repetition (home -> bottle -> mouth -> bottle -> home, one repetition's end being the next one's start) and
combines them with the trial-wide reference as a linear Gaussian model per axis: the rests in the room scatter
about the reference's places by ``tau`` (the hand's own scatter), each displacement is off by ``sigma`` plus one
bias per movement type; both variance components are estimated from the trial by restricted maximum likelihood, so
a repetition's rests move from the reference only as far as the evidence says. :class:`RestRule` and
:func:`repetition_references` turn the estimate into each repetition's reference for the optimisation
(``OptimizationParams.rest_model``, an option: docs/accuracy.md, the seventh round of issue 31 point 2). Positions
in m, relative to the trial's home (the first start).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.stats import chi2

from imulog.process.integration import shrinkage_weight
from imulog.process.minjerk import R2GWaypoints
from imulog.process.trajectory_optimize import OptimizationParams
from imulog.process.trajectory_repetitions import Repetition
from imulog.process.trajectory_rests import rest_positions, window_links

# the grid (m) the two standard deviations are searched on, log-spaced: 1 mm to 10 cm
_GRID_M = np.geomspace(0.001, 0.10, 41)


@dataclass
class RestEstimate:
    """Every complete repetition's five rests (start, bottle, mouth, bottle, end) in the room (K, 5, 3) m relative to
    the trial's home, their posterior standard deviations relative to the repetition's start (K, 5, 3) m, the
    repetitions' list positions (K,), per axis the displacement error ``sigma_m`` and the rests' scatter ``tau_m``
    (3,) m the data gave, and the bias per movement type (reach, lift, return of the bottle, return of the hand) and
    axis ``bias_m`` (4, 3) m taken off the displacements."""

    rests_m: np.ndarray
    sd_m: np.ndarray
    index: np.ndarray
    sigma_m: np.ndarray
    tau_m: np.ndarray
    bias_m: np.ndarray

    def waypoints(self, k: int, end_axes: Sequence[bool] = (True, True, True)):
        """The ``k``-th complete repetition's bottle, mouth, bottle put back and end (3,) m each, relative to its own
        start; the end only on ``end_axes`` (0, the start, elsewhere)."""
        r = self.rests_m[k] - self.rests_m[k, 0]
        return r[1], r[2], r[3], np.where(np.asarray(end_axes, dtype=bool), r[4], 0.0)


@dataclass(frozen=True)
class RestRule:
    """How ``OptimizationParams.rest_model`` uses the estimate, parsed from its name
    ``TRUST[-xy][-test][-nobias][-gated][-ramp]``.

    trust: the reference's static trust per repetition and what the start keeps: ``waypoints`` (only the waypoints;
        ``sigma_ref_static_m`` as configured), ``replace`` (the waypoints, no static-position term for the start),
        ``posterior`` (the estimate's posterior standard deviation, at least 3 mm, no static-position term for the
        start), ``posterior-data`` (the same, the start's term kept), ``capped`` (the posterior standard deviation
        between 6 mm, the start's trust floor, and ``sigma_ref_static_m``), ``capped-tau`` (the same, with the rests'
        scatter ``tau`` at most ``sigma_ref_static_m``), ``trusted`` (``capped-tau``, and each displacement's error
        at least the start's own static trust over sqrt 2: a rest two movements on is no better known than the
        start's rests), ``trusted-posterior`` (``trusted`` with the posterior trust down to 1 mm and no
        static-position term for the start).
    axes: where the estimate is used (``-xy``: x and y; z keeps the trial-wide reference and trust).
    bias: per-movement bias terms (``-nobias``: none).
    alpha: ``-test``: the bias terms only where they differ from 0 at the 0.1 % level (as the trial's heading drift).
    gated: ``-gated``: on an axis only where the estimate's posterior standard deviation (RMS over the trial's
        rests) is below the start's own static trust there (the estimate then knows the rests better than the start
        alone does).
    ramp: ``-ramp``: the displacements from the start with each movement's offset taken off as a ramp between its
        two rests (:func:`imulog.process.integration.rest_ramp`, on the rule's axes; the eighth round), the start
        itself unchanged.
    """

    trust: str
    axes: tuple[bool, bool, bool] = (True, True, True)
    bias: bool = True
    alpha: float | None = None
    gated: bool = False
    ramp: bool = False

    TRUSTS = ("waypoints", "replace", "posterior", "posterior-data", "capped", "capped-tau", "trusted")

    @classmethod
    def parse(cls, name: str) -> RestRule:
        """The rule named ``name`` (ValueError for an unknown one)."""
        rest, kw = name, {}
        for suffix, key, value in (
            ("-ramp", "ramp", True),
            ("-gated", "gated", True),
            ("-nobias", "bias", False),
            ("-test", "alpha", 0.001),
            ("-xy", "axes", (True, True, False)),
        ):
            if rest.endswith(suffix):
                rest, kw[key] = rest.removesuffix(suffix), value
        if rest not in (*cls.TRUSTS, "trusted-posterior"):
            raise ValueError(
                f"unknown rest_model {name!r}: TRUST[-xy][-test][-nobias][-gated][-ramp], TRUST one of {cls.TRUSTS}"
            )
        return cls(trust=rest, **kw)


def repetition_references(
    t_s: np.ndarray,
    initial_m: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    rep_waypoints: Sequence[R2GWaypoints],
    waypoints: R2GWaypoints,
    params: OptimizationParams,
    info: dict[str, Any] | None = None,
) -> tuple[list[R2GWaypoints], list[OptimizationParams | None]]:
    """Each complete repetition's reference waypoints at its own rests (:func:`repetition_rests` on the start
    ``initial_m``, the trial-wide ``waypoints``) and its own optimisation parameters (None: the trial's ``params``,
    whose ``sigma_data_static_m`` is the per-axis trust already estimated), by ``params.rest_model``
    (:class:`RestRule`); the end moves only on the axes not held to return to the start. The other repetitions keep
    ``rep_waypoints``. ``info`` receives the variance components and the bias terms (``rest_model``)."""
    rule = RestRule.parse(str(params.rest_model))
    use = np.asarray(rule.axes, dtype=bool)
    base = rule.trust.removesuffix("-posterior")
    cap = params.sigma_ref_static_m if base in ("capped", "capped-tau", "trusted") else None
    sds = params.sigma_data_static_m
    floor = None
    if base == "trusted" and isinstance(sds, (tuple, list)):
        floor = [float(v) / np.sqrt(2.0) for v in sds]
    est = repetition_rests(
        t_s,
        initial_m,
        static_mask,
        repetitions,
        waypoints,
        rule.bias,
        tau_max_m=None if base == "capped" else cap,
        sigma_min_m=floor,
        alpha=rule.alpha,
    )
    own: list[OptimizationParams | None] = [None] * len(repetitions)
    out = list(rep_waypoints)
    if est is None:
        return out, own
    rts = params.return_to_start
    free = np.asarray([not r for r in rts] if isinstance(rts, (tuple, list)) else [not rts] * 3, dtype=bool)
    no_start = rule.trust in ("replace", "posterior", "trusted-posterior")
    if rule.gated and isinstance(sds, (tuple, list)):
        post_all = np.sqrt(np.nanmean(est.sd_m[:, 1:4] ** 2, axis=(0, 1)))
        use = use & (post_all < np.asarray([np.inf if v is None else v for v in sds], dtype=float))
        if not np.any(use):
            return out, own
    for k, i in enumerate(est.index):
        post = np.sqrt(np.nanmean(est.sd_m[k, 1:4] ** 2, axis=0))
        o = params
        if cap is not None:  # the posterior trust, at most the trial-wide reference's
            lo = 0.001 if rule.trust == "trusted-posterior" else 0.006
            o = replace(o, sigma_ref_static_m=tuple(float(v) for v in np.where(use, np.clip(post, lo, cap), cap)))
        elif rule.trust.startswith("posterior"):
            o = replace(o, sigma_ref_static_m=tuple(float(max(v, 0.003)) for v in post))
        if no_start:
            keep = sds if isinstance(sds, (tuple, list)) else (sds,) * 3
            o = replace(o, sigma_data_static_m=tuple(None if u else v for u, v in zip(use, keep, strict=True)))
        own[int(i)] = None if o is params else o
        bottle, mouth, back, end = est.waypoints(k, end_axes=free & use)
        trial = out[int(i)]
        back_trial = trial.bottle_m if trial.bottle_back_m is None else trial.bottle_back_m
        out[int(i)] = R2GWaypoints(
            bottle_m=tuple(np.where(use, bottle, trial.bottle_m).tolist()),
            mouth_m=tuple(np.where(use, mouth, trial.mouth_m).tolist()),
            end_m=tuple(np.where(use, end, trial.end_m).tolist()),
            bottle_back_m=tuple(np.where(use, back, back_trial).tolist()),
        )
    if info is not None:
        info["rest_model"] = {
            "sigma_m": np.round(est.sigma_m, 5).tolist(),
            "tau_m": np.round(est.tau_m, 5).tolist(),
            "bias_m": np.round(est.bias_m, 5).tolist(),
        }
    return out, own


def repetition_rests(
    t_s: np.ndarray,
    initial_m: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
    bias: bool = True,
    tau_max_m: float | None = None,
    sigma_min_m: Sequence[float] | None = None,
    alpha: float | None = None,
) -> RestEstimate | None:
    """Each complete repetition's rests from the start ``initial_m`` (N, 3) m (ZUPT from each window's start) and
    the trial-wide ``waypoints``; None with fewer than two complete repetitions.

    Per axis the unknowns are every rest's room position: each repetition's start (the previous window's end when
    the windows meet), bottle, mouth, bottle again and end. Observations: the start's displacement over each
    movement (:func:`imulog.process.trajectory_rests.rest_positions`, differenced), each ``X_j - X_{j-1}`` within
    ``sigma``, plus (``bias``) one fixed effect per movement type: what the start gets wrong the same way in every
    repetition. Prior: every home at 0, every bottle at the reference's bottle and every mouth at its mouth, each
    within ``tau``. ``(sigma, tau)`` maximise the restricted likelihood of the displacements on a log grid (1 mm to
    10 cm; ``tau`` at most ``tau_max_m``, ``sigma`` per axis at least ``sigma_min_m``); the bias terms are shrunk
    by their James-Stein factor and, with ``alpha``, kept only where they differ from 0 at that level. The rests
    are the posterior means, their uncertainty the posterior standard deviation of each rest relative to its
    repetition's start."""
    reps = [(i, r) for i, r in enumerate(repetitions) if len(r.phase_bounds_s) == 4]
    if len(reps) < 2:
        return None
    obs = np.array(
        [np.diff(np.vstack([np.zeros(3), rest_positions(t_s, initial_m, static_mask, r)]), axis=0) for _, r in reps]
    )  # (K, 4, 3) displacement per movement
    # unknown numbering: a repetition's start is the previous one's end when their windows meet
    links = window_links(repetitions)
    cols = np.zeros((len(reps), 5), dtype=int)
    n = 0
    for k, (i, _) in enumerate(reps):
        if k and reps[k - 1][0] == i - 1 and links[i]:
            cols[k, 0] = cols[k - 1, 4]
        else:
            cols[k, 0], n = n, n + 1
        cols[k, 1:] = np.arange(n, n + 4)
        n += 4
    kind = np.zeros(n, dtype=int)  # 0 home, 1 bottle, 2 mouth
    kind[cols[:, 1]] = kind[cols[:, 3]] = 1
    kind[cols[:, 2]] = 2
    targets = np.stack([np.zeros(3), np.asarray(waypoints.bottle_m), np.asarray(waypoints.mouth_m)])
    rests = np.zeros((len(reps), 5, 3))
    sd = np.zeros((len(reps), 5, 3))
    sig, tau = np.full(3, np.nan), np.full(3, np.nan)
    bias_m = np.zeros((4, 3))
    for ax in range(3):
        rows, y, btype = [], [], []
        for k in range(len(reps)):
            for j in range(4):
                if np.isfinite(obs[k, j, ax]):
                    r = np.zeros(n)
                    r[cols[k, j + 1]], r[cols[k, j]] = 1.0, -1.0
                    rows.append(r)
                    y.append(obs[k, j, ax])
                    btype.append(j)
        mu = targets[kind, ax]
        if len(rows) < 4:
            rests[:, :, ax] = mu[cols]
            sd[:, :, ax] = np.nan
            continue
        d = np.vstack(rows)
        b = np.asarray(btype)[:, None] == np.arange(4)[None, :] if bias else np.zeros((len(rows), 0))
        resid = np.asarray(y) - d @ mu
        lo = None if sigma_min_m is None else float(sigma_min_m[ax])
        s, t_, beta = _variance_components(d @ d.T, resid, b.astype(float), tau_max_m, lo, alpha)
        sig[ax], tau[ax] = s, t_
        if bias:
            bias_m[:, ax] = beta
            resid = resid - b @ beta
        # posterior of X ~ N(mu, tau^2 I) given resid = D (X - mu) + e, e ~ N(0, s^2 I)
        prec = d.T @ d / s**2 + np.eye(n) / t_**2
        cov = np.linalg.inv(prec)
        x = mu + cov @ (d.T @ resid) / s**2
        rests[:, :, ax] = x[cols]
        for k in range(len(reps)):
            c0 = cols[k, 0]
            for j in range(5):
                cj = cols[k, j]
                sd[k, j, ax] = np.sqrt(max(cov[cj, cj] + cov[c0, c0] - 2 * cov[cj, c0], 0.0))
    return RestEstimate(rests, sd, np.array([i for i, _ in reps]), sig, tau, bias_m)


def _variance_components(
    a: np.ndarray,
    resid: np.ndarray,
    fixed: np.ndarray,
    tau_max_m: float | None = None,
    sigma_min_m: float | None = None,
    alpha: float | None = None,
) -> tuple[float, float, np.ndarray]:
    """``(sigma, tau, beta)``: the standard deviations (m) maximising the restricted likelihood (REML) of
    ``resid ~ N(fixed beta, tau^2 a + sigma^2 I)`` on the log grid, and the fixed effects ``beta`` (m, generalised
    least squares) there; ``tau`` at most ``tau_max_m``, ``sigma`` at least ``sigma_min_m``. ``beta`` is 0 unless
    it differs from 0 at level ``alpha`` (Wald chi-square test; None: no test), and each effect is shrunk by its
    positive-part James-Stein factor."""
    lam, u = np.linalg.eigh(a)
    ry = u.T @ resid
    rb = u.T @ fixed  # (M, P)
    s2 = _GRID_M[:, None, None] ** 2
    t2 = _GRID_M[None, :, None] ** 2
    v = t2 * np.clip(lam, 0.0, None)[None, None, :] + s2  # (G, G, M): the covariance's eigenvalues
    p = fixed.shape[1]
    if p:
        btb = np.einsum("mp,ijm,mq->ijpq", rb, 1.0 / v, rb) + 1e-12 * np.eye(p)
        bty = np.einsum("mp,ijm,m->ijp", rb, 1.0 / v, ry)
        beta = np.linalg.solve(btb, bty[..., None])[..., 0]  # (G, G, P)
        e = ry[None, None, :] - np.einsum("mp,ijp->ijm", rb, beta)
        ll = -0.5 * (np.sum(np.log(v) + e**2 / v, axis=2) + np.linalg.slogdet(btb)[1])
    else:
        ll = -0.5 * np.sum(np.log(v) + ry[None, None, :] ** 2 / v, axis=2)
    if tau_max_m is not None:
        ll = np.where(_GRID_M[None, :] <= tau_max_m * (1 + 1e-9), ll, -np.inf)
    if sigma_min_m is not None:
        ll = np.where(_GRID_M[:, None] >= min(sigma_min_m, _GRID_M[-1]) * (1 - 1e-9), ll, -np.inf)
    i, j = np.unravel_index(int(np.argmax(ll)), ll.shape)
    if not p:
        return float(_GRID_M[i]), float(_GRID_M[j]), np.zeros(0)
    b = beta[i, j]
    cov = np.linalg.inv(btb[i, j])  # the effects' covariance, m^2
    if alpha is not None and float(b @ btb[i, j] @ b) < chi2.ppf(1.0 - alpha, p):
        return float(_GRID_M[i]), float(_GRID_M[j]), np.zeros(p)  # no significant bias: none taken off
    # positive-part James-Stein: only the share of each effect beyond its own noise
    keep = shrinkage_weight(np.abs(b) / np.sqrt(np.diag(cov)))
    return float(_GRID_M[i]), float(_GRID_M[j]), keep * b


def reference_scatter(
    t_s: np.ndarray,
    initial_m: np.ndarray,
    static_mask: np.ndarray,
    repetitions: Sequence[Repetition],
    waypoints: R2GWaypoints,
    sigma_ref_m: float | Sequence[float],
    sigma_min_m: Sequence[float] | None = None,
) -> tuple[float, float, float]:
    """The trial-wide reference's static error per axis (m): at least ``sigma_ref_m`` (the configured trust), and
    at least what the hand's own scatter about the trial-wide waypoints says, ``sqrt(2) tau`` (a rest relative to
    its repetition's start scatters by both places' ``tau``; ``tau`` by restricted maximum likelihood from the
    start's rest-to-rest displacements, :func:`repetition_rests` with the significance-tested movement biases and
    each displacement's error at least ``sigma_min_m`` per axis, so a poor start's errors are not read as the hand's
    scatter). The configured value with fewer than two complete repetitions (issue 31 point 2, eleventh round)."""
    ref = np.broadcast_to(np.asarray(sigma_ref_m, dtype=np.float64), (3,))
    est = repetition_rests(t_s, initial_m, static_mask, repetitions, waypoints, sigma_min_m=sigma_min_m, alpha=0.001)
    if est is None:
        return tuple(float(v) for v in ref)
    tau = np.where(np.isfinite(est.tau_m), est.tau_m, 0.0)
    return tuple(float(v) for v in np.maximum(ref, np.sqrt(2.0) * tau))
