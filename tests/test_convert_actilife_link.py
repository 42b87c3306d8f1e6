"""The Actigraph Link's epoch export (GGIRread's real ActiGraph13_timestamps_headers.csv, tests/data, Apache-2.0):
a 'Data Table File Created By Actigraph Link' banner whose Start Date (09-12-2017, month first) does not match its
declared date format (dd/MM/yyyy), then a names row and ISO time stamps ending in Z."""

from __future__ import annotations

import lzma
import warnings
from pathlib import Path

import numpy as np
from imulog.converters import convert_file, detect

DATA = Path(__file__).parent / "data" / "ActiGraph13_timestamps_headers.csv.xz"


def test_link_epoch_export_equals_ggirreads_documented_values(tmp_path: Path):
    """GGIRread's test_readActiGraphCount.R: 1000 epochs of 1 s, serial TAS1D48140206, x + y + z + vm summing to
    255 707.4 (vm = the vector magnitude it computes), 442 steps. Its start (2017-12-09) comes from the time format
    its test passes; the rows' own stamps, the banner's Start Time and the Download Date (09-19-2017: month first)
    all say 2017-09-12 15:00, which imulog keeps, saying why."""
    path = tmp_path / "ActiGraph13_timestamps_headers.csv"
    path.write_bytes(lzma.decompress(DATA.read_bytes()))
    assert detect(path).name == "actilife-csv"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no pandas/numpy warning reaches the user
        rec = convert_file(path)
    (sig,) = rec.signals
    c = sig.columns
    assert len(sig) == 1000 and c == ["axis1", "axis2", "axis3", "steps", "vm"]
    xyz = sig.values[:, :3]
    assert abs(xyz.sum() + np.sqrt((xyz**2).sum(axis=1)).sum() - 255707.4) < 0.1
    assert sig.values[:, 3].sum() == 442
    np.testing.assert_array_equal(np.diff(sig.t_ns), 1_000_000_000)
    dev = rec.metadata["imulog.device.tas1d48140206_counts"]
    assert dev["serial"] == "TAS1D48140206" and dev["epoch_s"] == 1.0 and dev["model"] == "Actigraph Link"
    assert rec.metadata["imulog.trial"]["start_time"] == "2017-09-12T15:00:00.000"
    (w,) = [w for w in rec.warnings if "Start Date" in w]
    assert "'09-12-2017 15:00:00' does not match its date format dd/MM/yyyy" in w
