"""How well can any method place a phase's boundaries? The information limit of the simulated trials (issue 31
point 1).

    python benchmarks/boundary_limit.py                                  # stroke-slow, sets 0:0 30:8, three noises
    python benchmarks/boundary_limit.py --conditions stroke-slow stroke --sets 0:0 --draws 20

For every phase of the simulated trials (the simulator's own motion plan, ``imulog.simulate.core.motion_plan``:
the submovements' onsets, durations and weights, the displacement, the wrist's rotation and its own time law), an
*oracle* that knows the model form observes the phase at the condition's IMU rate, 1 s of rest either side, in
white noise:

* ``acc``: the hand's acceleration (world frame, gravity and orientation known, no bias), 3 axes, sd ``acc`` per
  sample; unknowns: the displacement (3), each submovement's onset, duration and weight;
* ``acc+gyr``: and the gyroscope (3 axes, sd ``gyr`` per sample), the rotation's vector and its time law, whose
  onset (end) is the phase's where the simulator ties them (``stroke-slow``: the rotation starts with the phase
  and ends at 0.7-1.0 of it).

Two figures per phase: the Cramer-Rao bound of the onset, offset and duration (the Fisher information of the
whitened samples, the Jacobian by central differences), and a Monte-Carlo oracle: ``--draws`` noise draws, each
fitted by least squares (scipy ``least_squares``, Levenberg-Marquardt with the model's analytic Jacobian) starting at
the truth, so only the noise moves it (an estimator
that knows the model form and starts right: no method can expect to do better). A phase is within when its
duration error is under 0.1 s. On the same trials ``hand (default)`` (``benchmarks/segmentation_accuracy.py``'s
scoring, the full simulated IMU with bias, quantisation, gravity) at the same noise (``ImuParams.acc_noise_mps2``,
``gyr_noise_dps``). Noise levels as ``NAME=ACC,GYR`` (m/s^2 and deg/s per sample): the eleventh round's quarter of
the accelerometer's, the simulator's default, and the real devices' median 1-10 Hz density
(``benchmarks/device_noise.py``) at the simulator's 114.9 Hz.

``--outside``: each ``hand (default)`` phase outside 0.1 s with the oracle's bound on that phase. ``--from-hand``
(an experiment, docs/accuracy.md): the oracle's fit without its two gifts, started from ``hand (default)``'s
boundaries with the number of submovements chosen by BIC (``--fit-starts`` random spreads per number,
``--fit-k-known`` for the true number only).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.special import erf

from imulog.simulate.core import motion_plan
from imulog.simulate.motion import MotionPlan, SubmovementLaw

sys.path.insert(0, str(Path(__file__).resolve().parent))

from phase_fit import mj_derivatives as _mj_derivatives  # noqa: E402  (the model's derivatives, one definition)

MARGIN_S = 1.0  # s of rest observed before and after the phase
MIN_DURATION_S = 0.05  # s: a submovement's shortest duration in the fit
NOISES = ("quarter-acc=0.005,0.1", "simulator=0.02,0.1", "devices-median=0.0342,0.0623")


@dataclass(frozen=True)
class Phase:
    """One true phase, times in s from its start: the translation ``dp_m`` (m) along ``sum_i w_i mj((t - t_i) /
    T_i)``, the rotation ``rotvec_rad`` (rad, sensor frame) along one minimum-jerk law from ``rot_onset_s`` to
    ``rot_end_s``; ``rot_onset_tied`` / ``rot_end_tied``: the rotation starts / ends with the translation."""

    onsets_s: np.ndarray
    durations_s: np.ndarray
    weights: np.ndarray
    dp_m: np.ndarray
    rotvec_rad: np.ndarray
    rot_onset_s: float
    rot_end_s: float
    rot_onset_tied: bool
    rot_end_tied: bool

    @property
    def duration_s(self) -> float:
        return float(np.max(self.onsets_s + self.durations_s) - np.min(self.onsets_s))


@dataclass(frozen=True)
class Noise:
    """White noise per sample: accelerometer (m/s^2) and gyroscope (rad/s) sd per axis, at ``rate_hz`` (Hz)."""

    acc_mps2: float
    gyr_rads: float
    rate_hz: float


def phases_of(plan: MotionPlan) -> list[tuple[int, str, Phase]]:
    """(repetition, label, :class:`Phase`) of each true phase of ``plan`` that is one segment without a bowed path
    (the grid's ``stroke``-like and default conditions); ValueError for any other."""
    t0 = np.asarray(plan.t0)
    out = []
    for iv in plan.intervals:
        if iv.task_index < 0:
            continue
        k = int(np.argmin(np.abs(t0 - iv.start_s)))
        if abs(t0[k] - iv.start_s) > 1e-9 or abs(t0[k] + plan.duration[k] - iv.end_s) > 1e-9:
            raise ValueError(f"phase {iv.label} of repetition {iv.task_index} is not one segment")
        if np.any(plan.curve[k] != 0) or np.any(plan.lift[k] != 0):
            raise ValueError("a bowed or lifted path is not modelled by the oracle")
        T = plan.duration[k]
        law = plan.law[k] or SubmovementLaw(np.zeros(1), np.array([T]), np.ones(1))
        rot = plan.rot_law[k] or law
        if len(rot.onsets_s) != 1 and rot is not law:
            raise ValueError("a rotation of several submovements is not modelled")
        r_on = float(rot.onsets_s[0]) if rot is not law else 0.0
        r_end = float(rot.onsets_s[0] + rot.durations_s[0]) if rot is not law else T
        out.append(
            (
                iv.task_index,
                iv.label,
                Phase(
                    onsets_s=np.asarray(law.onsets_s, dtype=float),
                    durations_s=np.asarray(law.durations_s, dtype=float),
                    weights=np.asarray(law.weights, dtype=float),
                    dp_m=np.asarray(plan.dp[k], dtype=float),
                    rotvec_rad=np.asarray(plan.rv[k], dtype=float),
                    rot_onset_s=r_on,
                    rot_end_s=r_end,
                    rot_onset_tied=abs(r_on - float(np.min(law.onsets_s))) < 1e-9,
                    rot_end_tied=abs(r_end - float(np.max(law.onsets_s + law.durations_s))) < 1e-9,
                ),
            )
        )
    return out


# -- the parametric model: theta = [D (3), t_i (k), T_i (k), w_2..w_k (k-1)] + gyro [r (3), rot onset?, rot end?]


def pack(ph: Phase, gyro: bool) -> np.ndarray:
    """The true parameter vector of ``ph`` (see :func:`predict`)."""
    theta = [ph.dp_m, ph.onsets_s, ph.durations_s, ph.weights[1:]]
    if gyro:
        theta.append(ph.rotvec_rad)
        if not ph.rot_onset_tied:
            theta.append([ph.rot_onset_s])
        if not ph.rot_end_tied:
            theta.append([ph.rot_end_s])
    return np.concatenate([np.asarray(x, dtype=float).ravel() for x in theta])


def boundaries(theta: np.ndarray, k: int) -> tuple[float, float]:
    """Onset and offset (s) of the translation with parameters ``theta``."""
    on, du = theta[3 : 3 + k], theta[3 + k : 3 + 2 * k]
    return float(np.min(on)), float(np.max(on + du))


def predict(theta: np.ndarray, ph: Phase, t: np.ndarray, noise: Noise, gyro: bool) -> np.ndarray:
    """Whitened model samples at times ``t`` (s from the phase's start): the acceleration (N, 3) / ``acc_mps2`` and,
    with ``gyro``, the angular velocity (N, 3) / ``gyr_rads``, flattened."""
    k = len(ph.onsets_s)
    D, on, du = theta[:3], theta[3 : 3 + k], theta[3 + k : 3 + 2 * k]
    w = np.r_[1.0 - np.sum(theta[3 + 2 * k : 2 + 3 * k]), theta[3 + 2 * k : 2 + 3 * k]]
    sdd = SubmovementLaw(on, du, w)(t)[2]
    out = [(sdd[:, None] * D).ravel() / noise.acc_mps2]
    if gyro:
        j = 2 + 3 * k
        r = theta[j : j + 3]
        j += 3
        t_on, t_end = boundaries(theta, k)
        if not ph.rot_onset_tied:
            t_on, j = theta[j], j + 1
        if not ph.rot_end_tied:
            t_end = theta[j]
        span = max(t_end - t_on, 1e-6)
        ds = SubmovementLaw(np.array([t_on]), np.array([span]), np.ones(1))(t)[1]
        out.append((ds[:, None] * r).ravel() / noise.gyr_rads)
    return np.concatenate(out)


def sample_times(ph: Phase, rate_hz: float, phase_frac: float = 0.0) -> np.ndarray:
    """Sample times (s from the phase's start) over the phase and ``MARGIN_S`` either side."""
    first = -MARGIN_S + phase_frac / rate_hz
    return first + np.arange(int((ph.duration_s + 2 * MARGIN_S) * rate_hz)) / rate_hz


def jacobian(theta: np.ndarray, ph: Phase, t: np.ndarray, noise: Noise, gyro: bool) -> np.ndarray:
    """Analytic Jacobian of :func:`predict` (rows as it flattens them; tests check it against central differences)."""
    k = len(ph.onsets_s)
    n = len(t)
    D, on, du = theta[:3], theta[3 : 3 + k], theta[3 + k : 3 + 2 * k]
    w = np.r_[1.0 - np.sum(theta[3 + 2 * k : 2 + 3 * k]), theta[3 + 2 * k : 2 + 3 * k]]
    g = np.empty((k, n))
    dg_dt = np.empty((k, n))
    dg_dT = np.empty((k, n))
    for i in range(k):
        tau = (t - on[i]) / du[i]
        _, d2, d3 = _mj_derivatives(tau)
        g[i] = d2 / du[i] ** 2
        dg_dt[i] = -d3 / du[i] ** 3
        dg_dT[i] = -(d3 * tau + 2.0 * d2) / du[i] ** 3
    S = w @ g
    cols = np.zeros((n, 3, len(theta)))
    for c in range(3):
        cols[:, c, c] = S
    cols[:, :, 3 : 3 + k] = (w[:, None] * dg_dt).T[:, None, :] * D[None, :, None]
    cols[:, :, 3 + k : 3 + 2 * k] = (w[:, None] * dg_dT).T[:, None, :] * D[None, :, None]
    cols[:, :, 3 + 2 * k : 2 + 3 * k] = (g[1:] - g[0]).T[:, None, :] * D[None, :, None]
    blocks = [cols.reshape(n * 3, len(theta)) / noise.acc_mps2]
    if gyro:
        j = 2 + 3 * k
        r = theta[j : j + 3]
        t_on, t_end = boundaries(theta, k)
        first, last = int(np.argmin(on)), int(np.argmax(on + du))
        c_on, c_end = [3 + first], [3 + last, 3 + k + last]  # columns the tied ends move with
        j_r = j
        j += 3
        if not ph.rot_onset_tied:
            t_on, c_on, j = theta[j], [j], j + 1
        if not ph.rot_end_tied:
            t_end, c_end = theta[j], [j]
        span = max(t_end - t_on, 1e-6)
        tau = (t - t_on) / span
        d1, d2, _ = _mj_derivatives(tau)
        ds = d1 / span
        d_on = (d2 * (tau - 1.0) + d1) / span**2
        d_end = -(d2 * tau + d1) / span**2
        gcols = np.zeros((n, 3, len(theta)))
        for c in range(3):
            gcols[:, c, j_r + c] = ds
        for col in c_on:
            gcols[:, :, col] += d_on[:, None] * r[None, :]
        for col in c_end:
            gcols[:, :, col] += d_end[:, None] * r[None, :]
        blocks.append(gcols.reshape(n * 3, len(theta)) / noise.gyr_rads)
    return np.vstack(blocks)


def numeric_jacobian(
    theta: np.ndarray, ph: Phase, t: np.ndarray, noise: Noise, gyro: bool, h: float = 1e-6
) -> np.ndarray:
    """Central-difference Jacobian of :func:`predict` (steps ``h`` in each parameter's unit): the check of
    :func:`jacobian`."""
    cols = []
    for j in range(len(theta)):
        e = np.zeros_like(theta)
        e[j] = h
        cols.append((predict(theta + e, ph, t, noise, gyro) - predict(theta - e, ph, t, noise, gyro)) / (2 * h))
    return np.column_stack(cols)


def boundary_gradients(ph: Phase, gyro: bool) -> tuple[np.ndarray, np.ndarray]:
    """d onset / d theta and d offset / d theta at the truth (a min and a max over the submovements)."""
    k = len(ph.onsets_s)
    n = len(pack(ph, gyro))
    g_on, g_off = np.zeros(n), np.zeros(n)
    g_on[3 + int(np.argmin(ph.onsets_s))] = 1.0
    last = int(np.argmax(ph.onsets_s + ph.durations_s))
    g_off[3 + last] = g_off[3 + k + last] = 1.0
    return g_on, g_off


def cramer_rao(ph: Phase, noise: Noise, gyro: bool) -> tuple[float, float, float]:
    """Cramer-Rao bound (sd, s) of the onset, offset and duration of ``ph`` observed in ``noise``."""
    theta = pack(ph, gyro)
    J = jacobian(theta, ph, sample_times(ph, noise.rate_hz), noise, gyro)
    cov = np.linalg.pinv(J.T @ J)
    g_on, g_off = boundary_gradients(ph, gyro)
    return tuple(float(np.sqrt(g @ cov @ g)) for g in (g_on, g_off, g_off - g_on))


def oracle_errors(ph: Phase, noise: Noise, gyro: bool, rng: np.random.Generator) -> tuple[float, float, float]:
    """One Monte-Carlo draw: onset, offset and duration errors (s) of the least-squares fit of the model to the
    noisy samples, started at the truth."""
    theta0 = pack(ph, gyro)
    t = sample_times(ph, noise.rate_hz, float(rng.uniform()))
    y = predict(theta0, ph, t, noise, gyro)
    y = y + rng.normal(size=y.shape)
    k = len(ph.onsets_s)
    fit = least_squares(
        lambda th: predict(th, ph, t, noise, gyro) - y,
        theta0,
        jac=lambda th: jacobian(th, ph, t, noise, gyro),
        method="lm",
        xtol=1e-6,
        ftol=1e-6,
    )
    if np.any(fit.x[3 + k : 3 + 2 * k] < MIN_DURATION_S):  # a submovement collapsed: no boundary to read
        return np.inf, np.inf, np.inf
    on, off = boundaries(fit.x, k)
    on0, off0 = boundaries(theta0, k)
    return on - on0, off - off0, (off - on) - (off0 - on0)


def _guess(a: float, b: float, k: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Onsets and durations (s) of ``k`` submovements spread over ``[a, b]``: the first starts at ``a``, the one that
    ends last ends at ``b``, the others start in the first 60 % and last at least 0.2 s."""
    span = max(b - a, 0.3)
    on = np.r_[a, a + span * np.sort(rng.uniform(0.1, 0.6, k - 1))]
    end = np.r_[a + span * rng.uniform(0.5, 0.9), a + span * rng.uniform(0.6, 1.0, k - 1)]
    end[int(np.argmax(end))] = a + span
    return on, np.maximum(end - on, 0.2)


def fit_from(
    ph: Phase, noise: Noise, gyro: bool, a: float, b: float, rng: np.random.Generator, ks=(1, 2, 3, 4), starts: int = 3
) -> tuple[float, float, float, int]:
    """The oracle's fit without its two gifts: started from boundaries ``a``, ``b`` (s from the true start, e.g. a
    method's) instead of the truth, and the number of submovements chosen by BIC over ``ks`` (``starts`` random
    spreads each, the amplitudes by linear least squares). Onset, offset and duration errors (s) and the chosen k.
    The observation is the oracle's (the true model in white noise over the true phase and 1 s either side)."""
    theta0 = pack(ph, gyro)
    t = sample_times(ph, noise.rate_hz, float(rng.uniform()))
    y = predict(theta0, ph, t, noise, gyro) + rng.normal(size=len(t) * (6 if gyro else 3))
    acc_obs = y[: 3 * len(t)].reshape(-1, 3) * noise.acc_mps2
    best: tuple[float, np.ndarray, Phase] | None = None
    for k in ks:
        for _ in range(starts):
            on, du = _guess(a, b, k, rng)
            G = np.column_stack([SubmovementLaw(on[i : i + 1], du[i : i + 1], np.ones(1))(t)[2] for i in range(k)])
            c = np.linalg.lstsq(G, acc_obs, rcond=None)[0]  # (k, 3)
            D = c.sum(axis=0)
            w = c @ D / max(float(D @ D), 1e-12)
            guess = replace(ph, onsets_s=on, durations_s=du, weights=w / w.sum(), dp_m=D * w.sum())
            if gyro:
                rot_end = b if ph.rot_end_tied else a + 0.85 * (b - a)
                ds = SubmovementLaw(np.array([a]), np.array([max(rot_end - a, 0.2)]), np.ones(1))(t)[1]
                gyr_obs = y[3 * len(t) :].reshape(-1, 3) * noise.gyr_rads
                r = ds @ gyr_obs / max(float(ds @ ds), 1e-12)
                guess = replace(guess, rotvec_rad=r, rot_onset_s=a, rot_end_s=rot_end)
            th = pack(guess, gyro)
            fit = least_squares(
                lambda x, g=guess: predict(x, g, t, noise, gyro) - y,
                th,
                jac=lambda x, g=guess: jacobian(x, g, t, noise, gyro),
                method="lm",
                xtol=1e-6,
                ftol=1e-6,
                max_nfev=300,
            )
            if np.any(fit.x[3 + k : 3 + 2 * k] < MIN_DURATION_S):
                continue
            bic = float(2 * fit.cost + len(th) * np.log(len(y)))
            if best is None or bic < best[0]:
                best = (bic, fit.x, guess)
    if best is None:
        return np.inf, np.inf, np.inf, 0
    k = len(best[2].onsets_s)
    on, off = boundaries(best[1], k)
    on0, off0 = boundaries(theta0, len(ph.onsets_s))
    return on - on0, off - off0, (off - on) - (off0 - on0), k


def within_expected(sd_s: np.ndarray, tol_s: float = 0.1) -> np.ndarray:
    """P(|error| < tol) for a zero-mean Gaussian error of sd ``sd_s``."""
    return erf(tol_s / (np.sqrt(2.0) * np.maximum(sd_s, 1e-12)))


def hand_score(seed: int, subject: int, repetitions: int, options: dict, acc: float, gyr: float) -> dict:
    """``hand (default)`` on the trial scored as ``benchmarks/segmentation_accuracy.py`` does (its ``score``: the
    share of durations within 0.1 s, the phases outside it with their onset / offset errors), the IMU noise set to
    ``acc`` m/s^2 and ``gyr`` deg/s per sample (the rest of the simulated IMU as the grid has it)."""
    from segmentation_accuracy import score

    from imulog.process.segmentation.pipeline import PhaseParams
    from imulog.process.segmentation.repetitions import RepetitionParams
    from imulog.simulate import simulate

    sim = simulate(
        "r2g", seed=seed, subject=subject, repetitions=repetitions, acc_noise_mps2=acc, gyr_noise_dps=gyr, **options
    )
    params = replace(PhaseParams(), repetitions=RepetitionParams(n_repetitions=repetitions))
    return score(sim, params)


def end_speed_mps(ph: Phase, before_s: float) -> float:
    """The hand's true speed (m/s) ``before_s`` seconds before the phase's end."""
    law = SubmovementLaw(ph.onsets_s, ph.durations_s, ph.weights)
    t = np.array([float(np.max(ph.onsets_s + ph.durations_s)) - before_s])
    return float(np.linalg.norm(ph.dp_m) * abs(law(t)[1][0]))


def conditions_options(names: list[str]) -> dict[str, dict]:
    """The grid's conditions and the benchmark's wider ones (``segmentation_accuracy._wider``) by name."""
    from segmentation_accuracy import _wider

    from imulog.simulate.grid import condition

    wider = _wider()
    return {n: dict(wider[n]) if n in wider else condition(n) for n in names}


def print_outside(cond: str, nname: str, trials: list, scores: list[dict], noise: Noise) -> None:
    """Each ``hand (default)`` phase outside 0.1 s: its onset / offset errors, the oracle's Cramer-Rao sd of that
    phase's duration (accelerometer; with the gyroscope) and the hand's true speed 0.1 and 0.3 s before its end;
    then how many of them the oracle would place within 0.1 s at least 95 % of the time (sd under 0.051 s)."""
    print(f"\n{cond} / {nname}: hand (default)'s phases outside 0.1 s against the oracle's bound on the same phase")
    sds = []
    for (seed, subject, phases), sc in zip(trials, scores, strict=True):
        by_key = {(rep, label): ph for rep, label, ph in phases}
        for rep, label, on, off in sc["outside"]:
            ph = by_key[(rep, label)]
            sd_a, sd_g = cramer_rao(ph, noise, False)[2], cramer_rao(ph, noise, True)[2]
            sds.append(sd_g)
            print(
                f"  seed {seed} subject {subject} repetition {rep} {label}: hand onset {on:+.3f} s, offset {off:+.3f} s; "
                f"oracle duration sd {sd_a:.3f} s (acc), {sd_g:.3f} s (acc+gyr); the hand's speed 0.1 / 0.3 s before "
                f"its end {100 * end_speed_mps(ph, 0.1):.2f} / {100 * end_speed_mps(ph, 0.3):.2f} cm/s"
            )
    sds = np.array(sds)
    print(
        f"  {len(sds)} phases outside 0.1 s; the oracle (acc+gyr) places {int(np.sum(sds < 0.051))} of them within 0.1 s "
        f"at least 95 % of the time (median sd {np.median(sds) if len(sds) else float('nan'):.3f} s)"
    )


def print_from_hand(
    cond: str,
    nname: str,
    trials: list,
    scores: list[dict],
    noise: Noise,
    hand: np.ndarray,
    starts: int = 3,
    k_known: bool = False,
) -> None:
    """:func:`fit_from` on every phase, started from ``hand (default)``'s boundaries (a phase it missed counts as
    outside) with ``starts`` random spreads per k (``k_known``: only the true k): the share within 0.1 s per trial
    against the hand's, and the phases it moves in or out."""
    shares, fixed, broken, ks, n_true_k = [], 0, 0, [], 0
    for (seed, subject, phases), sc in zip(trials, scores, strict=True):
        rng = np.random.default_rng([seed, subject, 32])
        ends = {(r, lab): (on, off) for r, lab, on, off in sc["ends"]}
        ok = []
        for rep, label, ph in phases:
            if (rep, label) not in ends:
                ok.append(False)
                continue
            on, off = ends[(rep, label)]
            ks_try = (len(ph.onsets_s),) if k_known else (1, 2, 3, 4)
            _, _, dur_err, k = fit_from(ph, noise, True, on, ph.duration_s + off, rng, ks_try, starts)
            ok.append(abs(dur_err) < 0.1)
            ks.append(k)
            n_true_k += k == len(ph.onsets_s)
            hand_ok = abs(off - on) < 0.1
            fixed += ok[-1] and not hand_ok
            broken += hand_ok and not ok[-1]
        shares.append(float(np.mean(ok)))
    shares = np.array(shares)
    print(
        f"\n{cond} / {nname}: the oracle's fit from hand (default)'s boundaries, "
        f"{'k known' if k_known else 'k by BIC'}, {starts} starts per k (acc+gyr, one draw): "
        f"{100 * shares.mean():.1f} % within 0.1 s (worst trial {100 * shares.min():.1f}), {int(np.sum(shares < 0.95))} "
        f"of {len(shares)} trials under 95 %; hand (default) {100 * hand.mean():.1f} % ({100 * hand.min():.1f}), "
        f"{int(np.sum(hand < 0.95))} under; phases brought within 0.1 s {fixed}, taken out {broken}; k chosen right on "
        f"{n_true_k} of {len(ks)} phases"
    )
    print(
        "  per trial (seed/subject: fit, hand): "
        + ", ".join(
            f"{t[0]}/{t[1]}: {100 * s_:.1f}, {100 * h:.1f}" for t, s_, h in zip(trials, shares, hand, strict=True)
        )
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--conditions", nargs="+", default=["stroke-slow"])
    ap.add_argument("--sets", nargs="+", default=["0:0", "30:8"], help="FIRST_SEED:FIRST_SUBJECT, each 3 x 2 trials")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--subjects", type=int, default=2)
    ap.add_argument("--repetitions", type=int, default=10)
    ap.add_argument("--draws", type=int, default=10, help="Monte-Carlo noise draws per phase")
    ap.add_argument("--noise", nargs="+", default=list(NOISES), help="NAME=ACC_MPS2,GYR_DPS per sample")
    ap.add_argument("--no-hand", action="store_true", help="skip hand (default) on the same trials")
    ap.add_argument(
        "--from-hand",
        action="store_true",
        help="also the oracle's fit started from hand (default)'s boundaries with k chosen by BIC (acc+gyr, one draw)",
    )
    ap.add_argument("--fit-starts", type=int, default=3, help="--from-hand: random starts per number of submovements")
    ap.add_argument("--fit-k-known", action="store_true", help="--from-hand: the true number of submovements only")
    ap.add_argument(
        "--outside", action="store_true", help="each hand phase outside 0.1 s with the oracle's bound on that phase"
    )
    args = ap.parse_args()

    noises = {}
    for item in args.noise:
        name, vals = item.split("=")
        a, g = (float(v) for v in vals.split(","))
        noises[name] = (a, g)
    pairs = [
        (int(s0) + i, int(b0) + j)
        for s0, b0 in (x.split(":") for x in args.sets)
        for i in range(args.seeds)
        for j in range(args.subjects)
    ]
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)  # small dense problems: BLAS threads only contend on the shared machine
    t_start = time.process_time()
    print(
        "| condition | noise (acc m/s^2, gyr deg/s per sample) | observer | CRB sd onset / offset / duration s (median) "
        "| oracle rms onset / offset / duration s | within 0.1 s %: CRB (worst trial, its seed/subject) / oracle (worst "
        "trial) | trials under 95 %: "
        "CRB / oracle |"
    )
    print("|" + "---|" * 7)
    hand_rows = []
    for cond, options in conditions_options(args.conditions).items():
        rate = float(options.get("imu_rate_hz", 114.9))
        trials = [
            (
                seed,
                subject,
                phases_of(motion_plan("r2g", seed=seed, subject=subject, repetitions=args.repetitions, **options)),
            )
            for seed, subject in pairs
        ]
        for nname, (acc, gyr_dps) in noises.items():
            noise = Noise(acc, float(np.radians(gyr_dps)), rate)
            for gyro in (False, True):
                crb, err, crb_trial, orc_trial = [], [], [], []
                for seed, subject, phases in trials:
                    rng = np.random.default_rng([seed, subject, 31])
                    c = np.array([cramer_rao(ph, noise, gyro) for _, _, ph in phases])
                    e = np.array(
                        [[oracle_errors(ph, noise, gyro, rng) for _ in range(args.draws)] for _, _, ph in phases]
                    ).reshape(len(phases), args.draws, 3)
                    crb.append(c)
                    err.append(e)
                    crb_trial.append(float(np.mean(within_expected(c[:, 2]))))
                    orc_trial.append(np.mean(np.abs(e[:, :, 2]) < 0.1, axis=0))  # per draw
                c, e = np.concatenate(crb), np.concatenate(err)
                orc = np.array(orc_trial)  # (trials, draws)
                rms = np.sqrt(np.mean(e**2, axis=(0, 1))) if args.draws else np.full(3, np.nan)
                orc_cells = ("-", f"- of {len(trials)}")
                if args.draws:
                    orc_cells = (
                        f"{100 * orc.mean():.1f} ({100 * orc.mean(axis=1).min():.1f})",
                        f"{int(np.sum(orc.mean(axis=1) < 0.95))} of {len(trials)} (draws under 95 %: "
                        f"{100 * np.mean(orc < 0.95):.0f} %)",
                    )
                print(
                    f"| {cond} | {nname} ({acc:g}, {gyr_dps:g}) | {'acc+gyr' if gyro else 'acc'} | "
                    f"{np.median(c[:, 0]):.3f} / {np.median(c[:, 1]):.3f} / {np.median(c[:, 2]):.3f} | "
                    f"{rms[0]:.3f} / {rms[1]:.3f} / {rms[2]:.3f} | "
                    f"{100 * np.mean(crb_trial):.1f} ({100 * np.min(crb_trial):.1f}, "
                    f"{'/'.join(map(str, pairs[int(np.argmin(crb_trial))]))}) / {orc_cells[0]} | "
                    f"{int(np.sum(np.array(crb_trial) < 0.95))} / {orc_cells[1]} |",
                    flush=True,
                )
            if not args.no_hand:
                scores = [hand_score(sd, sb, args.repetitions, options, acc, gyr_dps) for sd, sb in pairs]
                w = np.array([r["duration_within_0_1_s"] for r in scores])
                hand_rows.append((cond, nname, acc, gyr_dps, w))
                if args.outside:
                    print_outside(cond, nname, trials, scores, noise)
                if args.from_hand:
                    print_from_hand(cond, nname, trials, scores, noise, w, args.fit_starts, args.fit_k_known)
    if hand_rows:
        print(
            "\n| condition | noise (acc m/s^2, gyr deg/s per sample) | hand (default): within 0.1 s % (worst trial) | trials under 95 % |"
        )
        print("|" + "---|" * 4)
        for cond, nname, acc, gyr_dps, w in hand_rows:
            print(
                f"| {cond} | {nname} ({acc:g}, {gyr_dps:g}) | {100 * w.mean():.1f} ({100 * w.min():.1f}) | "
                f"{int(np.sum(w < 0.95))} of {len(w)} |"
            )
    print(f"\ntrials (seed, subject): {pairs}; {args.draws} draws per phase; CPU {time.process_time() - t_start:.1f} s")


if __name__ == "__main__":
    main()
