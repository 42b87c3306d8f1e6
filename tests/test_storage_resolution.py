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


@pytest.mark.parametrize("name", ["ax3_sample.cwa", "ax6_sample.cwa"])
def test_axivity_counts_read_back_as_the_converters_values(shared_data: Path, tmp_path: Path, name: str):
    from imulog.converters.axivity import read_cwa

    rec = read_cwa(shared_data / "devices" / "axivity_cwa" / name)
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
