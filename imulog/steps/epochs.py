"""``imulog process epochs``: ENMO, MAD, ActiGraph counts and non-wear per epoch, with hourly and daily totals.

Follows the step-window contract (docs/architecture.md, "Step windows"): pass 1 reads the accelerometer window by
window and keeps bounded summaries (means of still 10-s epochs for the calibration, per-axis statistics of 15-min
blocks for non-wear); the reduce fits the calibration and flags non-wear blocks; pass 2 computes the epochs core by
core (cores of whole hours, margins for the counts' resampler) and yields them through ``StreamPieces``. A lab
trial is one window. Outputs (docs/epochs.md): ``/derived/epochs/{E}s/{imu}`` (SignalStream, one row per epoch,
stamped at its start) and the record ``imulog.epochs`` (calibration, non-wear periods, hourly and daily totals).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imulog.console import window_progress
from imulog.model import SignalStream
from imulog.params import check_params
from imulog.steps.common import names_trial

if TYPE_CHECKING:
    from imulog.steps.base import StepOutcome

STEP = "epochs"
ALGORITHM = "enmo-mad-counts-vanhees2013"
RECORD = "imulog.epochs"
COLUMNS = ["enmo_g", "mad_g", "counts_x", "counts_y", "counts_z", "counts_vm", "nonwear", "valid_fraction"]
UNITS = ["g", "g", "counts", "counts", "counts", "counts", "1", "1"]


@dataclass(frozen=True)
class EpochParams:
    """Epoch lengths (s), calibration, non-wear rule (van Hees 2013) and valid-day rule (hours of wear)."""

    epochs_s: tuple[float, ...] = (5.0, 60.0)
    calibrate: bool = True
    calibration_epoch_s: float = 10.0
    still_sd_g: float = 0.013
    nonwear_block_s: float = 900.0
    nonwear_window_s: float = 3600.0
    nonwear_sd_g: float = 0.013
    nonwear_range_g: float = 0.050
    valid_day_hours: float = 16.0
    choi: bool = True  # also Choi et al. 2011 non-wear from the 60-s counts (vector magnitude), in the record
    core_s: float = 3600.0
    margin_s: float = 60.0

    def __post_init__(self) -> None:  # ParamError names the field and its unit; the CLI prints the same line
        if isinstance(self.epochs_s, list):
            object.__setattr__(self, "epochs_s", tuple(self.epochs_s))
        check_params(
            self,
            positive=("epochs_s", "calibration_epoch_s", "nonwear_block_s", "nonwear_window_s", "core_s"),
            non_negative=("still_sd_g", "nonwear_sd_g", "nonwear_range_g", "valid_day_hours", "margin_s"),
        )

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["epochs_s"] = list(self.epochs_s)
        return d


def _samples(seconds: float, rate: float, what: str) -> int:
    n = seconds * rate
    if abs(n - round(n)) > 1e-6 or round(n) < 1:
        step = whole_seconds(rate)
        nominal = round(rate)
        hint = (
            f" (at this rate use epochs of {step} s multiples: --epoch-s {step} --epoch-s 60; in imulog batch "
            f"--set epochs.epochs_s={step},60)"
            if step
            else f" (no epoch of whole seconds fits it: when the device sampled at a nominal {nominal} Hz that its "
            f"time stamps drift from, declare it when converting: imulog convert FILE --rate {nominal})"
        )
        raise ValueError(f"epochs: {what} of {seconds:g} s is not a whole number of samples at {rate:g} Hz{hint}")
    return int(round(n))


def whole_seconds(rate: float) -> int | None:
    """The shortest of 1, 2, 5, 10 s that holds a whole number of samples at ``rate`` Hz (a GENEActiv's 85.7 Hz:
    10 s), or None. Dividing 10 s, it also divides the 10-s calibration epoch and the 15-min non-wear block."""
    return next((k for k in (1, 2, 5, 10) if abs(k * rate - round(k * rate)) <= 1e-6), None)


DECLARED_RATE_TOLERANCE = 0.05  # a .cwa's block clock runs a few percent off its declared rate (docs/epochs.md)


def epoch_rate_hz(channel_meta: dict[str, str], measured_hz: float) -> float:
    """The rate epochs are counted at: the device's declared rate (``meta.declared_rate_hz``, which the converter
    keeps when the time stamps are more than 1 % off it, else ``meta.rate_hz``; e.g. a .cwa's 100 Hz over stamps
    of 98.4 Hz) when it is within :data:`DECLARED_RATE_TOLERANCE` of the measured one, else the measured rate
    snapped to 1/8 Hz when within 0.05 %."""
    import json

    try:
        meta = json.loads(channel_meta.get("meta", "{}"))
        declared = float(meta.get("declared_rate_hz") or meta.get("rate_hz") or 0)
    except (ValueError, TypeError, AttributeError):
        declared = 0.0
    if declared > 0 and abs(declared - measured_hz) <= DECLARED_RATE_TOLERANCE * declared:
        return declared
    snapped = round(measured_hz * 8) / 8
    return snapped if snapped > 0 and abs(snapped - measured_hz) <= 5e-4 * snapped else measured_hz


def epoch_pieces(
    path: str | Path, imu_topic: str, imu: str, p: EpochParams, record: dict[str, Any], start_time: str | None
) -> Iterator[SignalStream]:
    """Yield the epoch channels window by window; fill ``record`` at the end (pass 1, reduce, pass 2)."""
    from imulog.archive import TrialReader
    from imulog.process import epochs as ep
    from imulog.process.metrics import acc_to_g
    from imulog.process.metrics.periods import DAY_S, HOUR_S, wall_clock_origin_ns
    from imulog.steps.common import nominal_rate_hz
    from imulog.steps.sample_window import SampleWindow
    from imulog.steps.windows import plan_windows

    with TrialReader(path) as trial:
        total = trial.channel(imu_topic).sample_count
        first = next(iter(trial.iter_blocks(imu_topic)))
        rate = epoch_rate_hz(trial.channel(imu_topic).metadata, nominal_rate_hz(first.t_ns))
        t0 = int(first.t_ns[0])
        per_cal = _samples(p.calibration_epoch_s, rate, "the calibration epoch")
        per_block = _samples(p.nonwear_block_s, rate, "the non-wear block")
        per_epoch = [_samples(e, rate, "an epoch") for e in p.epochs_s]
        core_s = p.core_s
        for e in (*p.epochs_s, p.nonwear_block_s, p.calibration_epoch_s):
            if abs(core_s / e - round(core_s / e)) > 1e-9:
                raise ValueError(f"epochs: the core of {core_s:g} s is not a whole number of {e:g} s periods")
        # pass 1: summaries (window cores only; no margins needed)
        still, blocks = [], []
        buf = SampleWindow(((b.acc,) for b in trial.iter_blocks(imu_topic)), total)
        for w in window_progress(plan_windows(total, rate, core_s=core_s, margin_s=0.0), "epochs (pass 1 of 2)"):
            (acc,) = buf.take(w.lo, w.hi)
            g = acc_to_g(acc)
            if p.calibrate:
                still.append(ep.still_epoch_means(g, per_cal, p.still_sd_g))
            blocks.append(ep.AxisStats.of_blocks(g, per_block))
        # reduce
        cal = ep.fit_calibration(np.concatenate(still)) if p.calibrate and still else ep.Calibration(reason="off")
        stats = ep.AxisStats.concat(blocks)
        window_blocks = max(1, int(round(p.nonwear_window_s / p.nonwear_block_s)))
        nonwear = ep.nonwear_blocks(stats, window_blocks=window_blocks, sd_g=p.nonwear_sd_g, range_g=p.nonwear_range_g)
        # pass 2: epochs core by core
        counts_ok = True
        try:
            up, down = ep.counts_factors(rate)
        except ValueError:
            counts_ok = False
        filt = ep.CountsFilter()
        hour0, hour_label = wall_clock_origin_ns(t0, start_time, HOUR_S)
        day0, day_label = wall_clock_origin_ns(t0, start_time, DAY_S)
        hourly: dict[int, list[float]] = {}
        daily: dict[int, list[float]] = {}
        minute_counts: list[np.ndarray] = []  # 60-s vector-magnitude counts for Choi's rule (a week: 10,080)
        minute_starts: list[np.ndarray] = []
        dt_ns = 1e9 / rate
        buf = SampleWindow(((b.t_ns, b.acc) for b in trial.iter_blocks(imu_topic)), total)
        for w in window_progress(plan_windows(total, rate, core_s=core_s, margin_s=p.margin_s), "epochs (pass 2 of 2)"):
            t, acc = buf.take(w.lo, w.hi)
            g = cal.apply(acc_to_g(acc))
            core = g[w.core_slice]
            tc = t[w.core_slice]
            if counts_ok:
                filled = np.where(np.isfinite(g), g, np.nanmedian(g, axis=0) if np.isfinite(g).any() else 0.0)
                g30 = ep.to_30hz(filled, rate)
                a = (w.core_lo - w.lo) * up // down
                b = a + (w.core_hi - w.core_lo) * up // down
                trimmed = filt(g30[a:b])
            for e_s, per in zip(p.epochs_s, per_epoch, strict=True):
                enmo, mad, valid = ep.epoch_enmo_mad(core, per)
                k = len(enmo)
                if counts_ok:
                    c = ep.counts_per_epoch(trimmed, e_s)[:k]
                    c = np.vstack([c, np.zeros((k - len(c), 3))]) if len(c) < k else c
                    vm = np.sqrt((c * c).sum(axis=1))
                else:
                    c, vm = np.full((k, 3), np.nan), np.full(k, np.nan)
                first_index = w.core_lo + np.arange(k) * per
                flag = nonwear[first_index // per_block].astype(np.float64)
                t_start = tc[np.arange(k) * per]
                if counts_ok and e_s == 60.0:
                    minute_counts.append(vm)
                    minute_starts.append(t_start)
                yield SignalStream(
                    f"/derived/epochs/{e_s:g}s/{imu}",
                    t_start,
                    COLUMNS,
                    UNITS,
                    np.column_stack([enmo, mad, c, vm, flag, valid]),
                    frame_id=imu,
                )
                if e_s == p.epochs_s[-1]:
                    n_samples = valid * np.minimum(per, w.core_hi - first_index)
                    for rows, origin, period in ((hourly, hour0, HOUR_S), (daily, day0, DAY_S)):
                        idx = ((t_start - origin) // int(period * 1e9)).astype(np.int64)
                        for i in np.unique(idx):
                            m = idx == i
                            wear = m & (flag == 0)
                            row = rows.setdefault(int(i), [0.0, 0.0, 0.0, 0.0])
                            row[0] += float(n_samples[m].sum() / rate)  # recorded s
                            row[1] += float(n_samples[wear].sum() / rate)  # worn s
                            row[2] += float(np.nansum(enmo[wear] * n_samples[wear]))  # ENMO g x samples
                            row[3] += float(np.nansum(vm[wear])) if counts_ok else 0.0
        last_t = int(t[-1]) if total else t0
    record.update(
        {
            "imu": imu_topic,
            "rate_hz": round(rate, 4),
            "duration_s": round((last_t - t0 + dt_ns) / 1e9, 3),
            "epochs_s": list(p.epochs_s),
            "calibration": cal.to_dict(),
            "counts": "Brønd 2017 / Neishabouri 2022" if counts_ok else f"not computed: {rate:g} Hz",
            "nonwear": _periods(nonwear, t0, p.nonwear_block_s, rate, per_block, total),
            "by_hour": _rows(hourly, hour0, HOUR_S, rate, None, hour_label),
            "by_day": _rows(daily, day0, DAY_S, rate, p.valid_day_hours, day_label),
        }
    )
    record["valid_days"] = sum(1 for r in record["by_day"] if r["valid"])
    if p.choi:
        record["nonwear_choi"] = _choi_record(minute_counts, minute_starts, counts_ok, 60.0 in p.epochs_s)
    if day_label is not None:
        record["first_day"] = day_label.date().isoformat()


def _choi_record(counts: list[np.ndarray], starts: list[np.ndarray], counts_ok: bool, has_minutes: bool) -> Any:
    """Choi 2011 non-wear periods ``[start ns, end ns]`` from the 60-s counts, or why they were not computed."""
    from imulog.process.epochs import choi_nonwear
    from imulog.process.gaps import runs_of

    if not has_minutes:
        return "not computed: needs a 60 s epoch"
    if not counts_ok:
        return "not computed: no counts at this rate"
    vm, t = (np.concatenate(x) if x else np.zeros(0) for x in (counts, starts))
    return [[int(t[a]), int(t[b - 1]) + 60_000_000_000] for a, b in runs_of(choi_nonwear(vm))]


def _periods(flags: np.ndarray, t0: int, block_s: float, rate: float, per_block: int, total: int) -> list[list[int]]:
    """Non-wear periods as [start ns, end ns] on the device clock."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    out = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        end_sample = min(total, b * per_block)
        out.append([int(t0 + a * per_block / rate * 1e9), int(t0 + end_sample / rate * 1e9)])
    return out


def _rows(
    rows: dict[int, list[float]], origin: int, period_s: float, rate: float, valid_h: float | None, label: Any = None
) -> list:
    """Hourly or daily rows: start (device clock ns, and wall-clock time when the trial's start is known), hours
    recorded and worn, mean ENMO over the worn epochs (mg), counts (vector magnitude) summed over them."""
    from datetime import timedelta

    out = []
    for i in sorted(rows):
        rec_s, wear_s, enmo_sum, counts = rows[i]
        r = {
            "start": None if label is None else (label + timedelta(seconds=i * period_s)).isoformat(),
            "start_ns": int(origin + i * period_s * 1e9),
            "recorded_h": round(rec_s / 3600, 4),
            "wear_h": round(wear_s / 3600, 4),
            "enmo_mean_mg": round(1000 * enmo_sum / (wear_s * rate), 4) if wear_s > 0 else None,
            "counts_vm_sum": round(counts, 3),
        }
        if valid_h is not None:
            r["valid"] = bool(wear_s / 3600 >= valid_h)
        out.append(r)
    return out


@names_trial
def run_epochs(
    path: str | os.PathLike[str], *, imu: str | None = None, params: EpochParams | None = None, force: bool = False
) -> StepOutcome:
    """Epochs of one IMU (``imulog process epochs``): appends ``/derived/epochs/{N}s/IMU`` for each epoch length in
    ``params.epochs_s`` (ENMO and MAD in g, ActiGraph counts, wear) and the ``imulog.epochs`` record (hourly and
    daily totals). Returns the :class:`~imulog.steps.base.StepOutcome`; :class:`~imulog.steps.common.StepError`
    names ``path``."""
    from imulog.archive import TrialReader
    from imulog.archive.streaming import StreamPieces
    from imulog.steps.base import StepResult, run_step
    from imulog.steps.common import pick_imu, record_for

    p = params or EpochParams()
    with TrialReader(path) as trial:
        name = pick_imu(trial.topics(), imu)
        record_name = record_for(RECORD, name, trial.topics(), trial.metadata)
    imu_topic = f"/imu/{name}"

    def compute(trial) -> StepResult:
        start_time = (trial.metadata.get("imulog.trial") or {}).get("start_time")
        record: dict[str, Any] = {}
        pieces = StreamPieces(
            topics=[f"/derived/epochs/{e:g}s/{name}" for e in p.epochs_s],
            pieces=lambda: epoch_pieces(path, imu_topic, name, p, record, str(start_time) if start_time else None),
        )
        return StepResult(streams=[pieces], metadata={record_name: record})

    return run_step(
        path,
        step=f"{STEP}:{name}",
        algorithm=ALGORITHM,
        params={"imu": name, **p.to_dict()},
        inputs=[imu_topic],
        metadata_inputs=("imulog.trial",),
        compute=compute,
        force=force,
    )
