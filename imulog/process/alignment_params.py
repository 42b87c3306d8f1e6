"""Settings of the IMU-to-Vicon alignment (clock windows, lag search, filters, quality thresholds)."""

from __future__ import annotations

from dataclasses import dataclass

from imulog.params import check_params
from imulog.process.alignment_frames import FilterParams
from imulog.process.alignment_search import SearchParams


@dataclass(frozen=True)
class AlignmentParams:
    """IMU-to-Vicon alignment settings.

    Clock: a coarse lag over the whole recording (``coarse_hz`` grid, +-``max_lag_s``), then one lag per
    ``window_s`` (30 s) window across the trial, starting ``window_start_s`` after the reference's first
    sample, each searched +-``fine_lag_s`` around the coarse lag on a ``grid_hz`` grid; windows scoring under
    ``min_window_score`` or without movement (reference signal sd under ``min_window_activity``, in the
    signal's unit: ``min_window_activity`` rad/s for angular velocity, ``min_window_activity_mps2`` m/s^2 for
    a marker's acceleration) are left out; with ``drift`` (default) a straight line offset + drift x time is fitted
    to the windows (outliers beyond ``outlier_k`` robust sd and ``outlier_floor_s`` rejected), else their
    median offset is used. The uncertainties pool the windows' scatter with ``window_lag_sd_s`` (0.5 ms, the
    per-window lag scatter of simulated trials) counted as two windows. ``filter``: marker low-pass (6 Hz, 2nd order); ``cluster``: ``auto`` (search the
    rigid marker set that moves with the IMU, :mod:`imulog.process.alignment_search`), ``oxy`` (markers
    O, X, Y as in the thesis) or ``svd`` (the ``markers`` given, >= 3; one marker aligns on its
    acceleration); ``markers`` names with or without the ``Subject:`` prefix; ``bias_min_static_s``: static
    periods (gyro norm < 0.1 rad/s) at least this long give the gyroscope bias removed before the rotation
    fit. A trial too short for three windows is cut into up to ``short_windows`` windows of at least
    ``short_window_s`` (5 s) for the drift, which is applied only when its standard error is at most
    ``max_drift_uncertainty_ppm`` (20 ppm), else reported as not estimable. ``gyro_lowpass`` (off by default
    until the tests built on the old behaviour are reviewed): the gyroscope is low-passed like the markers before
    it is compared with them (:func:`gyro_like_markers`). ``poor_*`` thresholds flag a poor alignment (``quality``); under ``min_valid_score`` there is no
    alignment at all (the step fails and writes nothing).
    """

    window_s: float = 30.0
    window_start_s: float = 0.0
    max_lag_s: float = 60.0
    drift: bool = True
    drift_end_margin_s: float = 0.0
    filter: FilterParams = FilterParams()
    cluster: str = "auto"
    markers: tuple[str, ...] = ()
    grid_hz: float = 200.0
    coarse_hz: float = 50.0
    fine_lag_s: float = 0.5
    min_window_score: float = 0.5
    min_window_activity: float = 0.05
    min_window_activity_mps2: float = 0.1
    outlier_k: float = 4.0
    outlier_floor_s: float = 0.002
    window_lag_sd_s: float = 0.0005
    bias_min_static_s: float = 1.0
    search: SearchParams = SearchParams()
    min_valid_score: float = 0.5
    poor_score: float = 0.8
    poor_spread_s: float = 0.003
    poor_min_windows: int = 3
    poor_vector_match: float = 0.9
    short_window_s: float = 5.0
    short_windows: int = 6
    max_drift_uncertainty_ppm: float = 20.0
    gyro_lowpass: bool = False

    def __post_init__(self) -> None:  # ParamError names the field and its unit; the CLI prints the same line
        if isinstance(self.markers, list):
            object.__setattr__(self, "markers", tuple(self.markers))
        check_params(
            self,
            positive=("window_s", "grid_hz", "coarse_hz", "fine_lag_s", "short_window_s"),
            non_negative=("max_lag_s", "drift_end_margin_s", "outlier_floor_s", "window_lag_sd_s", "bias_min_static_s"),
            choices={"cluster": ("auto", "oxy", "svd")},
        )
