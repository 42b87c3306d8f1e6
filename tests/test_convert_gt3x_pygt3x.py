"""ActiGraph .gt3x sample times and values against ActiGraph's own reader, pygt3x (GPL-3.0-or-later, so not a
dependency: its decode of the shared sample is kept in tests/data/pygt3x_example.npz, see pygt3x_example.md), on the
shared file and on the same seconds stored as the older 12-bit ACTIVITY and ACTIVITY3 records."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from gt3x_variants import build_variant
from imulog.converters._common import G0
from imulog.converters.actigraph import read_gt3x

from imulog.archive import TrialReader
from imulog.cli import cli

REF = Path(__file__).parent / "data" / "pygt3x_example.npz"


@pytest.fixture(scope="module")
def gt3x(shared_data: Path) -> Path:
    return shared_data / "devices" / "actigraph_gt3x" / "example.gt3x"


def _wall_s(start_time: str, t_ns: np.ndarray) -> np.ndarray:
    """Sample times as seconds since 1970 of the device's wall clock (pygt3x reads the local time as UTC)."""
    wall = datetime.fromisoformat(start_time).replace(tzinfo=None)
    origin_us = (wall - datetime(1970, 1, 1)).total_seconds() * 1e6
    return (round(origin_us) * 1000 + t_ns) / 1e9


@pytest.mark.parametrize("kind", ["activity2", "activity", "activity3"])
def test_times_and_values_equal_pygt3x(gt3x: Path, tmp_path: Path, kind: str):
    ref = np.load(REF)
    src = gt3x if kind == "activity2" else build_variant(gt3x, tmp_path / f"{kind}.gt3x", kind)
    rec = read_gt3x(src)
    acc = next(s for s in rec.imus if not s.name.endswith("_imu"))
    assert len(acc) == len(ref["time_s"]) == 16200
    t = _wall_s(rec.metadata["imulog.trial"]["start_time"], acc.t_ns)
    # within one sample is the requirement; they are equal to float64 rounding
    np.testing.assert_allclose(t, ref["time_s"], atol=1e-6, rtol=0)
    np.testing.assert_allclose(acc.acc / G0, ref["counts"] / 256.0, atol=1e-12, rtol=0)


def test_activity3_variant_through_the_cli(gt3x: Path, tmp_path: Path):
    src = build_variant(gt3x, tmp_path / "a3.gt3x", "activity3")
    out = tmp_path / "a3.mcap"
    r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert CliRunner().invoke(cli, ["doctor", str(out)]).exit_code == 0
    with TrialReader(out) as trial:
        acc = trial.read("/imu/tas1e31150129")
        np.testing.assert_allclose(acc.acc[:, 2] / G0, np.load(REF)["counts"][:, 2] / 256.0, atol=1e-6)


def test_one_byte_activity_records_are_usb_events(gt3x: Path, tmp_path: Path):
    """A 1-byte ACTIVITY/ACTIVITY3 payload marks a USB connection (pygt3x skips it): no samples, no error."""
    import struct
    import zipfile

    from gt3x_variants import _record

    src = build_variant(gt3x, tmp_path / "a3.gt3x", "activity3")
    with zipfile.ZipFile(src) as z:
        info, log = z.read("info.txt"), z.read("log.bin")
    last = struct.unpack_from("<I", log, log.rfind(b"\x1e\x1b") + 2)[0]
    log += _record(0x1B, last + 1, b"\x01") + _record(0x00, last + 2, b"\x01")
    usb = tmp_path / "usb.gt3x"
    with zipfile.ZipFile(usb, "w") as z:
        z.writestr("info.txt", info)
        z.writestr("log.bin", log)
    acc = next(s for s in read_gt3x(usb).imus if not s.name.endswith("_imu"))
    assert np.isfinite(acc.acc).all() and len(acc) == 16200
