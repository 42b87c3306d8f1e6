"""The metrics step's one implementation: Doshi's metrics over bounded windows of the accelerometer (any length).

The accelerometer is read block by block and evaluated on cores of about an hour (``WindowParams.core_s``), each
read with a margin that covers every filter's reach (the moving averages of activity method 2 and of the
distance, the 0.1 s windows of arm usage); the cores are cut at multiples of the distance window, so every
distance window lies in one core. A recording within one core is one window: the whole computation. What spans
cores is carried over:

* arm use: the 0.1 s windows are numbered from the recording's first sample and each is counted in the core that
  holds its first sample;
* activity method 1 (sign changes about the mean): the mean comes from a first pass over the recording (one
  window: the mean of the bridged window itself, as the whole computation);
* activity method 2 (dead periods): an activity still open at the end of a core continues into the next;
* the distance histogram, its windows and the per-hour / per-day summaries add up counts.

``activity.method1`` keeps counts only (with noise its intervals number in the millions over a week). Memory:
one core and its margins.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from imulog.console import window_progress
from imulog.model import Intervals, SignalStream
from imulog.numeric import finite_rows

# the distance (cm) stored as counts on a 2**-10 cm grid (at most 5 um off, against the published 1 cm histogram
# bins; 1.3 bytes a sample compressed instead of float32's 3.8: docs/schemas.md, tests/test_storage_float32.py)
DISTANCE_GRID = {"precision": "quantized", "quantum": repr(2.0**-10)}


class DeadPeriodStitcher:
    """:func:`imulog.process.metrics.activity.dead_period_intervals` over consecutive pieces of one signal.

    Given each piece's sample times, it also keeps every kept interval's start time and end time (the time of
    the sample after its last non-zero one, or of that one at the recording's end, as the step stores them).
    """

    def __init__(self, dead_samples: int, min_samples: int = 1, keep: bool = True) -> None:
        self.dead = dead_samples
        self.min = min_samples
        self.keep = keep  # False: count the intervals only (a week's per-axis activities are many)
        self.count = 0
        self.start: int | None = None  # global index of the open activity's first non-zero sample
        self.last: int | None = None  # and of its last one so far
        self.start_t: int | None = None
        self.end_t: int | None = None  # time the open activity would end at (sample after ``last``, or ``last``)
        self.closed: list[tuple[int, int]] = []
        self.closed_t: list[tuple[int | None, int | None]] = []

    def add(self, nonzero_index: np.ndarray, t_ns: np.ndarray | None = None, t_first: int = 0) -> None:
        """Global indices (sorted) of the next piece's non-zero samples; ``t_ns``: times of the global samples
        ``t_first ...`` (the piece with its overlaps)."""
        idx = np.asarray(nonzero_index, np.int64)
        if not len(idx):
            return

        def time(i: int) -> int | None:
            k = i - t_first
            return int(t_ns[k]) if t_ns is not None and 0 <= k < len(t_ns) else None

        if self.last is not None:
            idx_all = np.concatenate([[self.last], idx])
        else:
            self.start, self.start_t = int(idx[0]), time(int(idx[0]))
            idx_all = idx
        split = np.flatnonzero(np.diff(idx_all) - 1 >= self.dead)
        for k in split:  # an activity ends at idx_all[k]; the next starts at idx_all[k + 1]
            last = int(idx_all[k])
            end_t = time(last + 1)
            self._close(last, self.end_t if end_t is None else end_t)
            self.start = int(idx_all[k + 1])
            self.start_t = time(self.start)
        self.last = int(idx_all[-1])
        self.end_t = time(self.last + 1)
        if self.end_t is None:  # the recording's last sample
            self.end_t = time(self.last)

    def _close(self, last: int, end_t: int | None) -> None:
        if self.start is not None and last + 1 - self.start >= self.min:
            self.count += 1
            if self.keep:
                self.closed.append((self.start, last + 1))
                self.closed_t.append((self.start_t, end_t))

    def finish(self) -> np.ndarray:
        if self.last is not None:
            self._close(self.last, self.end_t)
            self.start = self.last = None
        return np.array(self.closed, dtype=np.int64).reshape(-1, 2)

    def times(self) -> tuple[np.ndarray, np.ndarray]:
        """(start ns, end ns) of the kept intervals (from the times given to :meth:`add`)."""
        if not self.closed_t:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        t = np.array(self.closed_t, dtype=np.int64)
        return t[:, 0], t[:, 1]


def metric_plan(total: int, rate_hz: float, params: Any, windows: Any) -> list:
    """The metrics windows: cores of ``windows.core_s`` and margins of ``windows.margin_s`` (at least the moving
    averages' reach) rounded up to whole distance windows, so that every distance window lies in one core."""
    from imulog.steps.windows import plan_windows

    win = max(1, int(round(params.distance().window_s * rate_hz)))
    m = params.activity(rate_hz).m_samples
    core = win * max(1, int(np.ceil(windows.core_s * rate_hz / win)))
    margin = win * max(1, int(np.ceil(max(windows.margin_s * rate_hz, 2 * m + 2) / win)))
    return plan_windows(total, rate_hz, core_s=core / rate_hz, margin_s=margin / rate_hz)


def metric_pieces(
    blocks: Callable[[], Iterator[tuple[np.ndarray, np.ndarray]]],
    total: int,
    imu_topic: str,
    imu: str,
    params: Any,
    record: dict[str, Any],
    *,
    start_time: str | None = None,
    gaps: Any = None,
    windows: Any = None,
) -> Iterator[Any]:
    """Yield the distance channel core by core, then the activity intervals; fill ``record`` at the end.

    ``blocks()`` yields the recording's ``(t_ns, acc)`` in order (called twice: a first pass for the rate, the
    means and the plan); ``windows`` a :class:`~imulog.steps.windows.WindowParams` (default: an hour, 10 s margins
    rounded up to whole distance windows)."""
    from imulog.heap import reuse_heap
    from imulog.process.gaps import prepare
    from imulog.process.metrics import ArmUsageParams, acc_to_g, arm_usage
    from imulog.process.metrics.activity import high_passed_noise_removed
    from imulog.process.metrics.arm_usage import to_reference_rate
    from imulog.process.metrics.distance import histogram_percent, weighted_area, windowed_distance
    from imulog.process.metrics.periods import DAY_S, HOUR_S, PeriodAccumulator, wall_clock_origin_ns
    from imulog.steps.common import nominal_rate_hz
    from imulog.steps.sample_window import SampleWindow
    from imulog.steps.windows import WindowParams

    p = params
    c = windows or WindowParams(core_s=3600.0, margin_s=10.0)
    # pass 1: the mean of each axis (activity method 1) and the first samples (rate, origin)
    sums, counts, first_t, rate = np.zeros(3), np.zeros(3), None, None
    for t_block, acc_block in blocks():
        a = acc_to_g(acc_block)
        ok = np.isfinite(a)
        if ok.all():  # no gap in the block (one fast pass): the same sums without the masked copy
            sums += a.sum(axis=0)
            counts += len(a)
        else:
            sums += np.where(ok, a, 0.0).sum(axis=0)
            counts += ok.sum(axis=0)
        if first_t is None:
            first_t = int(t_block[0])
            rate = nominal_rate_hz(t_block)
    mean = sums / np.maximum(counts, 1)
    act = p.activity(rate)
    dist_p = p.distance()
    win = max(1, int(round(dist_p.window_s * rate)))
    plan = metric_plan(total, rate, p, c)
    core = plan[0].core_hi - plan[0].core_lo
    if len(plan) > 1:
        reuse_heap()  # the same temporaries core after core: reuse their pages (imulog.heap)
    usage_p = ArmUsageParams(p.noise_level_g, p.arm_usage_rate_hz)
    decimated = rate > 1.5 * usage_p.reference_rate_hz  # as arm_usage decides
    width_ns = 1e9 / usage_p.reference_rate_hz
    stitchers = [DeadPeriodStitcher(act.dead_samples, act.min_activity_samples, keep=j == 3) for j in range(4)]
    centres = dist_p.bin_centres_cm
    hist = np.zeros(len(centres))
    window_ends: list[np.ndarray] = []
    active_windows = np.zeros(3)
    active_any_windows = 0
    valid_windows = 0
    m1_axis = np.zeros(3, np.int64)
    m1_any = 0
    last_sign: np.ndarray | None = None
    missing = 0
    reports = []
    periods = {
        key: PeriodAccumulator(*wall_clock_origin_ns(first_t, start_time, period_s), period_s, centres)
        for key, period_s in (("by_hour", HOUR_S), ("by_day", DAY_S))
    }
    buf = SampleWindow(blocks(), total)
    last_t = first_t
    for w in window_progress(plan, "metrics"):
        core_start, core_end, lo = w.core_lo, w.core_hi, w.lo
        t, acc = buf.take(w.lo, w.hi)
        raw_g = acc_to_g(acc)
        (acc_g,), report = prepare([raw_g], gaps)
        reports.append(report)
        if len(plan) == 1:  # the whole recording: the mean of its bridged samples, as activity_count_sign
            mean = np.nanmean(acc_g, axis=0)
        k0, k1 = core_start - lo, core_end - lo
        unknown = ~finite_rows(acc_g)
        missing += int((~finite_rows(raw_g[k0:k1])).sum())
        # arm use: the recording's 0.1 s windows (numbered from its first sample), each counted in the core that
        # holds its first sample; at or below the reference rate, samples are the windows
        if decimated:
            origin = first_t + int((int(t[0]) - first_t) // width_ns * width_ns)
            usage = arm_usage(acc_g, usage_p, t_ns=t, origin_ns=origin)
            windows, index = to_reference_rate(acc_g, t, usage_p.reference_rate_hz, origin)
            starts = np.flatnonzero(np.concatenate([[True], index[1:] != index[:-1]]))
            in_core = starts[(starts >= k0) & (starts < k1)]
            valid = finite_rows(windows[index[in_core]])
            counted = usage.active[in_core][valid]
        else:
            usage = arm_usage(acc_g, usage_p, t_ns=t)
            counted = usage.active[k0:k1][~unknown[k0:k1]]
        active = usage.active
        active_windows += counted.sum(axis=0)
        active_any_windows += int(counted.any(axis=1).sum())
        valid_windows += len(counted)
        # activity method 1: sign changes about the recording's mean
        sign = np.where(acc_g[k0:k1] > mean, 1, -1)
        previous = sign[:-1] if last_sign is None else np.concatenate([last_sign[None, :], sign[:-1]])
        change = sign[1:] != previous if last_sign is None else sign != previous
        m1_axis += change.sum(axis=0)
        m1_any += int(change.any(axis=1).sum())
        last_sign = sign[-1]
        # activity method 2: non-zero samples of each column, stitched across cores
        h = high_passed_noise_removed(acc_g, act)[k0:k1]
        h[unknown[k0:k1]] = 0.0
        for j, stitcher in enumerate(stitchers):
            stitcher.add(core_start + np.flatnonzero(h[:, j] != 0), t if j == 3 else None, lo)
        # distance: every window inside this core (cores start at multiples of the window)
        d_all = 100.0 * np.sqrt((windowed_distance(acc_g, rate, dist_p) ** 2).sum(axis=1))[k0:k1]
        ends = np.arange(win - 1, len(d_all), win)
        if core_end == total and (not len(ends) or ends[-1] != len(d_all) - 1):
            ends = np.append(ends, len(d_all) - 1)  # the recording's last, partial window
        window_ends.append(d_all[ends])
        d_cm = np.where(unknown[k0:k1], np.nan, d_all)
        finite_d = d_cm[np.isfinite(d_cm)]
        if len(finite_d):
            hist += histogram_percent(finite_d, dist_p) * len(finite_d) / 100.0
        tc = t[k0:k1]
        for acc_ in periods.values():
            acc_.add(tc, ~unknown[k0:k1], active[k0:k1].any(axis=1), d_cm)
        last_t = int(t[k1 - 1])
        yield SignalStream(
            f"/derived/metrics/distance/{imu}",
            tc,
            ["distance_cm"],
            ["cm" if p.acc_unit == "m/s^2" else "cm (Doshi A.3, integrated in g)"],
            d_cm[:, None],
            frame_id=imu,
            attrs=dict(DISTANCE_GRID),
        )
    for stitcher in stitchers[:3]:
        stitcher.finish()
    per_axis = [s.count for s in stitchers[:3]]
    overall = stitchers[3].finish()
    starts_t, ends_t = stitchers[3].times()
    for acc_ in periods.values():
        acc_.add_activity_starts(starts_t)
    yield Intervals(
        topic=f"/derived/metrics/activity/{imu}",
        start_ns=starts_t,
        end_ns=ends_t,
        labels=["activity"] * len(overall),
        task_index=np.arange(1, len(overall) + 1),
    )
    n_hist = hist.sum()
    hist_percent = 100.0 * hist / n_hist if n_hist else hist
    windows_cm = np.concatenate(window_ends) if window_ends else np.zeros(0)
    durations = (overall[:, 1] - overall[:, 0]) / rate
    r = _round
    record.update(
        {
            "imu": imu_topic,
            "rate_hz": r(rate, 4),
            "duration_s": r((last_t - first_t) / 1e9, 4),
            "arm_usage.noise_level_g": p.noise_level_g,
            "arm_usage.rate_hz": usage_p.reference_rate_hz if rate > 1.5 * usage_p.reference_rate_hz else rate,
            "arm_usage.x_percent": r(100 * active_windows[0] / max(valid_windows, 1), 4),
            "arm_usage.y_percent": r(100 * active_windows[1] / max(valid_windows, 1), 4),
            "arm_usage.z_percent": r(100 * active_windows[2] / max(valid_windows, 1), 4),
            "arm_usage.overall_percent": r(100 * active_any_windows / max(valid_windows, 1), 4),
            "activity.method1.count": m1_any,
            "activity.method1.per_axis": m1_axis.tolist(),
            "activity.method2.count": len(overall),
            "activity.method2.per_axis": per_axis,
            "activity.method2.m_samples": act.m_samples,
            "activity.method2.dead_samples": act.dead_samples,
            "activity.method2.noise_floor_g": p.noise_floor_g,
            "activity.method2.min_activity_samples": act.min_activity_samples,
            "activity.method2.total_s": r(durations.sum(), 4),
            "activity.method2.mean_s": r(durations.mean(), 4) if len(durations) else None,
            "distance.window_s": p.window_s,
            "distance.acc_unit": p.acc_unit,
            "distance.weighted_area": r(weighted_area(hist_percent, centres, p.weight_start_cm), 4),
            "distance.weight_start_cm": p.weight_start_cm,
            "distance.bin_width_cm": dist_p.bin_width_cm,
            "distance.histogram_percent": [r(v, 4) for v in hist_percent],
            "distance.window_median_cm": r(np.median(windows_cm), 4) if len(windows_cm) else None,
            "distance.window_max_cm": r(np.max(windows_cm), 4) if len(windows_cm) else None,
        }
    )
    if len(plan) > 1:
        record["computed"] = f"core by core ({len(plan)} cores of {core / rate:g} s, bounded memory)"
    span = (last_t - first_t) / 1e9
    for key, acc_ in periods.items():
        if span > acc_.period_s:
            record[key] = [row.to_dict() for row in acc_.rows(p.weight_start_cm)]
    if len(plan) == 1 and reports[0].missing:  # flat keys, as every key of the record
        record.update({f"gaps.{k}": v for k, v in reports[0].as_dict().items()})
    elif missing:
        record["gaps.missing_samples"] = missing


def _round(x: float, digits: int = 6) -> float:
    return float(round(float(x), digits))
