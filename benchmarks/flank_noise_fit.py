"""Step 7's acceleration flank fit on a ramp in low-passed noise: ordinary against generalised least squares
(issue 31 point 1, fourteenth round).

A gravity-free acceleration rising linearly from rest at a known sample (``--slope`` m/s^2 per sample) plus white
noise (``--noise`` m/s^2 per sample, the median real device's by default), low-passed as step 1 does (zero-phase
2nd-order Butterworth at ``--cutoff`` Hz), fitted by :func:`~imulog.process.segmentation.flanks.flank_zero` from the
sample where ``|a|`` first crosses the level: the default (ordinary least squares), with the rest's level
(``flank_rest_level``), with the low-passed noise's correlation (``flank_noise``) and with both. Prints per fit the
bias and sd of ``t0`` (samples) and how many draws end more than 0.05 s and 0.1 s off.

    python benchmarks/flank_noise_fit.py
    python benchmarks/flank_noise_fit.py --cutoff 25 --noise 0.02
"""

from __future__ import annotations

import argparse

import numpy as np

from imulog.process.segmentation.boundaries import lowpass_axes
from imulog.process.segmentation.flank_noise import FlankNoiseParams
from imulog.process.segmentation.flanks import flank_zero
from imulog.process.segmentation.hand_params import HandParams


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=114.0, help="sampling rate (Hz)")
    ap.add_argument("--cutoff", type=float, default=12.1, help="step 1's cut-off (Hz; 12.1 at the devices' noise)")
    ap.add_argument("--noise", type=float, default=0.033, help="white accelerometer noise (m/s^2 per sample)")
    ap.add_argument("--slope", type=float, default=0.004, help="the flank's rise (m/s^2 per sample)")
    ap.add_argument("--level", type=float, default=0.05, help="step 5's motion level (m/s^2)")
    ap.add_argument("--draws", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    n, t0 = 260, 120.0
    x = np.arange(n, dtype=float)
    ramp = np.zeros((n, 3))
    ramp[:, 0] = np.minimum(args.slope * np.maximum(x - t0, 0.0), 6 * args.level)
    hp = HandParams()  # step 7's stretches as _extrapolated takes them
    noise = FlankNoiseParams(args.cutoff, args.rate, hp.flank_noise_band_hz)
    rest = int(round(hp.rest_window_s * args.rate))
    back, span = round(hp.max_extrapolation_s * args.rate), round(hp.flank_search_s * args.rate)
    smooth = max(1, round(0.05 * args.rate))
    fits = {"ordinary (default)": (0, None), "rest's level": (rest, None), "noise's correlation": (0, noise)}
    fits["both"] = (rest, noise)
    errors: dict[str, list[float]] = {k: [] for k in fits}
    rng = np.random.default_rng(args.seed)
    for _ in range(args.draws):
        a = lowpass_axes(ramp + rng.normal(0.0, args.noise, (n, 3)), args.rate, args.cutoff)
        above = np.flatnonzero(np.linalg.norm(a[100:], axis=1) > args.level)
        if len(above) == 0:
            continue
        first = 100 + int(above[0])
        for name, (samples, model) in fits.items():
            top = hp.flank_top_n_level * args.level
            z = flank_zero(a, first, args.level, top, span, back, smooth, None, samples, model)
            errors[name].append(np.nan if z is None else z - t0)
    print(f"{args.draws} draws, {args.rate:g} Hz, cut-off {args.cutoff:g} Hz, noise {args.noise:g} m/s^2")
    print("| fit | bias (samples) | sd (samples) | off > 0.05 s | off > 0.1 s |")
    print("|---|---|---|---|---|")
    for name, err in errors.items():
        e = np.asarray(err)
        big = [int(np.sum(np.abs(e) > s * args.rate)) for s in (0.05, 0.1)]
        print(f"| {name} | {np.nanmean(e):+.2f} | {np.nanstd(e):.2f} | {big[0]} | {big[1]} |")


if __name__ == "__main__":
    main()
