"""Bad input: one ConversionError with a one-line message naming file, line and/or column; never anything else.

The explicit cases pin the message for each kind of damage; the property-based tests (hypothesis) damage valid
files of every text format at random and require that a converter either reads them (with sane output) or
raises ConversionError, nothing else.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from imulog.converters import ConversionError, ConvertOptions, UnknownFormatError, convert_file, get

from imulog.model import Recording

FUSION = (
    "Time (s),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),Accelerometer X (g),Accelerometer Y (g),"
    "Accelerometer Z (g),Magnetometer X (uT),Magnetometer Y (uT),Magnetometer Z (uT)\n"
    + "".join(f"{i * 0.01:.2f},0.1,-0.2,0.3,0.01,-0.02,0.99,15.3,0.4,-41.0\n" for i in range(8))
)
SHIMMER = (
    '"sep=;"\nS_1_Timestamp_Unix_CAL;S_1_Accel_LN_X_CAL;S_1_Accel_LN_Y_CAL;S_1_Accel_LN_Z_CAL;S_1_Gyro_X_CAL;S_1_Gyro_Y_CAL;S_1_Gyro_Z_CAL;\n'
    "ms;m/(s^2);m/(s^2);m/(s^2);deg/s;deg/s;deg/s;\n"
    + "".join(f"{1000 + 20 * i};-1.4;10.0;0.5;0.1;1.8;-0.2;\n" for i in range(8))
)
MAPPED_CSV = "timestamp,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 8.7:.3f},0.01,0.02,0.98,0.4,0.1,-0.1\n" for i in range(8))
MAPPING = {
    "format": "imulog.mapping/1",
    "device": {"name": "wrist", "rate_hz": 115.0},
    "time": {"column": "timestamp", "unit": "ms"},
    "columns": {
        **{f"a{a}": {"quantity": "acc", "axis": a, "unit": "g"} for a in "xyz"},
        **{f"g{a}": {"quantity": "gyr", "axis": a, "unit": "dps"} for a in "xyz"},
    },
}
GAITMAP = (
    "sensor,left_sensor,left_sensor,left_sensor,left_sensor,left_sensor,left_sensor\n"
    "axis,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z\n" + "".join(f"{i},0.8,2.7,9.4,-0.1,0.03,-0.06\n" for i in range(8))
)
XSENS = (
    "// Device information:\n//  DeviceId: 00B41234\n// Update Rate: 100.0Hz\n"
    "PacketCounter\tSampleTimeFine\tAcc_X\tAcc_Y\tAcc_Z\tGyr_X\tGyr_Y\tGyr_Z\n"
    + "".join(f"{(65533 + i) % 65536:05d}\t\t0.1\t0.2\t9.8\t0.01\t0.02\t0.03\n" for i in range(8))
)
ADC = "".join(f"X={510 + i}\tY=498\tZ=600\n" for i in range(8))
NEXUS = (
    "Trajectories,,,,,,,,\n100,,,,,,,,\n,,S:A,,,S:B,,,\nFrame,Sub Frame,X,Y,Z,X,Y,Z\n,,mm,mm,mm,mm,mm,mm\n"
    + "".join(f"{i + 1},0,{i}.5,2,3,,,\n" if i == 3 else f"{i + 1},0,{i}.5,2,3,4,5,6\n" for i in range(8))
    + "\nDevices,,,,\n1000,,,,\n,,FP,,\nFrame,Sub Frame,Fx,Fy,Fz\n,,N,N,N\n"
    + "".join(f"{f},{s},1,2,3\n" for f in range(1, 4) for s in range(10))
)
MOCAP = ",M1,M1,M1\n,x,y,z\n" + "".join(f"{i},1.5,2,3\n" for i in range(8))
STRIDES = "s_id,foot,start,end,gsd_id\n0,left,10,30,1\n1,left,30,52,1\n"

# (format, file name, valid content, options)
SEEDS = {
    "delimited-fusion": ("delimited", "imu.csv", FUSION, {}),
    "delimited-shimmer": ("delimited", "shimmer.csv", SHIMMER, {}),
    "delimited-mapping": ("delimited", "wrist.csv", MAPPED_CSV, {"mapping": True}),
    "gaitmap-imu": ("gaitmap", "imu_sample.csv", GAITMAP, {}),
    "gaitmap-mocap": ("gaitmap", "mocap_sample.csv", MOCAP, {}),
    "gaitmap-strides": ("gaitmap", "stride_borders_sample.csv", STRIDES, {}),
    "xsens": ("xsens", "MT_00B41234.txt", XSENS, {}),
    "adc": ("adc", "adc.txt", ADC, {"rate_hz": 50.0}),
    "vicon-csv": ("vicon-csv", "vicon.csv", NEXUS, {}),
}


def _write(tmp: Path, key: str, content: bytes | str) -> tuple[Path, ConvertOptions]:
    fmt, name, _, opts = SEEDS[key]
    path = tmp / name
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    mapping = None
    if opts.get("mapping"):
        mapping = tmp / "wrist.mapping.json"
        mapping.write_text(json.dumps(MAPPING))
    return path, ConvertOptions(mapping=mapping, rate_hz=opts.get("rate_hz"))


def _convert(tmp: Path, key: str, content: bytes | str) -> Recording:
    path, options = _write(tmp, key, content)
    return get(SEEDS[key][0]).convert(path, options)  # the converter itself, not the registry's safety net


def _check_sane(rec: Recording) -> None:
    for stream in rec.streams():
        t = getattr(stream, "t_ns", None)
        if t is not None:
            assert np.all(np.diff(t) > 0), f"{stream} time stamps not strictly increasing"
    for imu in rec.imus:
        for arr in (imu.acc, imu.gyr, imu.mag):
            if arr is not None:  # NaN = a gap (an empty or NaN cell); never infinite
                assert not np.isinf(arr).any()


@pytest.mark.parametrize("key", sorted(SEEDS))
def test_valid_seeds_convert(tmp_path, key):
    rec = _convert(tmp_path, key, SEEDS[key][2])
    assert rec.streams()
    _check_sane(rec)


def _replace_line(text: str, lineno: int, new: str) -> str:
    lines = text.split("\n")
    lines[lineno - 1] = new
    return "\n".join(lines)


CASES = [
    # key, damage, expected message (regex)
    (
        "delimited-fusion",
        lambda s: _replace_line(s, 4, "0.02,0.1,-0.2"),
        r"imu\.csv: line 4: truncated line: 3 fields, expected 10",
    ),
    (
        "delimited-fusion",
        lambda s: _replace_line(s, 5, "0.03,0.1,abc,0.3,0.01,-0.02,0.99,15.3,0.4,-41.0"),
        r"line 5, column 'Gyroscope Y \(deg/s\)': 'abc' is not a number",
    ),
    (  # an empty IMU cell is a gap (tests/test_convert_validation.py); an empty time cell is not
        "delimited-fusion",
        lambda s: _replace_line(s, 5, ",0.1,0.2,0.3,0.01,-0.02,0.99,15.3,0.4,-41.0"),
        r"line 5, column 'Time \(s\)': empty cell",
    ),
    (
        "delimited-fusion",
        lambda s: _replace_line(s, 6, "0.01,0.1,-0.2,0.3,0.01,-0.02,0.99,15.3,0.4,-41.0"),
        r"line 6, column 'Time \(s\)': time stamp goes backwards",
    ),
    (
        "delimited-fusion",
        lambda s: _replace_line(s, 6, "0.03,0.1,-0.2,0.3,0.01,-0.02,0.99,15.3,0.4,-41.0"),
        r"line 6, column 'Time \(s\)': duplicated time stamp",
    ),
    (
        "delimited-fusion",
        lambda s: s.replace("Accelerometer Z (g)", "Accelerometer X (g)"),
        r"duplicated column 'Accelerometer X \(g\)'",
    ),
    (
        "delimited-fusion",
        lambda s: s.replace("Accelerometer Z (g)", "Pressure (kPa)"),
        r"missing column\(s\) for acc z",
    ),
    (
        "delimited-fusion",
        lambda s: s.replace("Gyroscope X (deg/s)", "Gyroscope X (furlong/s)"),
        r"column 'Gyroscope X \(furlong/s\)': unknown gyr unit 'furlong/s'",
    ),
    (
        "delimited-fusion",
        lambda s: s.replace("0.99,15.3,0.4,-41.0\n0.05", "0.99,15.3,0.4,-41.0,7\n0.05"),
        r"line 6: 11 fields, expected 10",
    ),
    ("delimited-fusion", lambda s: s.split("\n")[0] + "\n", r"no data rows"),
    ("delimited-fusion", lambda s: "", r"imu\.csv: empty file"),
    (  # no unit in the header and a time step that fits none (inferred units: tests/test_convert_validation.py)
        "delimited-fusion",
        lambda s: s.replace("Time (s)", "Time").replace("\n0.0", "\n0.000"),
        r"column 'Time': no time unit in the header and a step of 0.0001 fits no unit at 5-5000 Hz",
    ),
    (
        "delimited-fusion",
        lambda s: s.replace("0.99,15.3,0.4,-41.0\n0.05", "0.99,15.3,0.4,-41.0\n\n0.05"),
        r"line 7: empty line inside the data",
    ),
    (  # NaN is a gap; infinity is not a number an IMU records
        "delimited-fusion",
        lambda s: s.replace("0.99,15.3", "inf,15.3", 1),
        r"line 2, column 'Accelerometer Z \(g\)': infinite value",
    ),
    (
        "delimited-shimmer",
        lambda s: s.replace("deg/s;deg/s;deg/s", "deg/s;deg/s;bananas"),
        r"unknown gyr unit 'bananas'",
    ),
    (
        "delimited-mapping",
        lambda s: s.replace("timestamp", "time_ms"),
        r"time column 'timestamp' of the mapping file is not in the header",
    ),
    (
        "gaitmap-imu",
        lambda s: _replace_line(s, 5, "2,0.8,2.7,9.4,-0.1,0.03"),
        r"line 5: truncated line: 6 fields, expected 7",
    ),
    (
        "gaitmap-imu",
        lambda s: _replace_line(s, 5, "1,0.8,2.7,9.4,-0.1,0.03,-0.06"),
        r"line 5, column 'sensor/axis': duplicated time stamp",
    ),
    ("xsens", lambda s: s.replace("00002\t", "00001\t"), r"line 10, column 'PacketCounter': PacketCounter duplicated"),
    ("xsens", lambda s: s.replace("\tGyr_Z", "\tGyr_Q"), r"missing column\(s\) Gyr_Z"),
    ("xsens", lambda s: s.replace("9.8", "9,8", 1), r"line 5, column 'Acc_Z': '9,8' is not a number"),
    (
        "adc",
        lambda s: s.replace("X=513", "X=513 Q=1"),
        r"adc\.txt: line 4: expected 'X=<int> Y=<int> Z=<int>', got 'X=513 Q=1",
    ),
    ("adc", lambda s: s.replace("X=513", "X=5130"), r"line 4, column 'X': 5130 counts outside the 10-bit range"),
    ("vicon-csv", lambda s: s.replace("mm,mm,mm,mm", "mm,mm,mm,furlong", 1), r"unknown length unit 'furlong'"),
    ("vicon-csv", lambda s: s.replace("3,0,2.5", "2,0,2.5"), r"line 8, column 'Frame': duplicated time stamp"),
    ("vicon-csv", lambda s: s.replace("5,0,4.5,2,3", "5,0,4.5,x,3"), r"line 10, column 'Y': 'x' is not a number"),
    ("vicon-csv", lambda s: s.replace("S:A,,,S:B", "S:A,,,S:A"), r"duplicated marker 'S:A'"),
    ("vicon-csv", lambda s: s.replace("Trajectories", "Trajektorien"), r"not a Vicon Nexus CSV"),
    # a download cut off mid-row is dropped with a warning (tests/test_convert_validation.py); a short row in the
    # middle of the Devices section is damage
    (
        "vicon-csv",
        lambda s: s.replace("1000,,,,", "1234,,,,"),
        r"device rate 1234 Hz is not a multiple of the frame rate 100 Hz",
    ),
]


@pytest.mark.parametrize("key, damage, message", CASES)
def test_bad_input_gives_one_precise_line(tmp_path, key, damage, message):
    with pytest.raises(ConversionError, match=message) as info:
        _convert(tmp_path, key, damage(SEEDS[key][2]))
    text = str(info.value)
    assert "\n" not in text and text.startswith(str(tmp_path))


def test_apostrophes_are_not_quotes_but_long_quoted_values_are_cut():
    """Only a quoted value is cut to an excerpt: the apostrophes of two possessives more than 40 characters apart
    ("the device's ... the session's") stay as written; a long repr()-quoted cell is still cut, with its length."""
    prose = "recognised as NilsPodLib's _header.json), but it holds the session's settings, not its samples"
    assert ConversionError("x.json", prose).problem == prose
    cell = "9" * 500
    err = ConversionError("x.csv", f"value {cell!r} is not finite", line=4)
    assert str(err) == f"x.csv: line 4: value '{cell[:36]}...' (502 chars) is not finite"


def test_binary_garbage_and_unknown_formats(tmp_path):
    junk = tmp_path / "junk.csv"
    junk.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(UnknownFormatError, match=r"junk\.csv: unknown format"):
        convert_file(junk)
    # a text file no reader knows may be a table of anything (SOURCES.tsv): the mapping hint is a condition
    with pytest.raises(UnknownFormatError, match=r"; if it is IMU text whose header carries no units .* give a map"):
        convert_file(junk)
    for fmt in ("delimited", "xsens", "adc", "vicon-csv", "gaitmap", "c3d", "broad-hdf5"):
        with pytest.raises(ConversionError, match=r"junk\.csv: "):
            convert_file(junk, fmt)
    with pytest.raises(UnknownFormatError, match="unknown format 'nope'"):
        convert_file(junk, "nope")


def test_bad_mapping_files_are_named(tmp_path):
    csv = tmp_path / "wrist.csv"
    csv.write_text(MAPPED_CSV)
    for change, message in [
        (
            lambda d: d["columns"]["ax"].update(unit="furlong"),
            r"wrist\.mapping\.json: columns\.ax\.unit 'furlong' is not a known acc unit",
        ),
        (lambda d: d["columns"]["gx"].update(quantity="speed"), r"columns\.gx\.quantity 'speed' unknown"),
        (lambda d: d["columns"]["gx"].update(axis="w"), r"columns\.gx\.axis 'w' must be x, y or z"),
        (lambda d: d.update(format="other/2"), r"unknown mapping format 'other/2'"),
        (lambda d: d["time"].update(unit="fortnight"), r"time\.unit 'fortnight' unknown"),
    ]:
        doc = json.loads(json.dumps(MAPPING))
        change(doc)
        (tmp_path / "wrist.mapping.json").write_text(json.dumps(doc))
        with pytest.raises(ConversionError, match=message):
            convert_file(csv)
    (tmp_path / "wrist.mapping.json").write_text("{not json")
    with pytest.raises(ConversionError, match=r"wrist\.mapping\.json: line 1: not a valid mapping file"):
        convert_file(csv)


def test_corrupt_binary_formats(tmp_path, shared_data):
    c3d = tmp_path / "cut.c3d"
    c3d.write_bytes((shared_data / "c3d/ktk_sample_propulsion_upperlimb.c3d").read_bytes()[:5000])
    with pytest.raises(ConversionError, match=r"cut\.c3d: "):
        convert_file(c3d)
    h5 = tmp_path / "cut.hdf5"
    h5.write_bytes((shared_data / "broad/02_undisturbed_slow_rotation_B.hdf5").read_bytes()[:4000])
    with pytest.raises(ConversionError, match=r"cut\.hdf5: "):
        convert_file(h5, "broad-hdf5")
    # detected too: a cut-off .hdf5 used to be reported as 'unknown format'
    with pytest.raises(ConversionError, match=r"cut\.hdf5: corrupt HDF5: .*truncated file"):
        convert_file(h5)


# ------------------------------------------------------------------------------------- property based
_TEXTISH = st.text(alphabet='0123456789.,;\t-+eE\n\r xyzXYZ=naNIf_"/()abc#:', max_size=12)
_MUTATION = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("delete"), st.floats(0, 1), st.integers(1, 40)),
    st.tuples(st.just("insert"), st.floats(0, 1), _TEXTISH),
    st.tuples(st.just("bytes"), st.floats(0, 1), st.binary(min_size=1, max_size=8)),
    st.tuples(st.just("line"), st.floats(0, 1), _TEXTISH),
    st.tuples(st.just("dupline"), st.floats(0, 1)),
    st.tuples(st.just("swap"), st.floats(0, 1), st.floats(0, 1)),
)


def _mutate(data: bytes, mutations: list[tuple]) -> bytes:
    for m in mutations:
        kind, where = m[0], m[1]
        pos = int(where * len(data))
        if kind == "truncate":
            data = data[:pos]
        elif kind == "delete":
            data = data[:pos] + data[pos + m[2] :]
        elif kind == "insert":
            data = data[:pos] + m[2].encode() + data[pos:]
        elif kind == "bytes":
            data = data[:pos] + m[2] + data[pos:]
        else:
            lines = data.split(b"\n")
            i = min(int(where * len(lines)), len(lines) - 1)
            if kind == "line":
                lines[i] = m[2].encode()
            elif kind == "dupline":
                lines.insert(i, lines[i])
            else:
                j = min(int(m[2] * len(lines)), len(lines) - 1)
                lines[i], lines[j] = lines[j], lines[i]
            data = b"\n".join(lines)
    return data


@pytest.mark.parametrize("key", sorted(SEEDS))
@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mutations=st.lists(_MUTATION, min_size=1, max_size=3))
# found by this test on 2026-12-07: a header of only the delimiter leaves no column in use, and pyarrow reads
# an empty include_columns as every column (converters/_table.py)
@example(mutations=[("line", 0.0, ";"), ("line", 0.125, "")])
def test_damaged_files_raise_only_conversion_error(tmp_path, key, mutations):
    data = _mutate(SEEDS[key][2].encode(), mutations)
    try:
        rec = _convert(tmp_path, key, data)
    except ConversionError as e:
        assert "\n" not in str(e)
        return
    _check_sane(rec)


@pytest.mark.parametrize("key", sorted(SEEDS))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.one_of(st.binary(max_size=200), _TEXTISH.map(str.encode)))
def test_arbitrary_bytes_raise_only_conversion_error(tmp_path, key, data):
    try:
        rec = _convert(tmp_path, key, data)
    except ConversionError:
        return
    _check_sane(rec)
