"""The one value check every reader's output gets (converters/values.py, issue 26), on built recordings."""

from __future__ import annotations

import numpy as np
import pytest
from imulog.converters import ConversionError
from imulog.converters.values import ValueReport, check_recording, finish

from imulog.model import ImuStream, Recording, SignalStream

G0 = 9.80665


def _imu(n: int = 100, **kw) -> ImuStream:
    acc = np.tile([0.0, 0.0, G0], (n, 1))
    return ImuStream(name="wrist", t_ns=np.arange(n) * 10_000_000, acc=acc, **kw)


def test_non_finite_and_absurd_values_become_counted_gaps():
    imu = _imu(meta={"acc_range_g": 8})
    imu.acc[3, 0], imu.acc[5, 1], imu.acc[7, 2] = np.inf, 17 * G0, 15 * G0  # 17 g > 2 x 8 g; 15 g is kept
    imu.acc[9, 0] = np.nan  # a gap already: not counted
    rec = Recording(imus=[imu])
    check_recording(rec, "x.csv")
    assert np.isnan(imu.acc[3, 0]) and np.isnan(imu.acc[5, 1]) and imu.acc[7, 2] == 15 * G0
    assert rec.warnings == ["/imu/wrist acc: 2 value(s) not finite or beyond the sensor's range stored as gaps (NaN)"]


def test_without_a_declared_range_1e6_g_is_the_limit_and_other_columns_1e30():
    imu = _imu()
    imu.acc[0, 0] = 0.9e6 * G0
    imu.acc[1, 0] = 1.1e6 * G0
    sig = SignalStream("/signals/x", np.arange(4), ["v"], ["V"], np.array([[1.0], [1e308], [-np.inf], [2.0]]))
    rec = Recording(imus=[imu], signals=[sig])
    check_recording(rec)
    assert np.isfinite(imu.acc[0, 0]) and np.isnan(imu.acc[1, 0])
    assert np.isnan(sig.values[1:3, 0]).all() and "/signals/x v: 2 value(s)" in " ".join(rec.warnings)


def test_a_channel_the_check_empties_is_an_error_naming_it():
    imu = _imu()
    imu.acc[:] = np.inf
    with pytest.raises(ConversionError, match=r"x.csv: /imu/wrist acc: every value .* unusable"):
        check_recording(Recording(imus=[imu]), "x.csv")
    with pytest.raises(ConversionError, match="no samples"):
        check_recording(Recording(imus=[_imu(0)]), "x.csv")


def test_quaternions_normalised_near_unit_norm_refused_beyond():
    q = np.tile([1.0, 0.0, 0.0, 0.0], (6, 1))
    q[1] *= 1 + 5e-4  # within 1e-3: normalised
    q[2] *= 1 + 1e-7  # printing precision: kept as written
    q[3, 1] = 1e20  # refused
    q[4] = np.nan  # a gap already
    sig = SignalStream("/orientation/wrist", np.arange(6), ["qw", "qx", "qy", "qz"], ["1"] * 4, q.copy())
    rec = Recording(signals=[sig])
    check_recording(rec)
    v = sig.values
    assert v[1, 0] == 1.0 and v[2, 0] == 1 + 1e-7 and np.isnan(v[3]).all() and np.isnan(v[4]).all()
    assert rec.warnings == [
        "/orientation/wrist orientation: 1 quaternion sample(s) whose norm is not 1 (off by more than 0.001) "
        "stored as gaps (NaN)"
    ]


def test_header_rate_off_the_time_stamps_is_reported_and_replaced():
    imu = _imu(meta={"rate_hz": 9000.0})
    rec = Recording(imus=[imu], metadata={"imulog.device.wrist": {"rate_hz": 9000.0}})
    check_recording(rec)
    assert imu.meta["rate_hz"] == 100.0 and imu.meta["declared_rate_hz"] == 9000.0
    assert rec.metadata["imulog.device.wrist"]["rate_hz"] == 100.0
    assert "declared rate 9000 Hz differs from the time stamps' 100 Hz" in rec.warnings[0]
    ok = _imu(meta={"rate_hz": 100.5})  # within 1 %: kept
    check_recording(Recording(imus=[ok]))
    assert ok.meta["rate_hz"] == 100.5


def test_times_must_increase_and_start_within_1970_2100():
    imu = _imu()
    imu.t_ns[50] = imu.t_ns[49]
    with pytest.raises(ConversionError, match="do not increase at sample 50"):
        check_recording(Recording(imus=[imu]))
    rec = Recording(imus=[_imu()], metadata={"imulog.trial": {"start_time": "1969-12-31T23:59:59+00:00"}})
    with pytest.raises(ConversionError, match="outside 1970-2100"):
        check_recording(rec)


def test_pieces_accumulate_and_finish_decides():
    report = ValueReport()
    first, second = _imu(), _imu()
    second.t_ns = second.t_ns + 10**9 * 10
    second.acc[:] = np.inf  # the whole second piece is bad, the first is good: a warning, not an error
    check_recording(Recording(imus=[first]), report=report, final=False)
    check_recording(Recording(imus=[second]), report=report, final=False)
    end = Recording()
    finish(end, report)
    assert end.warnings == ["/imu/wrist acc: 300 value(s) not finite or beyond the sensor's range stored as gaps (NaN)"]
    with pytest.raises(ConversionError, match="go back between two pieces"):
        check_recording(Recording(imus=[_imu()]), report=report, final=False)


def test_long_labels_are_capped_and_stay_distinct():
    from imulog.model import MarkerStream

    a, b = "M" * 300_000 + "a", "M" * 300_000 + "b"
    m = MarkerStream("vicon", np.arange(3), [a, b, "LASI"], np.zeros((3, 3, 3)))
    rec = Recording(markers=[m])
    check_recording(rec)
    assert len(set(m.labels)) == 3 and max(len(x) for x in m.labels) == 64 and m.labels[2] == "LASI"


def test_event_times_cast_from_nan_are_errors():
    from imulog.model import Intervals

    bad = np.array([0.0, np.nan]) * 1e9
    with np.errstate(invalid="ignore"):
        start = bad.astype(np.int64)  # what a reader's cast of an empty cell gives: the smallest int64
    ev = Intervals(topic="/events/strides", start_ns=start, end_ns=start.copy(), labels=["a", "b"])
    with pytest.raises(ConversionError, match="/events/strides: event 1 has no valid time"):
        check_recording(Recording(events=[ev]), "s.csv")
