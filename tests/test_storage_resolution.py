"""Raw samples stored at the device's own resolution (issue 28): counts in the archive, the converter's SI values
read back exactly, on the real Axivity samples and on ADC text."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imulog.archive import TrialReader, codec, write_trial


def _blocks(trial: TrialReader, topic: str) -> list:
    cls = codec.MESSAGE_CLASSES["imulog.ImuBlock"]
    return [cls.FromString(bytes(p)) for p in trial.messages(topic)]


@pytest.mark.parametrize("rule", ["skdh", "openmovement"])
@pytest.mark.parametrize("name", ["ax3_sample.cwa", "ax6_sample.cwa"])
def test_axivity_counts_read_back_as_the_converters_values(shared_data: Path, tmp_path: Path, name: str, rule: str):
    from imulog.converters import ConvertOptions
    from imulog.converters.axivity import read_cwa

    rec = read_cwa(shared_data / "devices" / "axivity_cwa" / name, ConvertOptions(extra={"cwa_times": rule}))
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    imu = rec.imus[0]
    with TrialReader(path) as tr:
        back = tr.read(f"/imu/{imu.name}")
        blocks = _blocks(tr, f"/imu/{imu.name}")
    assert np.array_equal(back.t_ns, imu.t_ns)
    for f in ("acc", "gyr", "mag"):
        want = getattr(imu, f)
        assert (getattr(back, f) is None) == (want is None)
        if want is not None:
            assert np.array_equal(getattr(back, f), want, equal_nan=True), f
    # the device's counts are what is stored: (counts / 256) * 9.80665 for acc (1 g = 256 at +-8 g)
    counted = [b for b in blocks if b.HasField("acc_q")]
    assert len(counted) >= 0.9 * len(blocks)
    assert (
        counted[0].acc_q.divisor[0] in (256.0, 512.0, 1024.0, 2048.0, 4096.0) and counted[0].acc_q.scale[0] == 9.80665
    )
    assert max(abs(c) for c in counted[0].acc_q.counts) < 2**15
    if imu.gyr is not None:
        assert all(b.HasField("gyr_q") for b in counted)
    if rule == "openmovement":  # skdh's rule changes the rate by up to a sample per device block: explicit times
        assert sum(not len(b.t_ns) for b in blocks) >= 0.9 * len(blocks)  # start + span (+ residuals)


def test_adc_text_counts_with_zero_offset(tmp_path: Path):
    from imulog.converters.adc import read_adc

    rng = np.random.default_rng(4)
    counts = rng.integers(300, 724, (3000, 3))
    src = tmp_path / "tilt.txt"
    src.write_text("".join(f"X={x} Y={y} Z={z}\n" for x, y, z in counts))
    rec = read_adc(src, rate_hz=50.0, zero_counts=[510.0, 512.0, 509.0])
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    with TrialReader(path) as tr:
        back = tr.read("/imu/acc")
        blocks = _blocks(tr, "/imu/acc")
    assert np.array_equal(back.acc, rec.imus[0].acc) and np.array_equal(back.t_ns, rec.imus[0].t_ns)
    assert all(b.HasField("acc_q") and list(b.acc_q.shift) == [-510.0, -512.0, -509.0] for b in blocks)
    assert np.array_equal(np.concatenate([np.array(b.acc_q.counts) for b in blocks]).reshape(-1, 3), counts)


def _q_blocks(trial: TrialReader, topic: str, schema: str, field: str) -> tuple[int, list]:
    cls = codec.MESSAGE_CLASSES[schema]
    msgs = [cls.FromString(bytes(p)) for p in trial.messages(topic)]
    return len(msgs), [getattr(m, field) for m in msgs if m.HasField(field) and len(getattr(m, field).counts)]


def test_actigraph_gt3x_counts_read_back_as_the_converters_values(shared_data: Path, tmp_path: Path):
    from imulog.converters.actigraph import read_gt3x

    rec = read_gt3x(shared_data / "devices" / "actigraph_gt3x" / "example.gt3x")
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    with TrialReader(path) as tr:
        for imu in rec.imus:
            back = tr.read(f"/imu/{imu.name}")
            assert np.array_equal(back.t_ns, imu.t_ns)
            fields = [f for f in ("acc", "gyr", "mag", "temperature") if getattr(imu, f) is not None]
            for f in fields:
                assert np.array_equal(getattr(back, f), getattr(imu, f), equal_nan=True), (imu.name, f)
                n, qs = _q_blocks(tr, f"/imu/{imu.name}", "imulog.ImuBlock", f"{f}_q")
                assert len(qs) == n, (imu.name, f)  # every block as the device's counts
                assert max(abs(c) for c in qs[0].counts) < 2**15
            n, acc = _q_blocks(tr, f"/imu/{imu.name}", "imulog.ImuBlock", "acc_q")
            # the primary accelerometer's LSB per g (256 at +-8 g) or the IMU's; 1 g = 9.80665 m/s^2
            assert acc[0].divisor[0] in (256.0, 341.0, 2048.0) and acc[0].scale[0] == 9.80665, imu.name


def test_geneactiv_counts_read_back_as_the_converters_values(shared_data: Path, tmp_path: Path):
    from imulog.converters.geneactiv import read_bin

    rec = read_bin(shared_data / "devices" / "geneactiv_bin" / "GENEActiv_testfile.bin")
    imu = rec.imus[0]
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    with TrialReader(path) as tr:
        back = tr.read(f"/imu/{imu.name}")
        n, qs = _q_blocks(tr, f"/imu/{imu.name}", "imulog.ImuBlock", "acc_q")
    assert np.array_equal(back.acc, imu.acc) and np.array_equal(back.t_ns, imu.t_ns)
    assert len(qs) == n
    cal = rec.metadata[f"imulog.device.{imu.name}"]["calibration"]
    assert list(qs[0].divisor) == cal["gain"] and list(qs[0].shift) == [-o for o in cal["offset"]]
    counts = np.concatenate([np.array(q.counts) for q in qs]).reshape(-1, 3)
    assert np.all(counts % 100 == 0) and np.abs(counts // 100).max() < 2**11  # the 12-bit words x 100


@pytest.mark.parametrize("name", ["pc_int.c3d", "MACsample.c3d"])
def test_c3d_integer_points_stored_as_their_words(shared_data: Path, tmp_path: Path, name: str):
    from imulog.converters.c3d import read_c3d

    rec = read_c3d(shared_data / "devices" / "c3d_samples" / name)
    mk = rec.markers[0]
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    with TrialReader(path) as tr:
        back = tr.read(mk.topic)
        n, qs = _q_blocks(tr, mk.topic, "imulog.MarkerBlock", "pos_q")
    assert np.array_equal(back.pos, mk.pos, equal_nan=True) and np.array_equal(back.valid, mk.valid)
    assert (~mk.valid).any()  # occluded samples: stored as count 0, read back as NaN
    assert len(qs) == n
    counts = np.concatenate([np.array(q.counts) for q in qs])
    assert np.abs(counts).max() <= 32768  # the file's int16 words
    scale = mk.meta["resolution"]["pos"]["scale"]
    assert qs[0].scale[0] == scale and 1e-6 < scale < 1e-3  # POINT:SCALE (mm) in m


def test_c3d_float_points_keep_float64(shared_data: Path, tmp_path: Path):
    from imulog.converters.c3d import read_c3d

    rec = read_c3d(shared_data / "c3d" / "ktk_sample_propulsion_upperlimb.c3d")
    assert "resolution" not in rec.markers[0].meta  # POINT:SCALE < 0: float32 words, no integer counts
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    with TrialReader(path) as tr:
        assert np.array_equal(tr.read(rec.markers[0].topic).pos, rec.markers[0].pos, equal_nan=True)


def test_geneactiv_light_stored_as_its_words(shared_data: Path, tmp_path: Path):
    """Light (10-bit word x Lux / Volts) and button (1 bit) as their words, read back as the converter's lux."""
    from imulog.converters.geneactiv import read_bin

    src = shared_data / "devices" / "geneactiv_bin" / "GENEActiv_testfile.bin"
    rec = read_bin(src)
    sig = rec.signals[0]
    cal = rec.metadata["imulog.device.geneactiv"]["calibration"]
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    with TrialReader(path) as tr:
        back = tr.read(sig.topic)
        n, qs = _q_blocks(tr, sig.topic, "imulog.SignalBlock", "values_q")
    assert np.array_equal(back.values, sig.values) and np.array_equal(back.t_ns, sig.t_ns)
    assert len(qs) == n and list(qs[0].scale) == [cal["lux"] / cal["volts"], 1.0]
    words = np.concatenate([np.array(q.counts) for q in qs]).reshape(-1, 2)
    # the words decoded by hand from the hex pages: light is bits 47-38 of each 48-bit sample, button bit 37
    hexes = [line for line in src.read_bytes().splitlines() if len(line) == 3600]
    raw = np.array([int(h[k : k + 12], 16) for h in hexes for k in range(0, 3600, 12)], dtype=np.int64)
    np.testing.assert_array_equal(words[:, 0], (raw >> 2) & 0x3FF)
    np.testing.assert_array_equal(words[:, 1], (raw >> 1) & 1)
    assert words[:, 0].max() > 0


@pytest.mark.parametrize("name", ["pc_int.c3d", "MACsample.c3d"])
def test_c3d_analogs_stored_as_their_words(shared_data: Path, tmp_path: Path, name: str):
    """C3D analogs as the file's int16 words with ANALOG:OFFSET and GEN_SCALE * SCALE, read back exactly as the
    converter's values, which equal the C3D formula on the words read by hand from the file."""
    import struct

    from imulog.converters.c3d import read_c3d
    from imulog.converters.c3d_format import parameters, to_intel

    src = shared_data / "devices" / "c3d_samples" / name
    rec = read_c3d(src)
    an = rec.analogs[0]
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    with TrialReader(path) as tr:
        back = tr.read(an.topic)
        n, qs = _q_blocks(tr, an.topic, "imulog.AnalogBlock", "values_q")
    assert np.array_equal(back.values, an.values) and len(qs) == n
    data = to_intel(src.read_bytes())
    p = parameters(data)
    n_points, per_frame = struct.unpack_from("<2H", data, 2)
    start = (struct.unpack_from("<H", data, 16)[0] - 1) * 512
    frames = int(p["POINT:FRAMES"][0])
    block = np.frombuffer(data, "<i2", count=frames * (4 * n_points + per_frame), offset=start).reshape(frames, -1)
    channels = an.values.shape[1]
    words = block[:, 4 * n_points :].reshape(-1, channels).astype(np.float64)
    stored = np.concatenate([np.array(q.counts) for q in qs]).reshape(-1, channels)
    np.testing.assert_array_equal(stored, words)
    off = np.zeros(channels)
    off[: len(p.get("ANALOG:OFFSET", []))] = np.asarray(p.get("ANALOG:OFFSET", []), dtype=np.float64)[:channels]
    step = float(p["ANALOG:GEN_SCALE"][0]) * np.asarray(p["ANALOG:SCALE"], dtype=np.float64)[:channels]
    np.testing.assert_allclose(an.values, (words - off) * step, rtol=1e-12, atol=0)


TEXT_AND_INTEGER_SOURCES = [
    # (file, topic, field, what the stored numbers are)
    ("empatica_e4/ACC.csv", "/imu/e4", "acc", "the file's 1/64 g counts: (counts / 64) * g"),
    ("axivity_csv/ax3_testfile_unix_timestamps.csv", "/imu/axivity", "acc", "the text's g decimals * g"),
    ("opensim_trc/markers.trc", "/markers/trc", "pos", "the text's mm decimals * 0.001"),
    ("optitrack_motive/sample_optitrack_take.csv", "/markers/motive", "pos", "the text's decimals, occlusions 0"),
    ("delsys_trigno/truncated_trigno_sample.csv", "/analog/mini_sensor_10", "values", "%.7g EMG to 13 decimals"),
    ("edf/trigno_emg.edf", "/analog/edf", "values", "the digital words: (d - dmin) * gain + pmin"),
    ("nilspod/NilsPodX-6F13_20210109_162824.bin", "/imu/nilspod_6f13", "acc", "int16 / (2**16 / range / 2 / 9.81)"),
    ("nilspod/NilsPodX-6F13_20210109_162824.bin", "/imu/nilspod_6f13", "gyr", "int16 / (2**16 / range / 2) * pi/180"),
    ("nilspod/NilsPodX-6F13_20210109_162824_data.csv", "/imu/nilspod_6f13", "acc", "NilsPodLib's quotients in full"),
    ("nilspod/NilsPodX-6F13_20210109_162824_data.csv", "/imu/nilspod_6f13", "gyr", "the same, deg/s x pi/180"),
]


@pytest.mark.parametrize(("rel", "topic", "field", "what"), TEXT_AND_INTEGER_SOURCES)
def test_text_and_integer_sources_store_no_float64(shared_data: Path, tmp_path: Path, rel, topic, field, what):
    """Every block of these channels is stored at the source's resolution (counts, with the text's decimals or
    the file's integer words), none as float64, and reads back equal to the converter's values."""
    from imulog.converters import convert_file

    rec = convert_file(shared_data / "devices" / rel)
    streams = {s.topic: s for s in [*rec.imus, *rec.markers, *rec.analogs, *rec.signals]}
    want = getattr(streams[topic], field)
    path = write_trial(tmp_path / "t.mcap", rec, attach_sources=False)
    schema = {"pos": "imulog.MarkerBlock", "values": "imulog.AnalogBlock"}.get(field, "imulog.ImuBlock")
    with TrialReader(path) as tr:
        got = getattr(tr.read(topic), field)
        cls = codec.MESSAGE_CLASSES[schema]
        msgs = [cls.FromString(bytes(p)) for p in tr.messages(topic)]
    assert np.array_equal(got, want, equal_nan=True), what
    assert msgs and all(m.HasField(f"{field}_q") and not len(getattr(m, field)) for m in msgs), what
