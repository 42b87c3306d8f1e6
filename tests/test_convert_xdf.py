"""XDF: the xdf-modules example files (MIT) against the values their README documents (clock offsets, host clock
reset, empty streams, string markers), IMU and mocap streams in a file the test writes, and damaged files."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from imulog.converters import ConversionError, detect
from imulog.converters._common import G0
from imulog.converters.xdf import iter_chunks, read_xdf, scan_chunks

from imulog.archive import TrialReader
from imulog.cli import cli


@pytest.fixture(scope="module")
def xdf_dir(shared_data: Path) -> Path:
    return shared_data / "devices" / "xdf"


def test_clock_reset_file_matches_the_readme(xdf_dir: Path):
    rec = read_xdf(xdf_dir / "clock_resets.xdf")
    eeg = next(s for s in rec.signals if s.topic == "/signals/biosemi")
    markers = next(e for e in rec.events if e.topic == "/events/mymarkerstream")
    assert eeg.values.shape == (27815, 8) and len(markers) == 175
    t = eeg.t_ns / 1e9
    # footer first/last time stamps + first/last clock offsets (README_example-files.md), both sides of the reset
    assert t[0] == pytest.approx(653150.379117 - 652340.28383985, abs=1e-3)
    assert t[-1] == pytest.approx(261.9267033 + 1121.1656319, abs=1e-3)
    m = markers.start_ns / 1e9
    assert m[0] == pytest.approx(653153.2121885 - 652340.2838639501, abs=1e-3)
    assert m[-1] == pytest.approx(259.6538279 + 1121.165595, abs=1e-3)
    assert np.all(np.diff(eeg.t_ns) > 0) and np.all(np.diff(markers.start_ns) > 0)  # one axis across the reset
    assert np.array_equal(markers.start_ns, markers.end_ns)
    assert markers.labels[:5] == ["XXX", "Test", "Blah", "Test", "Test-1-2-3"] and markers.labels[-1] == "XXX"
    np.testing.assert_allclose(eeg.values[0], [0.142, 0.463, 0.354, 0.220, 0.761, 0.323, 0.312, 0.861], atol=5e-4)
    dev = rec.metadata["imulog.device.biosemi"]
    assert dev["nominal_srate_hz"] == 100.0 and dev["clock_segments"] == 2 and dev["stream_type"] == "EEG"


def test_minimal_and_empty_streams(xdf_dir: Path):
    rec = read_xdf(xdf_dir / "minimal.xdf")
    data = rec.signals[0]
    assert data.topic == "/signals/senddatac" and data.values.shape == (9, 3)
    np.testing.assert_array_equal(data.values[:2], [[192, 255, 238], [12, 22, 32]])
    np.testing.assert_allclose(data.t_ns / 1e9, np.arange(5.1, 5.95, 0.1) - 0.1, atol=1e-9)  # offsets of -0.1 s
    strings = rec.events[0]
    np.testing.assert_allclose(strings.start_ns / 1e9, np.arange(5.1, 5.95, 0.1), atol=1e-9)  # no offsets
    assert strings.labels[1:5] == ["Hello", "World", "from", "LSL"]
    assert "imulog.trial" not in rec.metadata  # minimal.xdf's header has no datetime

    rec = read_xdf(xdf_dir / "empty_streams.xdf")
    topics = {s.topic: len(s) for s in rec.streams()}
    assert topics == {
        "/signals/empty_data_stream_test_stream_0_counter": 0,
        "/signals/data_stream_test_stream_0_counter": 10,
        "/events/ctrl": 1,
        "/events/empty_marker_stream_test_stream_0_counter": 0,
    }
    assert rec.events[0].labels == ['{"state": 2}']
    assert rec.metadata["imulog.trial"] == {"start_time": "2025-01-31T00:21:17.000+00:00", "time_zone": "UTC"}
    assert rec.metadata["imulog.device.ctrl"]["manufacturer"] == "pylsltools"


def _pyxdf_ns(path: Path) -> dict[str, tuple[np.ndarray, object]]:
    """pyxdf's reading (the reference): {stream name: (stamps in ns, samples)}, clocks synchronised, no dejitter."""
    pyxdf = pytest.importorskip("pyxdf")
    streams, _ = pyxdf.load_xdf(str(path), synchronize_clocks=True, handle_clock_resets=True, dejitter_timestamps=False)
    return {
        s["info"]["name"][0]: (np.round(s["time_stamps"] * 1e9).astype(np.int64), s["time_series"]) for s in streams
    }


@pytest.mark.parametrize("name", ["clock_resets.xdf", "minimal.xdf", "empty_streams.xdf"])
def test_chunk_by_chunk_equals_pyxdf_and_pieces_equal_the_whole(xdf_dir: Path, name: str):
    """imulog reads XDF chunk by chunk with pyxdf's clock synchronisation: every stamp (ns) and value equals pyxdf's,
    and pieces of 64 bytes to 50 kB joined equal the one piece (the first declares spans and meta)."""
    from imulog.converters._binary import concat_chunks

    from imulog.model import PIECES_RECORD

    path = xdf_dir / name
    whole = read_xdf(path)
    ref = _pyxdf_ns(path)
    for s in whole.streams():
        meta = whole.metadata[f"imulog.device.{s.topic.rsplit('/', 1)[-1]}"]
        t_ref, series = ref[meta["stream_name"]]
        t = s.start_ns if s.topic.startswith("/events/") else s.t_ns
        np.testing.assert_array_equal(t, t_ref)
        if s.topic.startswith("/signals/"):
            np.testing.assert_array_equal(s.values, np.asarray(series, dtype=np.float64).reshape(s.values.shape))
    for piece_bytes in (64, 1000, 50_000):
        pieces = list(iter_chunks(path, piece_bytes=piece_bytes))
        assert PIECES_RECORD in pieces[0].metadata and PIECES_RECORD not in whole.metadata
        assert {s.topic for s in pieces[0].streams()} == {s.topic for s in whole.streams()}
        joined = concat_chunks(pieces)
        assert [s.topic for s in joined.streams()] == [s.topic for s in whole.streams()]
        for a, b in zip(joined.streams(), whole.streams(), strict=True):
            for f in ("t_ns", "values", "start_ns", "end_ns"):
                if hasattr(a, f):
                    assert getattr(a, f).tobytes() == getattr(b, f).tobytes(), (a.topic, f)
        assert joined.metadata == whole.metadata
    if name == "clock_resets.xdf":
        assert len(list(iter_chunks(path, piece_bytes=50_000))) > 5


# ---------------------------------------------------------------------------------------- a file written here
def _chunk(tag: int, content: bytes) -> bytes:
    body = struct.pack("<H", tag) + content
    n = len(body)
    return (bytes([1, n]) if n < 256 else bytes([4]) + struct.pack("<I", n)) + body


def _header(sid: int, name: str, stype: str, channels: list[tuple[str, str, str]], srate: float) -> bytes:
    ch = "".join(f"<channel><label>{lab}</label><unit>{u}</unit><type>{t}</type></channel>" for lab, u, t in channels)
    xml = (
        f'<?xml version="1.0"?><info><name>{name}</name><type>{stype}</type><channel_count>{len(channels)}'
        f"</channel_count><nominal_srate>{srate}</nominal_srate><channel_format>float32</channel_format>"
        f"<source_id>{name}-1</source_id><desc><channels>{ch}</channels></desc></info>"
    )
    return _chunk(2, struct.pack("<I", sid) + xml.encode())


def _samples(sid: int, t: np.ndarray, values: np.ndarray) -> bytes:
    body = struct.pack("<I", sid) + bytes([4]) + struct.pack("<I", len(t))
    for ti, row in zip(t, values, strict=True):
        body += bytes([8]) + struct.pack("<d", ti) + row.astype("<f4").tobytes()
    return _chunk(3, body)


def _write_lab_xdf(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    n = 50
    t = 1000.0 + np.arange(n) / 100.0
    imu = np.column_stack(
        [rng.normal(0, 0.05, (n, 2)), 1 + rng.normal(0, 0.05, n), rng.normal(0, 20, (n, 3)), rng.normal(0, 1, n)]
    )
    mocap = rng.normal(500, 100, (n, 6))
    imu_ch = [(f"Acc{a}", "g", "Accelerometer") for a in "XYZ"] + [(f"Gyro{a}", "deg/s", "Gyroscope") for a in "XYZ"]
    imu_ch.append(("Battery", "V", "misc"))
    mocap_ch = [(f"{m}_{a}", "mm", "Position") for m in ("wrist", "elbow") for a in "XYZ"]
    data = (
        b"XDF:"
        + _chunk(
            1, b'<?xml version="1.0"?><info><version>1.0</version><datetime>2024-05-06T10:11:12+0200</datetime></info>'
        )
        + _header(1, "WristIMU", "IMU", imu_ch, 100)
        + _header(2, "Qualisys", "MoCap", mocap_ch, 100)
        + _samples(1, t[:25], imu[:25])
        + _samples(2, t[:25], mocap[:25])
        + _chunk(4, struct.pack("<Idd", 1, 1000.2, -0.5))
        + _chunk(4, struct.pack("<Idd", 2, 1000.2, -0.25))
        + _samples(1, t[25:], imu[25:])
        + _samples(2, t[25:], mocap[25:])
        + _chunk(4, struct.pack("<Idd", 1, 1000.6, -0.5))
        + _chunk(4, struct.pack("<Idd", 2, 1000.6, -0.25))
    )
    path.write_bytes(data)
    return t, imu.astype(np.float32).astype(np.float64), mocap.astype(np.float32).astype(np.float64)


def test_imu_and_mocap_streams_by_channel_labels_and_units(tmp_path: Path):
    path = tmp_path / "lab.xdf"
    t, imu_values, mocap_values = _write_lab_xdf(path)
    assert detect(path).name == "xdf"
    rec = read_xdf(path)
    imu = rec.imus[0]
    assert imu.topic == "/imu/wristimu"
    np.testing.assert_allclose(imu.acc, imu_values[:, :3] * G0, rtol=1e-12)
    np.testing.assert_allclose(imu.gyr, np.radians(imu_values[:, 3:6]), rtol=1e-12)
    np.testing.assert_allclose(imu.t_ns / 1e9, t - 0.5, atol=1e-6)  # clock offset applied
    rest = next(s for s in rec.signals if s.topic == "/signals/wristimu")
    assert rest.columns == ["Battery"] and rest.units == ["V"]
    markers = rec.markers[0]
    assert markers.topic == "/markers/qualisys" and markers.labels == ["wrist", "elbow"]
    np.testing.assert_allclose(markers.pos, mocap_values.reshape(-1, 2, 3) / 1000.0, rtol=1e-12)
    np.testing.assert_allclose(markers.t_ns / 1e9, t - 0.25, atol=1e-6)
    assert rec.metadata["imulog.trial"] == {"start_time": "2024-05-06T10:11:12.000+02:00", "time_zone": "+02:00"}


def test_imu_labels_without_units_stay_signals(tmp_path: Path):
    path = tmp_path / "nounits.xdf"
    t = np.arange(5) / 10.0
    path.write_bytes(
        b"XDF:"
        + _chunk(1, b"<info><version>1.0</version></info>")
        + _header(1, "imu", "IMU", [(f"Acc{a}", "", "") for a in "XYZ"], 10)
        + _samples(1, t, np.ones((5, 3)))
    )
    rec = read_xdf(path)
    assert not rec.imus and rec.signals[0].columns == ["AccX", "AccY", "AccZ"] and rec.signals[0].units == [""] * 3


# --------------------------------------------------------------------------------------------- damage and CLI
@pytest.mark.parametrize("how", ["truncate", "flip"])
def test_damaged_file_one_line_error_naming_the_chunk(xdf_dir: Path, tmp_path: Path, how: str):
    data = bytearray((xdf_dir / "clock_resets.xdf").read_bytes())
    # walk to chunk 40 independently of the converter
    pos, index = 4, 0
    while index < 40:
        width = data[pos]
        length = int.from_bytes(data[pos + 1 : pos + 1 + width], "little")
        pos += 1 + width + length
        index += 1
    if how == "truncate":
        width = data[pos]
        data = data[: pos + 1 + width + 5]
    else:
        data[pos] = 3  # chunk-length width byte must be 1, 4 or 8
    bad = tmp_path / f"{how}.xdf"
    bad.write_bytes(bytes(data))
    with pytest.raises(ConversionError) as e:
        scan_chunks(bad)
    msg = str(e.value)
    assert "\n" not in msg and bad.name in msg and f"chunk 40 (byte {pos})" in msg
    out = tmp_path / "out.mcap"
    r = CliRunner().invoke(cli, ["convert", str(bad), "-o", str(out)])
    assert r.exit_code != 0 and "chunk 40" in r.output
    assert not list(tmp_path.glob("*.mcap*"))


def test_damaged_samples_chunk_is_named_not_misread(xdf_dir: Path, tmp_path: Path):
    """A bad time-stamp flag inside a Samples chunk: pyxdf would read misaligned values silently."""
    from imulog.converters.xdf import iter_chunk_headers

    src = xdf_dir / "clock_resets.xdf"
    data = bytearray(src.read_bytes())
    index, at, _, start, _ = [c for c in iter_chunk_headers(src) if c[2] == 3][10]
    width = data[start + 4]
    data[start + 4 + 1 + width] = 0x07  # first sample's time-stamp flag must be 0 or 8
    bad = tmp_path / "flag.xdf"
    bad.write_bytes(bytes(data))
    with pytest.raises(ConversionError, match=rf"flag\.xdf: chunk {index} \(byte {at}\): damaged Samples chunk"):
        read_xdf(bad)


def test_cli_converts_every_example_and_doctor_passes(xdf_dir: Path, tmp_path: Path):
    for src in sorted(xdf_dir.glob("*.xdf")):
        out = tmp_path / f"{src.stem}.mcap"
        r = CliRunner().invoke(cli, ["convert", str(src), "-o", str(out)])
        assert r.exit_code == 0, r.output
        r = CliRunner().invoke(cli, ["doctor", str(out)])
        assert r.exit_code == 0, r.output
        with TrialReader(out) as trial:
            assert trial.topics()
            if src.stem == "empty_streams":
                assert "/events/empty_marker_stream_test_stream_0_counter" in trial.topics()
                assert "/signals/empty_data_stream_test_stream_0_counter" in trial.topics()


def test_a_stream_whose_chunks_come_later_but_start_earlier(tmp_path: Path, monkeypatch):
    """The case that kept XDF out of piece-wise conversion: the mocap stream's chunks all come after the IMU's in the
    file, yet its samples start 2 s earlier. In pieces the first piece declares every stream's span, so the trial's
    time origin (and every channel's log-time map) is the whole file's: both archives are equal sample by sample."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from test_convert_pieces_archive import assert_same_trial, convert_twice

    rng = np.random.default_rng(5)
    n = 400
    t_imu = 1002.0 + np.arange(n) / 100.0
    t_mocap = 1000.0 + np.arange(n) / 100.0
    imu_ch = [(f"Acc{a}", "g", "Accelerometer") for a in "XYZ"]
    mocap_ch = [(f"wrist_{a}", "mm", "Position") for a in "XYZ"]
    imu, mocap = rng.normal(0, 1, (n, 3)), rng.normal(500, 10, (n, 3))
    body = b"XDF:" + _chunk(1, b'<?xml version="1.0"?><info><version>1.0</version></info>')
    body += _header(1, "WristIMU", "IMU", imu_ch, 100) + _header(2, "Qualisys", "MoCap", mocap_ch, 100)
    for lo in range(0, n, 50):
        body += _samples(1, t_imu[lo : lo + 50], imu[lo : lo + 50])
    for lo in range(0, n, 50):
        body += _samples(2, t_mocap[lo : lo + 50], mocap[lo : lo + 50])
    path = tmp_path / "late.xdf"
    path.write_bytes(body)
    whole, pieces = convert_twice(path, tmp_path, ("imulog.converters.xdf.PIECE_BYTES", 2000), monkeypatch)
    assert_same_trial(whole, pieces)
    with TrialReader(pieces) as trial:
        timeline = trial.metadata["imulog.timeline"]  # one clock: both start at the mocap's first sample
        assert timeline["clocks"] == "shared" and timeline["device_origin_ns"] == round(1000.0 * 1e9)
        assert trial.read("/markers/qualisys").t_ns[0] == round(1000.0 * 1e9)


def test_an_empty_mocap_stream_is_a_channel_without_samples(tmp_path: Path, monkeypatch):
    """A MoCap stream that recorded nothing (its header only) is a marker channel with zero samples, its labels and
    meta kept, whole and in pieces (the codec could not encode a marker stream without samples); a MoCap stream
    whose samples all come after the first piece opens its channel in the first piece, as the whole file does."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from test_convert_pieces_archive import assert_same_trial, convert_twice

    rng = np.random.default_rng(7)
    n = 300
    t = 1000.0 + np.arange(n) / 100.0
    imu_ch = [(f"Acc{a}", "g", "Accelerometer") for a in "XYZ"]
    mocap_ch = [(f"{m}_{a}", "mm", "Position") for m in ("wrist", "elbow") for a in "XYZ"]
    body = b"XDF:" + _chunk(1, b'<?xml version="1.0"?><info><version>1.0</version></info>')
    body += _header(1, "Late", "MoCap", mocap_ch[:3], 100)  # stream 1: its channel comes first
    body += _header(2, "WristIMU", "IMU", imu_ch, 100) + _header(3, "Empty", "MoCap", mocap_ch, 100)
    imu = rng.normal(0, 1, (n, 3))
    for lo in range(0, n, 50):
        body += _samples(2, t[lo : lo + 50], imu[lo : lo + 50])
    body += _samples(1, t[-20:], rng.normal(500, 10, (20, 3)))
    path = tmp_path / "empty_mocap.xdf"
    path.write_bytes(body)
    rec = read_xdf(path)
    empty = next(m for m in rec.markers if m.topic == "/markers/empty")
    assert len(empty.t_ns) == 0 and empty.labels == ["wrist", "elbow"] and empty.pos.shape == (0, 2, 3)
    whole, pieces = convert_twice(path, tmp_path, ("imulog.converters.xdf.PIECE_BYTES", 2000), monkeypatch)
    assert_same_trial(whole, pieces)
    with TrialReader(whole) as a, TrialReader(pieces) as trial:
        opened = [[c.topic for c in t.channels if not c.metadata.get("twin_of")] for t in (a, trial)]
        assert opened[0] == opened[1]  # every channel opened in the first piece, in the whole file's order
        info = trial.channel("/markers/empty")
        assert info.sample_count == 0 and info.message_count == 0
        got = trial.read("/markers/empty")
        assert got.labels == ["wrist", "elbow"] and got.pos.shape == (0, 2, 3)
        assert got.meta["stream_type"] == "MoCap" and got.meta == empty.meta
        assert len(trial.read("/markers/late").t_ns) == 20
    r = CliRunner().invoke(cli, ["doctor", str(pieces)])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(cli, ["info", str(pieces)])
    assert r.exit_code == 0 and "/markers/empty" in r.output, r.output
    out = tmp_path / "empty.csv"
    r = CliRunner().invoke(cli, ["export", str(pieces), "-t", "/markers/empty", "-o", str(out)])
    assert r.exit_code == 0 and "0 rows" in r.output, r.output
    assert out.read_text().splitlines()[0].startswith('"t[s]","t_ns","wrist_x[m]"')


def test_one_xml_parser_for_files_and_live_headers(tmp_path: Path):
    """The XDF reader and the live capture parse a stream header with one function (``xdf_read.xml_dict``), in
    pyxdf's layout and equal to pyxdf's ``_xml2dict``, as plain dicts: a missing key raises instead of appearing."""
    import xml.etree.ElementTree as ET

    from imulog.converters import xdf_read

    import imulog.live.mapping as live

    assert live.xml_dict is xdf_read.xml_dict and not hasattr(live, "xml_to_dict")
    chunk = _header(1, "Qualisys", "MoCap", [(f"wrist_{a}", "mm", "Position") for a in "XYZ"], 100)
    path = tmp_path / "header.xdf"
    path.write_bytes(b"XDF:" + _chunk(1, b"<info><version>1.0</version></info>") + chunk)
    info = xdf_read.scan(path).streams[1].info
    xml = chunk[chunk.index(b"<?xml") :].decode()
    assert live.header_info(xml, 1) == {**info, "stream_id": ["1"]}
    assert {"info": info} == pytest.importorskip("pyxdf.pyxdf")._xml2dict(ET.fromstring(xml))
    channel = info["desc"][0]["channels"][0]["channel"][2]
    assert channel == {"label": ["wrist_Z"], "unit": ["mm"], "type": ["Position"]}
    for d in (info, info["desc"][0], channel):
        assert type(d) is dict
    with pytest.raises(KeyError):
        info["manufacturer"]  # noqa: B018
    assert "manufacturer" not in info
