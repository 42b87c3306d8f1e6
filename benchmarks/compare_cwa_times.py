"""Axivity .cwa sample times: imulog's two rules against the other decoders, on the shared AX3/AX6 samples and
GGIRread's AX3 and AX6 test files (tests/data).

For each file and each imulog rule (``skdh``, the default, and ``openmovement``) it prints, in ms, the difference
of each peer decode minus imulog's: the first sample, the median over all samples and the largest over all block
starts. Peers: scikit-digital-health's ``ReadCwa`` (run here), its shipped decode (``*_data.npz``), OpenMovement's
per-block ``estimatedFirstSampleTime`` and its whole-file ``CwaData`` (per-sample: anchors at the sample where the
block's time stamp applies, linear in between; it does not extrapolate before the first anchor, hence its first
sample), and GGIR's CSV export of GGIRread's AX6 file (its first 210 samples). No timing: a comparison of decodes.

    .venv/bin/python benchmarks/compare_cwa_times.py
"""

from __future__ import annotations

import lzma
import tempfile
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEVICES = ROOT.parent / "shared" / "data" / "devices" / "axivity_cwa"
TESTDATA = ROOT / "tests" / "data"


def _abs_s(rec) -> np.ndarray:
    start = np.datetime64(rec.metadata["imulog.trial"]["start_time"], "ns").astype(np.int64)
    return (start + rec.imus[0].t_ns) / 1e9


def _om_cwadata(path: Path) -> np.ndarray | None:
    """OpenMovement's whole-file sample times; its loader overflows a uint16 column under numpy 2, so the two
    columns it does arithmetic on are widened first (its rule is unchanged)."""
    try:
        import openmovement.load.cwa_load as cl
    except ImportError:
        return None
    orig = cl.CwaData._parse_times

    def widened(self):
        for c in ("device_fractional", "timestamp_offset"):
            self.df[c] = self.df[c].astype("int64")
        return orig(self)

    cl.CwaData._parse_times = widened
    try:
        with cl.CwaData(str(path), include_gyro=True) as cd:
            return np.asarray(cd.get_sample_values()[:, 0], dtype=np.float64)
    finally:
        cl.CwaData._parse_times = orig


def _om_block_starts(path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    try:
        from openmovement.load.cwa_load import _parse_cwa_data
    except ImportError:
        return None
    data = path.read_bytes()
    blocks = [_parse_cwa_data(data[k : k + 512]) for k in range(1024, len(data), 512)]
    blocks = [b for b in blocks if b.get("sampleCount")]
    first = np.concatenate([[0], np.cumsum([b["sampleCount"] for b in blocks])[:-1]])
    return first, np.array([b["estimatedFirstSampleTime"] for b in blocks])


def _skdh(path: Path) -> np.ndarray | None:
    try:
        from skdh.io import ReadCwa
    except ImportError:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.asarray(ReadCwa().predict(file=str(path))["time"], dtype=np.float64)


def _row(name: str, peer: np.ndarray, ours: np.ndarray, first: np.ndarray) -> str:
    n = min(len(peer), len(ours))
    d = (peer[:n] - ours[:n]) * 1e3
    db = d[first[first < n]]
    return f"  {name:26s} first {d[0]:+9.3f}  median {np.median(d):+8.3f}  block starts max |d| {np.abs(db).max():7.3f}"


def main() -> None:
    from imulog.converters import ConvertOptions, convert_file
    from imulog.converters.axivity import read_cwa

    with tempfile.TemporaryDirectory() as tmp:
        files = {"ax3_sample.cwa": DEVICES / "ax3_sample.cwa", "ax6_sample.cwa": DEVICES / "ax6_sample.cwa"}
        for name in ("ax3_testfile.cwa", "ax6_testfile_first8blocks.cwa", "ax6_testfile_formatted_timestamps.csv"):
            out = Path(tmp) / name
            out.write_bytes(lzma.decompress((TESTDATA / f"{name}.xz").read_bytes()))
            files[f"GGIRread {name}"] = out
        csv = files.pop("GGIRread ax6_testfile_formatted_timestamps.csv")
        print("peer minus imulog, ms (first sample; median over samples; largest over block starts)")
        for label, path in files.items():
            peers: dict[str, np.ndarray | tuple[np.ndarray, np.ndarray] | None] = {
                "skdh ReadCwa": _skdh(path),
                "OpenMovement CwaData": _om_cwadata(path),
                "OpenMovement block starts": _om_block_starts(path),
            }
            npz = DEVICES / path.name.replace("_sample.cwa", "_data.npz")
            if path.parent == DEVICES and npz.exists():
                peers["skdh shipped .npz"] = np.load(npz)["time"]
            if "ax6_testfile" in label:
                peers["GGIR CSV export"] = _abs_s(convert_file(csv))
            for rule in ("skdh", "openmovement"):
                rec = read_cwa(path, ConvertOptions(extra={"cwa_times": rule}))
                ours = _abs_s(rec)
                print(f"{label} ({len(ours)} samples), imulog --cwa-times {rule}")
                bs = _om_block_starts(path)
                first = bs[0] if bs is not None else np.array([0])
                for name, peer in peers.items():
                    if peer is None:
                        print(f"  {name:26s} (not installed)")
                    elif isinstance(peer, tuple):
                        d = (peer[1] - ours[peer[0]]) * 1e3
                        print(
                            f"  {name:26s} first {d[0]:+9.3f}  median {np.median(d):+8.3f}  "
                            f"block starts max |d| {np.abs(d).max():7.3f}"
                        )
                    else:
                        print(_row(name, peer, ours, first))


if __name__ == "__main__":
    main()
