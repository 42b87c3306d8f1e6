"""One call from a gyroscope signal to movements, labelled phases, a zero-velocity mask and a timing table.

Used by :mod:`imulog.steps.phases` and the accuracy benchmark. Methods:

* ``"dynamos"``: :func:`~imulog.process.segmentation.dynamos.dynamos`;
* ``"double-threshold"``: :func:`~imulog.process.segmentation.double_threshold.double_threshold` (Bai et al.);
* ``"template"``: DynAMoS movements of the correct repetitions are averaged into a template (with
  ``template_pad_s`` of context on each side) and its cross-correlation peaks become the movements.

Every method is followed by repetition splitting and event correction
(:func:`~imulog.process.segmentation.repetitions.segment_repetitions`) and by the phase-boundary refinement
of :mod:`~imulog.process.segmentation.boundaries` (``boundaries.enabled``; with method ``"dynamos"`` only when
``dynamos.refine_boundaries`` is on too, so that ``--no-refine`` gives the published method). The raw
movements (``movement_start``/``movement_end``) and the static mask keep the detector's boundaries. The static mask is the complement of
the raw movements (``static="movements"``) or the gyro-norm baseline (``static="gyro-norm"``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace

import numpy as np

from imulog.param_rules import check_rules
from imulog.process.segmentation.boundaries import BoundaryParams, refine_phase_boundaries
from imulog.process.segmentation.double_threshold import DoubleThresholdParams, double_threshold
from imulog.process.segmentation.dynamos import DynamosParams, dynamos, lowpass_norm
from imulog.process.segmentation.gaps import unphased_movements
from imulog.process.segmentation.hand import HandParams, refine_with_accelerometer
from imulog.process.segmentation.repetitions import Phases, RepetitionParams, segment_repetitions
from imulog.process.segmentation.template import TemplateParams, build_template, match_template
from imulog.process.segmentation.zero_velocity import (
    GyroNormStaticParams,
    gyro_norm_static,
    static_from_movements,
)

METHODS = ("dynamos", "double-threshold", "template")
PROTOCOLS = ("r2g", "movements")


@dataclass(frozen=True)
class PhaseParams:
    """All parameters of :func:`segment_phases` (each sub-object documents its own defaults and units).

    method: one of ``METHODS``; static: ``"movements"`` or ``"gyro-norm"``;
    protocol: ``"r2g"`` splits repetitions and labels the four drinking-task phases (with event correction);
    ``"movements"`` (any other task) keeps every detected movement as one phase labelled ``movement``,
    numbered from 1 in ``repetition``;
    static_margin_s: movements are widened by this (s) before taking the complement as zero velocity;
    template_pad_s: static context (s) on each side of the template (method ``"template"``).
    """

    method: str = "dynamos"
    protocol: str = "r2g"
    dynamos: DynamosParams = field(default_factory=DynamosParams)
    double_threshold: DoubleThresholdParams = field(default_factory=DoubleThresholdParams)
    template: TemplateParams = field(default_factory=TemplateParams)
    repetitions: RepetitionParams = field(default_factory=RepetitionParams)
    boundaries: BoundaryParams = field(default_factory=BoundaryParams)
    hand: HandParams = field(default_factory=HandParams)
    static: str = "movements"
    static_margin_s: float = 0.0
    gyro_norm: GyroNormStaticParams = field(default_factory=GyroNormStaticParams)
    template_pad_s: float = 0.5
    __post_init__ = check_rules  # bounds and choices: imulog.param_rules.RULES

    def to_dict(self) -> dict:
        """JSON-able form, for provenance."""
        d = asdict(self)
        d["repetitions"]["labels"] = list(self.repetitions.labels)
        return d


@dataclass(frozen=True)
class PhaseResult:
    """Output of :func:`segment_phases`: sample ranges, the static mask and the filtered norm (rad/s)."""

    movement_start: np.ndarray
    movement_end: np.ndarray
    phases: Phases
    static: np.ndarray
    norm: np.ndarray


def hand_params(params: PhaseParams) -> HandParams:
    """The accelerometer step's parameters for ``params.protocol``: step 9 (the speed profile,
    ``HandParams.profile_rest_s``) runs on the drinking task (``r2g``) only, where it was validated (issue 31); on
    daily-life movements it changed 1-2 of 180 minutes of moving time a recording, not for the better on average,
    at +15 % of the step's CPU (``benchmarks/home_phases_accuracy.py``, docs/long_recordings.md)."""
    if params.protocol == "r2g" or params.hand.profile_rest_s <= 0:
        return params.hand
    return replace(params.hand, profile_rest_s=0.0)


def template_movements(gyr, rate_hz, norm, params: PhaseParams):
    """Movements of method ``template``: DynAMoS repetitions averaged into a template, matched over ``norm``."""
    seg = dynamos(gyr, rate_hz, params.dynamos)
    ph = segment_repetitions(seg.start, seg.end, seg.norm, rate_hz, params.repetitions)
    pad = int(round(params.template_pad_s * rate_hz))
    ok = (ph.start - pad >= 0) & (ph.end + pad <= len(norm))
    if not ok.any():
        return seg.start, seg.end
    s, e = ph.start[ok], ph.end[ok]
    m = int(np.median(e - s))
    template = build_template(norm, s - pad, e + pad)
    scale = (m + 2 * pad) / len(template)
    marks = (int(round(pad / scale)), int(round((m + pad) / scale)))
    start, end, _ = match_template(norm, template, params.template, marks=marks)
    return start, end


def movements_as_phases(start: np.ndarray, end: np.ndarray) -> Phases:
    """Every movement ``[start, end)`` (samples) as its own phase ``movement``, numbered from 1 (no protocol)."""
    n = len(start)
    return Phases(
        start=np.asarray(start, dtype=np.int64),
        end=np.asarray(end, dtype=np.int64),
        repetition=np.arange(1, n + 1, dtype=np.int64),
        phase=np.zeros(n, dtype=np.int64),
        labels=["movement"] * n,
        n_corrected=0,
    )


def segment_phases(
    gyr_rad_s: np.ndarray,
    rate_hz: float,
    params: PhaseParams = PhaseParams(),
    acc_mps2: np.ndarray | None = None,
) -> PhaseResult:
    """Movements, corrected phases and zero-velocity mask from a gyroscope signal (N, 3) rad/s.

    With the accelerometer ``acc_mps2`` (N, 3) m/s^2 (same samples) the phase boundaries also follow the
    hand's translation (:mod:`~imulog.process.segmentation.hand`), and the static mask excludes the refined
    phases as well as the movements."""
    gyr = np.asarray(gyr_rad_s, dtype=float)
    norm = lowpass_norm(gyr, rate_hz, params.dynamos.cutoff_hz, params.dynamos.filter_order)
    if params.method == "dynamos":
        seg = dynamos(gyr, rate_hz, params.dynamos)
        start, end = seg.start, seg.end
    elif params.method == "double-threshold":
        start, end = double_threshold(gyr, rate_hz, params.double_threshold)
    elif params.method == "template":
        start, end = template_movements(gyr, rate_hz, norm, params)
    else:
        raise ValueError(f"unknown segmentation method {params.method!r}; choose one of {', '.join(METHODS)}")
    if params.protocol == "r2g":
        phases = segment_repetitions(start, end, norm, rate_hz, params.repetitions)
    elif params.protocol == "movements":
        phases = movements_as_phases(start, end)
    else:
        raise ValueError(f"unknown protocol {params.protocol!r}; choose one of {', '.join(PROTOCOLS)}")
    refine = params.boundaries.enabled and (params.method != "dynamos" or params.dynamos.refine_boundaries)
    if refine and len(phases):  # onsets/offsets where the gyroscope leaves/reaches its static noise
        ps, pe = refine_phase_boundaries(gyr, rate_hz, phases.start, phases.end, params.boundaries)
        if acc_mps2 is not None and params.hand.enabled:  # ... and where the hand leaves/reaches its rest
            others = unphased_movements(start, end, ps, pe)  # the calibration wave: motion that is no phase
            ps, pe = refine_with_accelerometer(acc_mps2, gyr, rate_hz, ps, pe, hand_params(params), movements=others)
        phases = replace(phases, start=ps, end=pe)
    if params.static == "movements":
        static = static_from_movements(len(gyr), start, end, rate_hz, params.static_margin_s)
        if refine and len(phases):  # zero velocity only where neither a movement nor a refined phase is
            static &= static_from_movements(len(gyr), phases.start, phases.end, rate_hz, params.static_margin_s)
    elif params.static == "gyro-norm":
        static = gyro_norm_static(gyr, rate_hz, params.gyro_norm)
    else:
        raise ValueError(f"unknown static detector {params.static!r}; choose 'movements' or 'gyro-norm'")
    return PhaseResult(start, end, phases, static, norm)


def timing_table(phases: Phases, t_ns: np.ndarray, gyr_rad_s: np.ndarray) -> list[dict]:
    """Per phase: repetition, label, start/end (ns and s from ``t_ns[0]``), duration (s), peak |gyr| (rad/s),
    ``forced`` (made by cutting a movement: no movement of its own) and its repetition's ``confidence``.

    ``t_ns`` are the sample times (any clock) of ``gyr_rad_s``; phase end = time of its last sample.
    """
    t_ns = np.asarray(t_ns, dtype=np.int64)
    raw = np.linalg.norm(np.nan_to_num(np.asarray(gyr_rad_s, dtype=float)), axis=1)
    forced = phases.forced if phases.forced is not None else np.zeros(len(phases), dtype=bool)
    confidence = {q["repetition"]: q["confidence"] for q in phases.quality}
    rows = []
    for i, (s, e, r, label) in enumerate(zip(phases.start, phases.end, phases.repetition, phases.labels, strict=True)):
        last = max(int(e) - 1, int(s))
        rows.append(
            {
                "repetition": int(r),
                "label": label,
                "start_ns": int(t_ns[s]),
                "end_ns": int(t_ns[last]),
                "start_s": round(float(t_ns[s] - t_ns[0]) * 1e-9, 4),
                "end_s": round(float(t_ns[last] - t_ns[0]) * 1e-9, 4),
                "duration_s": round(float(t_ns[last] - t_ns[s]) * 1e-9, 4),
                "peak_angular_velocity_rad_s": round(float(raw[s : last + 1].max()), 4),
                "forced": bool(forced[i]) if i < len(forced) else False,
                "confidence": confidence.get(int(r), 1.0),
            }
        )
    return rows
