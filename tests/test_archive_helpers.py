"""Shared builders and comparisons for the archive tests (no tests here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from imulog.model import AnalogStream, ImuStream, Intervals, MarkerStream, PoseStream, Recording, SignalStream


def bits(a: np.ndarray) -> np.ndarray:
    """Bit patterns of a float/int array (NaN payloads and -0.0 compare exactly)."""
    a = np.ascontiguousarray(a)
    return a.view(np.uint8).reshape(a.shape + (a.dtype.itemsize,)) if a.dtype.kind == "f" else a


def assert_bit_identical(a, b, what: str) -> None:
    assert (a is None) == (b is None), what
    if a is None:
        return
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, f"{what}: shape {a.shape} != {b.shape}"
    assert a.dtype == b.dtype, f"{what}: dtype {a.dtype} != {b.dtype}"
    assert np.array_equal(bits(a), bits(b)), f"{what}: values differ"


def assert_stream_equal(a, b) -> None:
    assert type(a) is type(b)
    if isinstance(a, Intervals):
        assert a.topic == b.topic and a.labels == b.labels
        for f in ("start_ns", "end_ns", "task_index"):
            assert_bit_identical(getattr(a, f), getattr(b, f), f"{a.topic} {f}")
        return
    assert_bit_identical(a.t_ns, b.t_ns, "t_ns")
    fields = {
        ImuStream: ("acc", "gyr", "mag", "temperature"),
        MarkerStream: ("pos", "valid"),
        AnalogStream: ("values",),
        SignalStream: ("values",),
        PoseStream: ("position", "orientation"),
    }[type(a)]
    for f in fields:
        assert_bit_identical(getattr(a, f), getattr(b, f), f"{type(a).__name__} {f}")
    for attr in ("name", "labels", "channel_names", "units", "columns", "frame_id", "meta", "topic"):
        if hasattr(a, attr):
            assert getattr(a, attr) == getattr(b, attr), attr


def synthetic_recording(rng: np.random.Generator, *, n_imu: int = 3000, sources: list[Path] | None = None) -> Recording:
    """Every stream type, with NaN gaps, -0.0, odd NaN payloads, a negative time base and an empty stream."""
    t = np.cumsum(rng.integers(8_600_000, 8_800_000, n_imu)).astype(np.int64) + 1_700_000_000_000_000_000
    acc = rng.normal(0, 9.81, (n_imu, 3))
    acc[100:140] = np.nan
    acc[5, 1] = -0.0
    weird_nan = np.frombuffer(np.uint64(0x7FF8DEADBEEF0001).tobytes(), dtype=np.float64)[0]
    acc[7, 2] = weird_nan
    gyr = rng.normal(0, 1, (n_imu, 3))
    mag = rng.normal(30, 5, (n_imu, 3))
    temp = rng.normal(25, 1, n_imu)
    imu = ImuStream(
        "wrist", t, acc=acc, gyr=gyr, mag=mag, temperature=temp, meta={"model": "LSM9DS1", "rate_hz": 115.0}
    )
    imu2 = ImuStream("chest", t[:50], acc=acc[:50])  # acc only
    tv = np.arange(2500, dtype=np.int64) * 10_000_000 - 5_000_000_000  # negative clock start
    pos = rng.normal(0, 0.3, (2500, 4, 3))
    pos[300:420, 2] = np.nan
    markers = MarkerStream("vicon", tv, ["O", "X", "Y", "A"], pos, meta={"source": "markers.csv"})
    analog = AnalogStream("emg", tv, ["biceps", "triceps"], ["V", "mV"], rng.normal(0, 1e-3, (2500, 2)))
    sig = SignalStream("/signals/reference_quat", t, ["qw", "qx", "qy", "qz"], ["1"] * 4, rng.normal(size=(n_imu, 4)))
    empty = SignalStream("/signals/empty", np.zeros(0, np.int64), ["a", "b"], ["m", "s"], np.zeros((0, 2)))
    events = Intervals(
        "/events/c3d", [-10, 0, 10_000_000], [-5, 0, 20_000_000], ["Foot Strike", "x", "reach"], [1, -1, 2]
    )
    pose_pos = rng.normal(size=(400, 3))
    pose_pos[10:20] = np.nan
    poses = PoseStream("/poses/cluster", tv[:400], pose_pos, rng.normal(size=(400, 4)), frame_id="world")
    return Recording(
        imus=[imu, imu2],
        markers=[markers],
        analogs=[analog],
        signals=[sig, empty],
        events=[events],
        poses=[poses],
        metadata={
            "imulog.trial": {"subject": "S01", "trial": 3, "task": "r2g", "side": "right", "date": "2024-05-01"},
            "imulog.anthropometrics": {"height_m": 1.78, "arm_length_m": 0.61, "dominant": "right", "flags": [1, 2]},
        },
        sources=[str(s) for s in (sources or [])],
    )


def load_broad(path: Path) -> Recording:
    """A real BROAD trial (h5py): IMU + optical poses with NaN rows where tracking was lost."""
    import h5py

    with h5py.File(path, "r") as f:
        rate = float(f.attrs["sampling_rate"])
        acc, gyr, mag = (np.asarray(f[k], dtype=np.float64) for k in ("imu_acc", "imu_gyr", "imu_mag"))
        opt_pos, opt_quat = np.asarray(f["opt_pos"], dtype=np.float64), np.asarray(f["opt_quat"], dtype=np.float64)
    t = np.round(np.arange(len(acc)) / rate * 1e9).astype(np.int64)
    imu = ImuStream("hand", t, acc=acc, gyr=gyr, mag=mag, meta={"model": "myon aktos-t", "rate_hz": rate})
    pose = PoseStream("/poses/optitrack", t, opt_pos, opt_quat, frame_id="world")
    return Recording(imus=[imu], poses=[pose], metadata={"imulog.trial": {"source": path.name}}, sources=[str(path)])


def load_nexus_markers(path: Path) -> MarkerStream:
    """The real Vicon Nexus marker CSV (51 markers, gaps as empty cells), read with numpy only."""
    lines = path.read_text().splitlines()
    rate = float(lines[1].split(",")[0])
    names_row = lines[2].split(",")
    labels = [n.split(":")[-1] for n in names_row[2::3] if n]
    rows = [ln.split(",") for ln in lines[5:] if ln.strip() and ln[0].isdigit()]
    width = 2 + 3 * len(labels)
    data = np.array([[float(v) if v else np.nan for v in (r + [""] * width)[:width]] for r in rows])
    t = np.round((data[:, 0] - 1) / rate * 1e9).astype(np.int64)
    pos = data[:, 2:].reshape(len(data), len(labels), 3) / 1000.0
    return MarkerStream("vicon", t, labels, pos, meta={"source": path.name, "rate_hz": rate})


def generic_times(count, t_ns, t0_ns, t_span_ns, t_residual_ns) -> np.ndarray:
    """A block's times as a generic protobuf reader rebuilds them (docs/schemas.md): ``t_ns``, or for
    schema_version 2 the start plus the span spread evenly plus residuals (absent fields may come as None)."""
    count = int(count or 0)
    if (t_ns is not None and len(t_ns)) or not count:
        return np.asarray(t_ns if t_ns is not None else [], dtype=np.int64)
    k, den = np.arange(count, dtype=np.int64), max(count - 1, 1)
    res = np.asarray(t_residual_ns, dtype=np.int64) if t_residual_ns is not None and len(t_residual_ns) else 0
    return int(t0_ns or 0) + (2 * k * int(t_span_ns or 0) + den) // (2 * den) + res
