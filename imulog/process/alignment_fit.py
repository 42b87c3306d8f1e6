"""The alignment clock fitted over windows across the trial: per-window lags, offset and drift with their uncertainties, quality."""

from __future__ import annotations

import numpy as np

from imulog.process.alignment_clock import NS
from imulog.process.alignment_lag import estimate_lag
from imulog.process.alignment_params import AlignmentParams


def _fit_line(
    t_s: np.ndarray, y_s: np.ndarray, prior_sd_s: float = 0.0, prior_n: float = 0.0
) -> tuple[float, float, float, float, float]:
    """Least-squares ``y = a + b t`` with ``t`` centred: (a, b, se_a, se_b, residual sd) (NaN se when n < 3).

    The residual variance is pooled with a prior ``prior_sd_s`` counted as ``prior_n`` observations, so that
    three or four windows that happen to line up do not claim a precision their scatter cannot show.
    """
    n = len(t_s)
    b = float(np.polyfit(t_s, y_s, 1)[0]) if n >= 2 and np.ptp(t_s) > 0 else 0.0
    a = float(np.mean(y_s - b * t_s))
    r = y_s - a - b * t_s
    if n < 3:
        return a, b, float("nan"), float("nan"), float(np.std(r)) if n else float("nan")
    sd = float(np.sqrt((np.sum(r**2) + prior_n * prior_sd_s**2) / (n - 2 + prior_n)))
    return a, b, sd / np.sqrt(n), sd / np.sqrt(np.sum(t_s**2)), sd


def _theil_sen(t_s: np.ndarray, y_s: np.ndarray) -> tuple[float, float]:
    """Robust line ``y = a + b t``: b the median of the pairwise slopes, a the median of ``y - b t``."""
    i, j = np.triu_indices(len(t_s), k=1)
    dt = t_s[j] - t_s[i]
    ok = dt != 0
    b = float(np.median((y_s[j] - y_s[i])[ok] / dt[ok])) if ok.any() else 0.0
    return float(np.median(y_s - b * t_s)), b


def fit_clock(
    t_dev_ns: np.ndarray,
    x_dev: np.ndarray,
    t_ref_ns: np.ndarray,
    x_ref: np.ndarray,
    params: AlignmentParams = AlignmentParams(),
    coarse_offset_ns: int | None = None,
    min_activity: float | None = None,
) -> dict:
    """Clock offset and drift from two signals that should match (e.g. angular-velocity norms).

    ``min_activity`` (default ``params.min_window_activity``): windows whose reference signal varies less
    (sd, the signal's unit) are left out.

    ``x_dev`` on the device clock, ``x_ref`` on the reference clock. Returns the clock fields of
    ``imulog.alignment``: ``offset_ns`` (at ``t0_ns``), ``drift_ppm``, ``t0_ns`` (device time of the mean
    window centre, so offset and drift are uncorrelated), ``offset_uncertainty_ns`` and
    ``drift_uncertainty_ppm`` (standard errors of the line fit, None with fewer than 3 windows),
    ``drift_estimated``, ``score`` (median peak correlation of the windows used), ``coarse_score``,
    ``residual_spread_ns`` (sd of the used windows' residual lag) and ``windows`` (per window: device-time
    centre, offset, score, residual_ns, used, and why not).
    """
    t_dev = np.asarray(t_dev_ns, dtype=np.int64)
    t_ref = np.asarray(t_ref_ns, dtype=np.int64)
    span_s = (int(t_ref[-1]) - int(t_ref[0])) / NS
    coarse = estimate_lag(
        t_dev,
        x_dev,
        t_ref,
        x_ref,
        window_start_s=params.window_start_s,
        window_s=span_s,
        max_lag_s=params.max_lag_s,
        grid_hz=params.coarse_hz,
        prior_offset_ns=None,
    )
    prior = coarse.offset_ns if coarse_offset_ns is None else int(coarse_offset_ns)
    usable = span_s - params.window_start_s - params.drift_end_margin_s
    n_win = _n_windows(usable, params)
    width = usable / n_win
    windows = []
    x_ref = np.asarray(x_ref, dtype=np.float64)
    for k in range(n_win):
        start = params.window_start_s + k * width
        w = {"start_s": round(start, 3), "width_s": round(width, 3), "used": False}
        sel = (t_ref >= t_ref[0] + start * NS) & (t_ref <= t_ref[0] + (start + width) * NS)
        activity = float(np.nanstd(x_ref[sel])) if np.isfinite(x_ref[sel]).sum() > 10 else 0.0
        try:
            est = estimate_lag(
                t_dev,
                x_dev,
                t_ref,
                x_ref,
                window_start_s=start,
                window_s=width,
                max_lag_s=params.fine_lag_s,
                grid_hz=params.grid_hz,
                min_overlap=0.8,
                prior_offset_ns=prior,
            )
        except ValueError:
            w["why"] = "no overlap"
            windows.append(w)
            continue
        w.update(t_dev_center_ns=est.t_dev_center_ns, offset_ns=est.offset_ns, score=round(est.score, 4))
        if activity < (params.min_window_activity if min_activity is None else min_activity):
            w["why"] = "no movement"
        elif est.score < params.min_window_score:
            w["why"] = "low score"
        elif abs(est.offset_ns - prior) >= 0.98 * params.fine_lag_s * NS:
            w["why"] = "lag at the search limit"
        else:
            w["used"] = True
        windows.append(w)
    result: dict = {"coarse_offset_ns": int(coarse.offset_ns), "coarse_score": round(coarse.score, 4)}
    if n_win > 1 and n_win * params.window_s > usable + 1e-9:
        result["short_trial_windows_s"] = round(width, 3)
    if not any(w["used"] for w in windows):
        # nothing better than the coarse lag over the whole recording
        result.update(
            offset_ns=int(coarse.offset_ns),
            drift_ppm=0.0,
            t0_ns=int(coarse.t_dev_center_ns),
            offset_uncertainty_ns=None,
            drift_uncertainty_ppm=None,
            drift_estimated=False,
            score=float(coarse.score),
            residual_spread_ns=None,
            windows=windows,
        )
        return result
    result.update(fit_window_lags(windows, width, params))
    result["windows"] = windows
    return result


def _n_windows(usable_s: float, params: AlignmentParams) -> int:
    """Windows across ``usable_s`` seconds: about ``window_s`` each; a trial too short for three of them
    (with ``drift``) is cut into windows of at least ``short_window_s`` so that the drift is estimated from
    the whole trial (at most ``short_windows``), its uncertainty deciding whether it is applied."""
    n = max(1, int(np.floor(usable_s / params.window_s + 0.5)))
    if params.drift and n < 3 and usable_s >= 3 * params.short_window_s:
        n = max(n, min(params.short_windows, int(usable_s // params.short_window_s)))
    return n


def fit_window_lags(windows: list[dict], width_s: float, params: AlignmentParams = AlignmentParams()) -> dict:
    """Offset and drift fitted to the lags of the ``used`` windows (dicts with ``t_dev_center_ns``,
    ``offset_ns``, ``score``; from one IMU, or pooled from every IMU of one recording, which share a clock).

    Robust line (Theil-Sen, then least squares without outliers beyond ``outlier_k`` robust sd and
    ``outlier_floor_s``); windows found outliers get ``used = False, why = "outlier"`` and every used one its
    ``residual_ns`` (in place). The drift is fitted with at least 3 windows spanning 1.5 widths; when its
    standard error exceeds ``max_drift_uncertainty_ppm`` it is not estimable: drift 0, ``drift_estimated``
    False, the uncertainty kept and ``drift_note`` saying why. Returns the clock fields of :func:`fit_clock`.
    """
    used = [w for w in windows if w.get("used")]
    if not used:
        raise ValueError("no usable window to fit the clock")
    keep = np.ones(len(used), dtype=bool)
    tc = np.array([w["t_dev_center_ns"] for w in used], dtype=np.int64)
    off = np.array([w["offset_ns"] for w in used], dtype=np.int64)
    t0 = int(np.round(np.mean(tc)))
    ts = (tc - t0) / NS
    ys = (off - off[0]) / NS  # s, relative (float precision)
    can_drift = params.drift and len(used) >= 3 and np.ptp(ts) >= 1.5 * width_s
    for it in range(3):
        if can_drift and keep.sum() >= 3:
            # first pass Theil-Sen (median of pairwise slopes): one bad window at an end of the trial has the
            # leverage to tilt a least-squares line towards itself and hide from the outlier test
            a, b = _theil_sen(ts[keep], ys[keep]) if it == 0 else _fit_line(ts[keep], ys[keep])[:2]
        else:
            a, b = float(np.median(ys[keep])), 0.0
        r = ys - a - b * ts
        mad = 1.4826 * float(np.median(np.abs(r[keep] - np.median(r[keep]))))
        new = np.abs(r) <= max(params.outlier_k * mad, params.outlier_floor_s)
        if new.sum() < 2 or np.array_equal(new, keep):
            break
        keep = new
    t0 = int(np.round(np.mean(tc[keep])))
    ts = (tc - t0) / NS
    drift_ok = can_drift and keep.sum() >= 3
    note = None
    if drift_ok:
        a, b, se_a, se_b, _ = _fit_line(ts[keep], ys[keep], params.window_lag_sd_s, 2.0)
        if np.isfinite(se_b) and se_b * 1e6 > params.max_drift_uncertainty_ppm:
            note = (
                f"drift not estimable: {b * 1e6:.0f} ± {se_b * 1e6:.0f} ppm over {np.ptp(ts[keep]):.0f} s "
                f"(uncertainty > {params.max_drift_uncertainty_ppm:g} ppm)"
            )
            drift_ok, b = False, 0.0
            a = float(np.mean(ys[keep]))
    else:
        a, b = float(np.median(ys[keep])), 0.0
        n = int(keep.sum())
        sd = (
            float(np.sqrt((np.sum((ys[keep] - a) ** 2) + 2 * params.window_lag_sd_s**2) / (n + 1)))
            if n >= 3
            else float("nan")
        )
        se_a, se_b = sd / np.sqrt(n) if n >= 3 else float("nan"), float("nan")
    r = ys - a - b * ts
    for w, ri, ki in zip(used, r, keep, strict=True):
        w["residual_ns"] = int(round(ri * NS))
        if not ki:
            w["used"] = False
            w["why"] = "outlier"
    scores = [w["score"] for w in used if w["used"]]
    spread = float(np.std(r[keep], ddof=1)) if keep.sum() >= 3 else float("nan")
    out = {
        "offset_ns": int(off[0] + round(a * NS)),
        "drift_ppm": float(b * 1e6),
        "t0_ns": t0,
        "offset_uncertainty_ns": None if not np.isfinite(se_a) else int(round(se_a * NS)),
        "drift_uncertainty_ppm": None if not np.isfinite(se_b) else float(se_b * 1e6),
        "drift_estimated": bool(drift_ok),
        "score": float(np.median(scores)),
        "residual_spread_ns": None if not np.isfinite(spread) else int(round(spread * NS)),
    }
    if note:
        out["drift_note"] = note
    return out


def assess_quality(record: dict, params: AlignmentParams = AlignmentParams()) -> tuple[str, list[str]]:
    """``("good" | "poor", reasons)`` of an ``imulog.alignment`` record, graded from its residuals and their
    uncertainty (:func:`imulog.process.alignment_quality.grade`; caveats that do not make it poor, such as a
    drift not estimated on a short trial, go into ``record["quality_notes"]``)."""
    from imulog.process.alignment_quality import grade

    quality, reasons, notes = grade(
        record,
        poor_score=params.poor_score,
        poor_spread_s=params.poor_spread_s,
        poor_vector_match=params.poor_vector_match,
    )
    if notes:
        record["quality_notes"] = notes
    return quality, reasons
