"""The accelerometer's and gyroscope's white noise at still periods of real device recordings, against the simulator's
(issue 31 point 1: is the simulator's noise what real wrist IMUs show?).

    python benchmarks/device_noise.py                       # the real files in ../shared/data
    python benchmarks/device_noise.py --data DIR --json noise.json

Every file is read through imulog's own converters (``imulog.converters.registry.convert_file``); every IMU stream
of it is one row. Still periods by one rule (:mod:`imulog.process.noise_level`): non-overlapping 1-s windows whose
detrended variance (the gyroscope's where the stream has one, else the accelerometer's) is at most twice the
quietest window's. Per channel: the per-sample sd (rms over the axes), the density that sd implies for white noise
up to the Nyquist frequency, and the density measured in 1-10 Hz (Welch, capped at 0.4 x the rate), the band a
drinking phase's flanks live in; the smallest step the file holds (``Q``: the sd is under one step, so the noise
is not resolved). The simulator's row is the same estimator on the opening still period of a default simulated
trial (``imulog.simulate.simulate("r2g")``: ``ImuParams.acc_noise_mps2`` 0.02 m/s^2 and ``gyr_noise_dps`` 0.1 deg/s
per sample at 114.9 Hz, LSM9DS1 quantisation).
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

from imulog.process.noise_level import G0, NoiseLevel, StillParams, noise_level, still_windows

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
PARAMS = StillParams(window_s=1.0)

# (device, file under the data folder, where it was worn / held, from the sources' READMEs)
FILES = [
    ("Axivity AX3", "devices/axivity_cwa/ax3_sample.cwa", "wrist-class logger, placement not stated"),
    ("Axivity AX6", "devices/axivity_cwa/ax6_sample.cwa", "wrist-class logger, placement not stated"),
    ("Axivity AX3 (OMGUI CSV)", "devices/axivity_csv/ax3_testfile_unix_timestamps.csv", "2-s excerpt"),
    ("GENEActiv 1.1", "devices/geneactiv_bin/GENEActiv_testfile.bin", "wrist logger, placement not stated"),
    ("ActiGraph GT9X Link", "devices/actigraph_gt3x/example.gt3x", "waist"),
    ("Movella DOT", "devices/movella_dot_csv/bei_D4CA6EF17860_20210830_170505.csv", "body-worn, placement not stated"),
    ("APDM Opal", "devices/apdm_csv/imuData01.csv", "pendulum test: 'static' sensor and three on the pendulum"),
    ("Delsys Trigno Mini", "devices/delsys_trigno/truncated_trigno_sample.csv", "EMG sensor with IMU, 2-s excerpt"),
    ("NilsPod", "devices/nilspod/NilsPodX-6F13_20210109_162824.bin", "6-s sample session"),
    ("Xsens MTw", "devices/xsens_mtmanager/MT_012005D6_031-000_00B421AF.txt", "OpenSense trial"),
    ("Xsens MTw", "devices/xsens_mtmanager/MT_012005D6_031-000_00B4227B.txt", "OpenSense trial"),
    ("Empatica E4", "devices/empatica_e4/ACC.csv", "wrist"),
    ("myon aktos-t (BROAD)", "broad/02_undisturbed_slow_rotation_B.hdf5", "hand-held, rests at start and end"),
    ("myon aktos-t (BROAD)", "broad/05_undisturbed_slow_rotation_with_breaks_B.hdf5", "hand-held, rests between"),
    ("myon aktos-t (BROAD)", "broad/14_undisturbed_slow_translation_with_breaks_B.hdf5", "hand-held, rests between"),
    ("x-io (Fusion example)", "imu_text/fusion_sensor_data.csv", "x-io example data"),
    ("Shimmer (Consensys)", "imu_text/shimmer_consensys_export.csv", "1.8-s excerpt"),
    ("gaitmap foot IMU", "gaitmap_foot/imu_sample.csv", "foot, walking with standing"),
]


def stream_rate_hz(t_ns: np.ndarray) -> float:
    """Sampling rate (Hz) from the median step of the time stamps (robust to gaps and dropped samples)."""
    return float(1e9 / np.median(np.diff(np.asarray(t_ns, dtype=np.float64))))


def measure_stream(imu, params: StillParams = PARAMS) -> dict | None:
    """Noise of one :class:`imulog.model.ImuStream` (None when it has no still window): rate, seconds used and a
    :class:`NoiseLevel` per channel present."""
    rate = stream_rate_hz(imu.t_ns)
    motion = imu.gyr if imu.gyr is not None else imu.acc
    windows = still_windows(motion, rate, params)
    if len(windows) == 0:
        return None
    out: dict = {"rate_hz": rate, "windows": len(windows), "total_s": len(imu.t_ns) / rate}
    if imu.acc is not None:
        out["acc"] = noise_level(imu.acc, rate, windows, params)
    if imu.gyr is not None:
        out["gyr"] = noise_level(imu.gyr, rate, windows, params)
    return out


def simulator_row(params: StillParams = PARAMS) -> dict:
    """The same estimator on the opening still period (30 s) of a default simulated R2G trial."""
    from imulog.simulate import simulate

    sim = simulate("r2g", seed=0, subject=0, repetitions=1)
    imu = sim.recording.imus[0]
    first_move = int(np.argmax(~sim.truth.imu_static_mask))
    cut = type(imu)(name=imu.name, t_ns=imu.t_ns[:first_move], acc=imu.acc[:first_move], gyr=imu.gyr[:first_move])
    return measure_stream(cut, params)


def _acc_cells(lv: NoiseLevel | None) -> list[str]:
    if lv is None:
        return ["-"] * 4
    return [
        f"{lv.step / G0 * 1e3:.3g}" if lv.step > 0 else "-",
        f"{lv.sd / G0 * 1e3:.2f}" + (" Q" if lv.quantisation_limited else ""),
        f"{lv.density_white / G0 * 1e6:.0f}",
        f"{lv.density_band / G0 * 1e6:.0f}",
    ]


def _gyr_cells(lv: NoiseLevel | None) -> list[str]:
    if lv is None:
        return ["-"] * 4
    d = np.degrees
    return [
        f"{d(lv.step) * 1e3:.3g}" if lv.step > 0 else "-",
        f"{d(lv.sd):.3f}" + (" Q" if lv.quantisation_limited else ""),
        f"{d(lv.density_white):.4f}",
        f"{d(lv.density_band):.4f}",
    ]


MIN_WINDOWS = 5  # still 1-s windows: a stream with fewer is an upper bound (its quietest windows may still move)
SIM_RATE_HZ = 114.9  # Hz: the simulator's default IMU rate


def summary(real: list[dict], sim: dict) -> None:
    """Where the simulator's 1-10 Hz density sits among the real devices: one value per device (the median over
    its streams that have at least ``MIN_WINDOWS`` still windows and are resolved by their LSB), and each as the
    per-sample sd of white noise at the simulator's rate (what ``acc_noise_mps2`` / ``gyr_noise_dps`` would be)."""
    for ch, unit, scale, per_sample in (
        ("acc", "ug/rtHz", 1e6 / G0, "acc_noise_mps2"),
        ("gyr", "deg/s/rtHz", np.degrees(1.0), "gyr_noise_dps"),
    ):
        per_device: dict[str, list[float]] = {}
        short, limited = [], []
        for r in real:
            if ch not in r:
                continue
            lv = r[ch]
            name = f"{r['device']} {r['stream']}"
            if lv.quantisation_limited:
                limited.append(name)
            elif r["windows"] < MIN_WINDOWS:
                short.append(name)
            else:
                per_device.setdefault(r["device"], []).append(lv.density_band)
        dev = {k: float(np.median(v)) for k, v in per_device.items()}
        s = sim[ch].density_band
        eq = np.sqrt(SIM_RATE_HZ / 2.0) * (1.0 if ch == "acc" else np.degrees(1.0))
        vals = np.array(sorted(dev.values()))
        print(
            f"\n{ch}: 1-10 Hz density per device ({len(dev)} devices with >= {MIN_WINDOWS} still 1-s windows, resolved), "
            f"and as {per_sample} at {SIM_RATE_HZ} Hz:"
        )
        for k, v in sorted(dev.items(), key=lambda kv: kv[1]):
            print(f"  {k}: {v * scale:.4g} {unit} ({v * eq:.4g} per sample)")
        print(
            f"  simulator: {s * scale:.4g} {unit} ({s * eq:.4g} per sample); {int(np.sum(vals < s))} of {len(vals)} "
            f"devices quieter; median of the devices {np.median(vals) * scale:.4g} {unit} = "
            f"{np.median(vals) / s:.2f} x the simulator ({np.median(vals) * eq:.4g} per sample)"
        )
        if short:
            print(f"  under {MIN_WINDOWS} still windows (upper bounds, not counted): {', '.join(short)}")
        if limited:
            print(f"  quantisation-limited (sd under one step, not counted): {', '.join(limited)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DATA, help="folder of the real recordings (shared/data)")
    ap.add_argument("--json", type=Path, help="write the rows here")
    args = ap.parse_args()

    from imulog.converters.registry import convert_file

    rows = []
    for device, rel, where in FILES:
        path = args.data / rel
        if not path.exists():
            print(f"skipped (missing): {rel}")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = convert_file(path)
        for imu in rec.imus:
            m = measure_stream(imu)
            if m is None:
                print(f"skipped (no still window): {rel} {imu.name}")
                continue
            stream = Path(rel).name.split("_")[0] if rel.startswith("broad/") else imu.name
            rows.append({"device": device, "file": rel, "stream": stream, "where": where, **m})
    sim = {"device": "simulator default (LSM9DS1 model)", "file": "simulate('r2g') opening static", "stream": "imu"}
    rows.append({**sim, "where": "acc_noise_mps2 0.02, gyr_noise_dps 0.1 per sample", **simulator_row()})

    print(
        "\n| device | stream | rate Hz | still s (of) | acc step mg | acc sd mg | acc white ug/rtHz | acc 1-10 Hz ug/rtHz "
        "| gyr step mdps | gyr sd deg/s | gyr white deg/s/rtHz | gyr 1-10 Hz deg/s/rtHz |"
    )
    print("|" + "---|" * 12)
    for r in rows:
        cells = [
            r["device"],
            r["stream"],
            f"{r['rate_hz']:.1f}",
            f"{r['acc'].still_s if 'acc' in r else r['gyr'].still_s:.0f} ({r['total_s']:.0f})",
            *_acc_cells(r.get("acc")),
            *_gyr_cells(r.get("gyr")),
        ]
        print("| " + " | ".join(cells) + " |")

    summary(rows[:-1], rows[-1])
    if args.json:
        out = [
            {
                **{k: v for k, v in r.items() if k not in ("acc", "gyr")},
                **{ch: vars(r[ch]) for ch in ("acc", "gyr") if ch in r},
            }
            for r in rows
        ]
        args.json.write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
