"""Every text format that converts in pieces, with the defects real exports have (a cut last row, a blank line, a NaN
field, a byte-order mark, CRLF line ends), gives in pieces what it gives whole (issue 24, item 4): the same
recording and warnings, or the same one-line error. The files are the first 80 lines of a shared sample of each
format (its header and first rows); the pieces are 1 byte (every line break a border), a row, a row and a half and
two random sizes up to five rows, so that a border falls before, on and after the defective line."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from imulog.converters._binary import concat_chunks
from imulog.converters.errors import ConversionError
from imulog.converters.registry import get
from test_convert_vicon_pieces import assert_same_nexus

TEXT = "imulog.converters._pieces.PIECE_BYTES"

#: (converter, a shared file of its format under ../shared/data)
CASES = [
    ("delimited", "imu_text/fusion_sensor_data.csv"),
    ("delimited", "imu_text/shimmer_consensys_export.csv"),
    ("gaitmap", "gaitmap_foot/imu_sample.csv"),
    ("gaitmap", "gaitmap_foot/mocap_sample.csv"),
    ("actilife-csv", "devices/actigraph_gt3x/exampleRAW.csv"),
    ("actilife-csv", "devices/actigraph_gt3x/example-IMU.csv"),
    ("actilife-csv", "devices/actigraph_count_csv/ActiGraph13.csv"),
    ("axivity-csv", "devices/axivity_csv/ax3_testfile_unix_timestamps.csv"),
    ("movella-dot", "devices/movella_dot_csv/bei_D4CA6EF17860_20210830_170505.csv"),
    ("nilspod", "devices/nilspod/NilsPodX-6F13_20210109_162824_data.csv"),
    ("xsens", "devices/xsens_mtmanager/MT_01200454_000-000_00B40DE4.txt"),
    ("xsens", "devices/xsens_mtmanager/MT2022_ACC_GYRO_ROT_MAT_SPACE_00B42D4B.txt"),
    ("vicon-csv", "vicon_nexus/markers.csv"),
    ("motive", "devices/optitrack_motive/sample_optitrack_take.csv"),
    ("opensim-trc", "devices/opensim_trc/markers.trc"),
    ("opensim-sto", "devices/opensim_mot/inverse_kin.mot"),
    ("opensim-sto", "devices/opensense_sto/myComplexTasksTrial_orientations.sto"),
    ("delsys", "devices/delsys_trigno/truncated_trigno_sample.csv"),
    ("empatica-e4", "devices/empatica_e4/ACC.csv"),
    ("apdm", "devices/apdm_csv/imuData01.csv"),
    ("apdm", "devices/apdm_csv/apdm_format7.csv"),
]

LINES = 80  # lines of the sample kept: its header and first rows


def _line_break(text: bytes) -> bytes:
    return b"\r\n" if b"\r\n" in text else b"\n"


def _replace_line(text: bytes, k: int, new: Callable[[bytes], bytes]) -> bytes:
    """``text`` with its line ``k`` from the end of the data (1: the last) replaced by ``new(line)``."""
    nl = _line_break(text)
    lines = text.split(nl)
    k = min(k, max(1, (len(lines) - 3) // 2))  # a short sample (3 header lines): a row in its middle
    lines[-k] = new(lines[-k])
    return nl.join(lines)


def _nan_field(line: bytes) -> bytes:
    """The line with its third field (or the last when fewer) written ``NaN``."""
    for sep in (b",", b"\t", b";", b" "):
        cells = line.split(sep)
        if len(cells) > 2:
            cells[min(2, len(cells) - 1)] = b"NaN"
            return sep.join(cells)
    return line


DEFECTS: dict[str, Callable[[bytes], bytes]] = {
    "none": lambda text: text,
    "cut last row": lambda text: text[: -max(2, len(text.rsplit(_line_break(text), 1)[-1]) // 3)],
    "cut last row, line break kept": lambda text: _replace_line(text, 1, lambda ln: ln[: len(ln) // 2]) + b"\n",
    "blank line": lambda text: _replace_line(text, 12, lambda ln: ln + _line_break(text)),
    "NaN field": lambda text: _replace_line(text, 12, _nan_field),
    "byte-order mark": lambda text: b"\xef\xbb\xbf" + text,
    "CRLF": lambda text: text.replace(b"\r\n", b"\n").replace(b"\n", b"\r\n"),
    "trailing blank lines": lambda text: text + _line_break(text) * 3,
}


def _sample(src: Path) -> bytes:
    """The first :data:`LINES` lines of ``src``, without a final line break."""
    nl = _line_break(src.read_bytes()[:65536])
    with open(src, "rb") as f:
        return b"".join(f.readline() for _ in range(LINES)).rstrip(b"\r\n").replace(nl, nl)


def _outcome(read: Callable) -> tuple:
    try:
        return "ok", read()
    except ConversionError as e:
        return "error", str(e)


@pytest.mark.parametrize(("name", "rel"), CASES, ids=[f"{c[0]}:{Path(c[1]).name}" for c in CASES])
def test_defects_give_the_same_outcome_in_any_pieces(name, rel, shared_data, tmp_path, monkeypatch):
    src = shared_data / rel
    conv = get(name)
    text = _sample(src)
    row = max(1, len(text) // LINES)
    rng = np.random.default_rng(len(text))
    sizes = [1, row, row * 3 // 2, *rng.integers(1, 5 * row, 2).tolist()]
    found = []
    for defect, make in DEFECTS.items():
        folder = tmp_path / defect.replace(" ", "_").replace(",", "")
        folder.mkdir()
        path = folder / src.name
        path.write_bytes(make(text))
        for sidecar in src.parent.glob(src.stem.rsplit("_data", 1)[0] + "_header.json"):  # NilsPod's CSV export
            (folder / sidecar.name).write_bytes(sidecar.read_bytes())
        monkeypatch.setattr(TEXT, 1 << 30)
        whole = _outcome(lambda p=path: conv.convert(p))
        for piece_bytes in sizes:
            monkeypatch.setattr(TEXT, piece_bytes)
            got = _outcome(lambda p=path: concat_chunks(list(conv.iter_chunks(p))))
            if got[0] != whole[0] or (got[0] == "error" and got[1] != whole[1]):
                found.append(
                    (
                        defect,
                        piece_bytes,
                        whole[0],
                        whole[1] if whole[0] == "error" else "",
                        got[1] if got[0] == "error" else "",
                    )
                )
                continue
            if got[0] == "ok":
                try:
                    assert_same_nexus(got[1], whole[1])
                except AssertionError as e:
                    found.append((defect, piece_bytes, "differs", str(e)[:300], ""))
    assert not found, "\n".join(map(str, found))
