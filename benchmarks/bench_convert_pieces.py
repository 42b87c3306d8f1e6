"""Host-clock text converted piece by piece against the same file in one piece: peak memory, CPU and wall time.

Writes Shimmer Consensys exports (``sep=`` line, names row, units row; host Unix stamps in ms that repeat and jitter,
so a uniform clock is fitted: docs/converters.md) of ``--hours`` and 4x as many hours at 51.2 Hz, then converts each
with ``imulog convert`` in a fresh subprocess (a) piece by piece (``IMULOG_STREAM_MIN_BYTES=0``, 16 MB pieces: two
passes over the file, the first summing the line) and (b) in one piece (the whole-file path). Peak RSS (``VmHWM``;
``ru_maxrss`` would carry this process's own peak, the generated arrays, across the child's exec), user+sys CPU
(``resource.getrusage``) and wall time are the subprocess's own; the machine is shared, so CPU time is the figure to
compare.

    .venv/bin/python benchmarks/bench_convert_pieces.py [--hours 2]

The same for the four formats issue 24 brought into pieces (XDF, NilsPodLib CSV, Xsens MT text, BIDS-motion):
generated files of ``--hours`` and 4x as many hours converted piece by piece, with the growth of the peak:

    .venv/bin/python benchmarks/bench_convert_pieces.py --formats xdf,nilspod-csv,xsens,bids --hours 1 [--whole]

C3D (``--formats c3d``): a 4-marker cluster at 100 Hz and one analog channel at 1 kHz, float32, the frame count in
``TRIAL:ACTUAL_END_FIELD`` (``benchmarks/long_c3d.py``: 1 h is 360 000 frames, 37 MB).

The lab and device text exports (Motive, Qualisys, TRC, ``.sto``, Delsys, Empatica E4 ACC, ActiLife epochs; files
written by ``lab_text_files.py``) likewise:

    .venv/bin/python benchmarks/bench_convert_pieces.py --formats motive,qualisys,trc,sto,delsys,e4,actilife-epoch --hours 1

An Empatica E4 session folder (ACC 32 Hz, BVP 64 Hz, EDA and TEMP 4 Hz, HR 1 Hz, IBI beats; ``imulog convert
FOLDER``, time windows across the files) in pieces and as the whole-folder read:

    .venv/bin/python benchmarks/bench_convert_pieces.py --formats e4-folder --hours 1 --whole

And for the HDF5 readers and MVNX (files written with h5py / as XML): the guarded h5py reader processes' CPU and
peak RSS are printed beside the command's own:

    .venv/bin/python benchmarks/bench_convert_pieces.py --formats broad,apdm-h5,opensignals-h5,mvnx --hours 1
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from lab_text_files import FORMATS as LAB_FORMATS  # noqa: E402 - the lab and device text exports' writers
from long_c3d import write_long_c3d  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def host_clock_csv(path: Path, n: int, *, rate_hz: float = 51.2, seed: int = 0, late: dict[int, float] | None = None):
    """A Shimmer Consensys export of ``n`` samples whose host Unix stamps (ms) repeat and jitter: packets of 4
    samples stamped on arrival. ``late``: row -> extra delay (s) of that row's stamp. Returns the stamps (ms)."""
    rng = np.random.default_rng(seed)
    t_true_ms = 1.6e12 + np.arange(n) * (1000.0 / rate_hz)
    arrival = t_true_ms[(np.arange(n) // 4) * 4 + 3] + rng.uniform(0, 15, n)  # a packet is stamped when it arrives
    for row, delay_s in (late or {}).items():
        arrival[row] += delay_s * 1000.0
    stamps = np.floor(arrival)  # 1 ms resolution: repeats within a packet
    acc = rng.normal(0, 1, (n, 3)) + [0, 0, 9.81]
    gyr = rng.normal(0, 5, (n, 3))
    pre = "Shimmer_40AC_"
    names = [pre + "Timestamp_Unix_CAL"]
    names += [pre + f"Accel_LN_{a}_CAL" for a in "XYZ"] + [pre + f"Gyro_{a}_CAL" for a in "XYZ"]
    units = ["ms"] + ["m/(s^2)"] * 3 + ["deg/s"] * 3
    with open(path, "w") as f:
        f.write('"sep=;"\n' + ";".join(names) + "\n" + ";".join(units) + "\n")
        np.savetxt(f, np.column_stack([stamps, acc, gyr]), delimiter=";", fmt=["%.0f"] + ["%.5f"] * 6)
    return stamps


_CHILD = """
import json, resource, sys, time
t0 = time.perf_counter()
from imulog.cli import cli
try:
    cli(["convert", sys.argv[1], "-o", sys.argv[2], "--attach-original", "never"], standalone_mode=False)
finally:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)  # guarded reader processes (h5py), if any
    # VmHWM: this program's own peak (ru_maxrss keeps the forking parent's peak across exec on Linux)
    hwm = [int(x.split()[1]) for x in open("/proc/self/status") if x.startswith("VmHWM:")]
    print(json.dumps({"wall_s": time.perf_counter() - t0, "cpu_s": ru.ru_utime + ru.ru_stime,
                      "peak_mb": (hwm[0] if hwm else ru.ru_maxrss) / 1024,
                      "children_cpu_s": kids.ru_utime + kids.ru_stime,
                      "children_peak_mb": kids.ru_maxrss / 1024}), file=sys.stderr)
"""


def convert(src: Path, out: Path, pieces: bool) -> dict:
    env = dict(os.environ, IMULOG_STREAM_MIN_BYTES="0" if pieces else str(1 << 60))
    res = subprocess.run([sys.executable, "-c", _CHILD, str(src), str(out)], capture_output=True, text=True, env=env)
    if res.returncode != 0:
        raise SystemExit(res.stderr[-2000:])
    assert ("piece by piece" in res.stdout) == pieces, res.stdout
    out.unlink()
    return json.loads(res.stderr.strip().splitlines()[-1])


def xdf_file(path: Path, n: int, *, rate_hz: float = 100.0, seed: int = 0) -> None:
    """An XDF recording of ``n`` samples: a 9-channel float32 IMU stream (AccX.. in g, GyroX.. in deg/s, MagX.. in
    uT) in 5-s Samples chunks, a marker stream every 10 s, clock offsets every 5 s, footers, as LabRecorder writes."""
    import struct

    rng = np.random.default_rng(seed)

    def chunk(tag: int, content: bytes) -> bytes:
        return bytes([8]) + struct.pack("<QH", len(content) + 2, tag) + content

    labels = [f"{q}{a}" for q in ("Acc", "Gyro", "Mag") for a in "XYZ"]
    units = ["g"] * 3 + ["deg/s"] * 3 + ["uT"] * 3
    ch = "".join(
        f"<channel><label>{lab}</label><unit>{u}</unit></channel>" for lab, u in zip(labels, units, strict=True)
    )
    imu_xml = (
        f"<?xml version='1.0'?><info><name>Wrist</name><type>IMU</type><channel_count>9</channel_count>"
        f"<nominal_srate>{rate_hz}</nominal_srate><channel_format>float32</channel_format>"
        f"<desc><channels>{ch}</channels></desc></info>"
    )
    mk_xml = (
        "<?xml version='1.0'?><info><name>Markers</name><type>Markers</type><channel_count>1</channel_count>"
        "<nominal_srate>0</nominal_srate><channel_format>string</channel_format></info>"
    )
    rec = np.dtype([("f", "u1"), ("t", "<f8"), ("v", "<f4", (9,))])
    t0 = 1000.0
    per = int(5 * rate_hz)
    with open(path, "wb") as f:
        f.write(b"XDF:" + chunk(1, b"<?xml version='1.0'?><info><version>1.0</version></info>"))
        f.write(chunk(2, struct.pack("<I", 1) + imu_xml.encode()))
        f.write(chunk(2, struct.pack("<I", 2) + mk_xml.encode()))
        for k, lo in enumerate(range(0, n, per)):
            m = min(per, n - lo)
            block = np.zeros(m, rec)
            block["f"] = 8
            block["t"] = t0 + (lo + np.arange(m)) / rate_hz + rng.uniform(0, 2e-4, m)
            block["v"] = rng.normal(0, 1, (m, 9))
            f.write(chunk(3, struct.pack("<IBI", 1, 4, m) + block.tobytes()))
            tk = t0 + lo / rate_hz
            f.write(chunk(4, struct.pack("<Idd", 1, tk, -0.25 + 1e-6 * k)))
            if k % 2 == 0:
                label = f"event {k}".encode()
                f.write(
                    chunk(
                        3,
                        struct.pack("<IBB", 2, 1, 1)
                        + bytes([8])
                        + struct.pack("<d", tk)
                        + bytes([1, len(label)])
                        + label,
                    )
                )
                f.write(chunk(4, struct.pack("<Idd", 2, tk, -0.25)))
        for sid, count in ((1, n), (2, (n + 2 * per - 1) // (2 * per))):
            footer = f"<?xml version='1.0'?><info><sample_count>{count}</sample_count></info>"
            f.write(chunk(6, struct.pack("<I", sid) + footer.encode()))


def nilspod_csv(path: Path, n: int, *, seed: int = 0) -> None:
    """NilsPodLib's ``data_as_csv`` export of ``n`` samples at 102.4 Hz (``<stem>_data.csv`` + ``_header.json``)."""
    rng = np.random.default_rng(seed)
    rate = 102.4
    t = np.arange(n) / rate
    cols = ["t", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z", "baro", "temp"]
    data = np.column_stack(
        [
            t,
            rng.normal(0, 5, (n, 3)),
            rng.normal(0, 1, (n, 3)) + [0, 0, 9.81],
            rng.normal(1000, 1, n),
            rng.normal(25, 0.1, n),
        ]
    )
    np.savetxt(path, data, delimiter=",", header=",".join(cols), comments="", fmt=["%.8f"] + ["%.5f"] * 8)
    stem = path.name[: -len("_data.csv")]
    header = {
        "sampling_rate_hz": rate,
        "acc_range_g": 16.0,
        "gyro_range_dps": 2000.0,
        "utc_start": 1610209704,
        "n_samples": n,
        "mac_address": "aa:bb:cc:dd:6f:13",
        "version_firmware": "v0.18.0",
    }
    (path.parent / f"{stem}_header.json").write_text(json.dumps(header))


def xsens_txt(path: Path, n: int, *, seed: int = 0) -> None:
    """An MT Manager 2022 text export of ``n`` samples at 100 Hz: PacketCounter (wrapping), SampleTimeFine, Acc,
    Gyr, Mag, Quat, tab-separated under the ``//`` header."""
    rng = np.random.default_rng(seed)
    head = [
        "// General information:",
        "//  MT Manager version: 2022.2.0",
        "// Device information:",
        "//  DeviceId: 00B42D4B",
        "//  ProductCode: MTW2-3A7G6",
        "// Coordinate system: ENU",
    ]
    cols = ["PacketCounter", "SampleTimeFine"] + [f"{q}_{a}" for q in ("Acc", "Gyr", "Mag") for a in "XYZ"]
    cols += [f"Quat_q{i}" for i in range(4)]
    q = rng.normal(0, 1, (n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    data = np.column_stack(
        [
            np.arange(n) % 65536,
            1_000_000 + np.arange(n) * 100,
            rng.normal(0, 1, (n, 3)),
            rng.normal(0, 0.5, (n, 3)),
            rng.normal(0, 0.3, (n, 3)),
            q,
        ]
    )
    with open(path, "w") as f:
        f.write("\n".join(head) + "\n" + "\t".join(cols) + "\n")
        np.savetxt(f, data, delimiter="\t", fmt=["%05d", "%d"] + ["%.6f"] * 13)


def bids_motion(folder: Path, n: int, *, seed: int = 0) -> Path:
    """A BIDS-motion recording of ``n`` samples at 100 Hz: one wrist IMU (acc m/s^2, gyr rad/s), ``n/a`` gaps."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    base = folder / "sub-01_task-home_tracksys-imu"
    rows = ["name\tcomponent\ttype\ttracked_point\tunits"]
    rows += [f"acc_{a}\t{a}\tACCEL\twrist\tm/s^2" for a in "xyz"] + [f"gyr_{a}\t{a}\tGYRO\twrist\trad/s" for a in "xyz"]
    Path(f"{base}_channels.tsv").write_text("\n".join(rows) + "\n")
    Path(f"{base}_motion.json").write_text(json.dumps({"SamplingFrequency": 100, "TrackingSystemName": "imu"}))
    data = np.column_stack([rng.normal(0, 1, (n, 3)) + [0, 0, 9.81], rng.normal(0, 0.5, (n, 3))])
    motion = Path(f"{base}_motion.tsv")
    np.savetxt(motion, data, delimiter="\t", fmt="%.6f")
    return motion


def _blocks(n: int, size: int = 1 << 18):
    """Consecutive (start, stop) row blocks covering ``n`` (the HDF5 writers write in blocks: bounded memory)."""
    return [(a, min(n, a + size)) for a in range(0, n, size)]


def broad_h5(path: Path, n: int, *, seed: int = 0) -> None:
    """A BROAD trial of ``n`` samples at 285.714 Hz (h5py): IMU acc/gyr/mag, optical position (NaN rows where tracking
    is lost) and quaternion, a movement mask in runs."""
    import h5py

    rng = np.random.default_rng(seed)
    with h5py.File(path, "w") as f:
        f.attrs["sampling_rate"] = 285.714
        ds = {k: f.create_dataset(k, (n, w), "f8") for k, w in (("imu_acc", 3), ("imu_gyr", 3), ("imu_mag", 3))}
        ds["opt_pos"] = f.create_dataset("opt_pos", (n, 3), "f8")
        ds["opt_quat"] = f.create_dataset("opt_quat", (n, 4), "f8")
        move = f.create_dataset("movement", (n,), "u1")
        for a, b in _blocks(n):
            m = b - a
            ds["imu_acc"][a:b] = rng.normal(0, 1, (m, 3)) + [0, 0, 9.81]
            ds["imu_gyr"][a:b] = rng.normal(0, 0.3, (m, 3))
            ds["imu_mag"][a:b] = rng.normal(20, 5, (m, 3))
            pos = rng.normal(0, 0.1, (m, 3))
            pos[rng.random(m) < 0.01] = np.nan
            ds["opt_pos"][a:b] = pos
            q = rng.normal(0, 1, (m, 4))
            ds["opt_quat"][a:b] = q / np.linalg.norm(q, axis=1, keepdims=True)
            move[a:b] = (np.arange(a, b) // 2857) % 2  # 10-s runs of movement and rest


def apdm_h5(path: Path, n: int, *, seed: int = 0) -> None:
    """An APDM Opal format-5 file of ``n`` samples at 128 Hz (h5py): one sensor with Time, accelerometer, gyroscope,
    magnetometer, temperature, barometer and the orientation estimate."""
    import h5py

    rng = np.random.default_rng(seed)
    with h5py.File(path, "w") as f:
        g = f.create_group("Sensors/XI-010203")
        cfg = g.create_group("Configuration")
        cfg.attrs["Label 0"] = b"Right Wrist"
        cfg.attrs["Sample Rate"] = np.uint16(128)
        cfg.attrs["Timezone Offset"] = 1.0
        time = g.create_dataset("Time", (n,), "u8")
        ds = {k: g.create_dataset(k, (n, 3), "f8") for k in ("Accelerometer", "Gyroscope", "Magnetometer")}
        temp, baro = g.create_dataset("Temperature", (n,), "f8"), g.create_dataset("Barometer", (n,), "f8")
        ori = f.create_group("Processed/XI-010203").create_dataset("Orientation", (n, 4), "f8")
        for a, b in _blocks(n):
            m = b - a
            time[a:b] = 1_600_000_000_000_000 + np.arange(a, b, dtype=np.uint64) * 7812
            ds["Accelerometer"][a:b] = rng.normal(0, 1, (m, 3)) + [0, 0, 9.81]
            ds["Gyroscope"][a:b] = rng.normal(0, 0.3, (m, 3))
            ds["Magnetometer"][a:b] = rng.normal(20, 5, (m, 3))
            temp[a:b] = 31 + rng.normal(0, 0.1, m)
            baro[a:b] = 101.3 + rng.normal(0, 0.01, m)
            q = rng.normal(0, 1, (m, 4))
            ori[a:b] = q / np.linalg.norm(q, axis=1, keepdims=True)


def opensignals_h5(path: Path, n: int, *, seed: int = 0) -> None:
    """An OpenSignals ``.h5`` of ``n`` samples at 1000 Hz (h5py): one BITalino, nSeq and EMG, EDA, ACC (uint16)."""
    import h5py

    rng = np.random.default_rng(seed)
    with h5py.File(path, "w") as f:
        g = f.create_group("00:07:80:3B:46:61")
        for k, v in (("sampling rate", 1000), ("resolution", [4, 10, 10, 10]), ("device", "bitalino_rev")):
            g.attrs[k] = v
        g.attrs["date"], g.attrs["time"] = "2017-1-20", "14:40:49.587"
        raw = g.create_group("raw")
        seq = raw.create_dataset("nSeq", (n, 1), "u2")
        chans = [raw.create_dataset(f"channel_{j}", (n, 1), "u2") for j in (1, 2, 3)]
        for ch, sensor in zip(chans, ("EMG", "EDA", "ACC"), strict=True):
            ch.attrs["sensor"] = sensor
        for a, b in _blocks(n):
            seq[a:b] = (np.arange(a, b) % 16).reshape(-1, 1)
            for ch in chans:
                ch[a:b] = rng.integers(0, 1024, (b - a, 1))


def mvnx_xml(path: Path, n: int, *, seed: int = 0) -> None:
    """An Xsens MVN ``.mvnx`` of ``n`` frames at 60 Hz in the MVNX 4 layout of ``tests/test_convert_mvnx.py`` (5
    segments, 2 sensors, 4 joints); frame bodies are drawn from a pool of 1000 (their values repeat; times do not)."""
    rng = np.random.default_rng(seed)
    segs, sensors, joints = ["Pelvis", "T8", "RightUpperArm", "RightForeArm", "RightHand"], ["Pelvis", "Hand"], 4

    def txt(a: np.ndarray) -> str:
        return " ".join(f"{v:.6f}" for v in a.ravel())

    pool = []
    for _ in range(1000):
        q = rng.normal(0, 1, (len(segs), 4))
        sq = rng.normal(0, 1, (len(sensors), 4))
        pool.append(
            f"<orientation>{txt(q / np.linalg.norm(q, axis=1, keepdims=True))}</orientation>"
            f"<position>{txt(rng.normal(0, 1, (len(segs), 3)))}</position>"
            f"<sensorFreeAcceleration>{txt(rng.normal(0, 2, (len(sensors), 3)))}</sensorFreeAcceleration>"
            f"<sensorMagneticField>{txt(rng.normal(0, 1, (len(sensors), 3)))}</sensorMagneticField>"
            f"<sensorOrientation>{txt(sq / np.linalg.norm(sq, axis=1, keepdims=True))}</sensorOrientation>"
            f"<jointAngle>{txt(rng.normal(0, 40, (joints, 3)))}</jointAngle></frame>\n"
        )
    with open(path, "w") as f:
        f.write('<?xml version="1.0" encoding="UTF-8"?>\n<mvnx version="4" xmlns="http://www.xsens.com/mvn/mvnx">\n')
        f.write('<mvn version="2021.0.1" build="1"/>\n<subject label="s" frameRate="60" ')
        f.write('recDate="Tue Mar 03 14:08:49.271 2020" recDateMSecsSinceEpoch="1583240929271">\n<segments>')
        f.write("".join(f'<segment label="{s}" id="{i}"/>' for i, s in enumerate(segs, 1)))
        f.write("</segments>\n<sensors>" + "".join(f'<sensor label="{s}"/>' for s in sensors) + "</sensors>\n")
        f.write("<joints>" + "".join(f'<joint label="j{k}"/>' for k in range(joints)) + "</joints>\n<frames>\n")
        t_ms = np.round(np.arange(n) * 1000 / 60).astype(np.int64)
        for a, b in _blocks(n, 10_000):
            f.write("".join(f'<frame time="{t_ms[i]}" index="{i}" type="normal">{pool[i % 1000]}' for i in range(a, b)))
        f.write("</frames>\n</subject>\n</mvnx>\n")


def e4_folder(folder: Path, n: int) -> Path:
    """An Empatica E4 session of ``n`` ACC samples (``n / 115200`` hours) in ``folder``: ACC 32 Hz (1/64 g counts),
    BVP 64 Hz, EDA and TEMP 4 Hz, HR 1 Hz (starting 10 s later, as E4 connect writes it), IBI beats about every
    0.8 s in runs with gaps; returns the folder (``imulog convert FOLDER`` converts the session)."""
    from lab_text_files import _write_file

    start = 1680686620
    seconds = n / 32.0
    files = {  # name: (rate Hz, columns, printf format, values(lo, hi, rng))
        "ACC": (32.0, 3, ["%d"] * 3, lambda lo, hi, rng: rng.integers(-64, 64, (hi - lo, 3))),
        "BVP": (64.0, 1, ["%.2f"], lambda lo, hi, rng: rng.normal(0, 40, (hi - lo, 1))),
        "EDA": (4.0, 1, ["%.6f"], lambda lo, hi, rng: np.abs(rng.normal(0.5, 0.2, (hi - lo, 1)))),
        "TEMP": (4.0, 1, ["%.2f"], lambda lo, hi, rng: rng.normal(32, 0.5, (hi - lo, 1))),
        "HR": (1.0, 1, ["%.2f"], lambda lo, hi, rng: rng.normal(75, 5, (hi - lo, 1))),
    }
    for name, (rate, cols, fmt, make) in files.items():
        t0 = start + (10 if name == "HR" else 0)
        header = [", ".join([f"{t0:.6f}"] * cols), ", ".join([f"{rate:.6f}"] * cols)]
        _write_file(folder / f"{name}.csv", header, int((seconds - (10 if name == "HR" else 0)) * rate), make, fmt, ",")
    rng = np.random.default_rng(1)
    ibi = rng.uniform(0.6, 1.0, int(seconds / 0.8))
    beats = np.cumsum(ibi) + 5.0
    keep = (beats < seconds) & (rng.random(len(beats)) < 0.7)  # beats the device dropped
    with open(folder / "IBI.csv", "w") as f:
        f.write(f"{start:.6f}, IBI\n")
        np.savetxt(f, np.column_stack([beats[keep], ibi[keep]]), delimiter=",", fmt="%.6f")
    return folder


#: format -> (samples per hour, how to write a file of n samples into a folder and return the path to convert)
FORMATS = {
    "xdf": (360_000, lambda d, n: (xdf_file(d / "rec.xdf", n), d / "rec.xdf")[1]),
    "nilspod-csv": (
        368_640,
        lambda d, n: (nilspod_csv(d / "NilsPodX-6F13_data.csv", n), d / "NilsPodX-6F13_data.csv")[1],
    ),
    "xsens": (
        360_000,
        lambda d, n: (xsens_txt(d / "MT_0120_000-000_00B42D4B.txt", n), d / "MT_0120_000-000_00B42D4B.txt")[1],
    ),
    "bids": (360_000, lambda d, n: bids_motion(d, n)),
    "c3d": (360_000, lambda d, n: (write_long_c3d(d / "long.c3d", n), d / "long.c3d")[1]),
    "broad": (1_028_570, lambda d, n: (broad_h5(d / "trial.hdf5", n), d / "trial.hdf5")[1]),
    "apdm-h5": (460_800, lambda d, n: (apdm_h5(d / "opal.h5", n), d / "opal.h5")[1]),
    "opensignals-h5": (3_600_000, lambda d, n: (opensignals_h5(d / "opensignals.h5", n), d / "opensignals.h5")[1]),
    "mvnx": (216_000, lambda d, n: (mvnx_xml(d / "capture.mvnx", n), d / "capture.mvnx")[1]),
}


FORMATS.update(LAB_FORMATS)
FORMATS["e4-folder"] = (115_200, e4_folder)  # an E4 session folder (ACC samples per hour), converted as a folder


def main_formats(hours: float, formats: list[str], whole: bool) -> None:
    """Each format at ``hours`` and 4x ``hours``, piece by piece (and in one piece with ``whole``)."""
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in formats:
            per_hour, write = FORMATS[fmt]
            peaks = {}
            for h in (hours, 4 * hours):
                folder = Path(tmp) / f"{fmt}_{h:g}h"
                folder.mkdir()
                src = write(folder, int(h * per_hour))
                size_mb = sum(p.stat().st_size for p in folder.iterdir()) / 1e6
                for pieces in (True, False) if whole else (True,):
                    r = convert(src, Path(tmp) / "out.mcap", pieces)
                    kind = "pieces" if pieces else "one piece"
                    peaks[(h, kind)] = r["peak_mb"]
                    kids = (  # the guarded h5py readers: their CPU and the largest one's peak RSS
                        f"  + reader children: cpu {r['children_cpu_s']:5.1f} s, peak {r['children_peak_mb']:5.0f} MB"
                        if r.get("children_cpu_s")
                        else ""
                    )
                    print(
                        f"{fmt:12s} {h:5.1f} h  {int(h * per_hour) / 1e6:5.2f} M samples  {size_mb:6.0f} MB  {kind:9s}  "
                        f"peak {r['peak_mb']:6.0f} MB  cpu {r['cpu_s']:6.1f} s  wall {r['wall_s']:6.1f} s{kids}",
                        flush=True,
                    )
                for p in folder.iterdir():
                    p.unlink()
            growth = peaks[(4 * hours, "pieces")] / peaks[(hours, "pieces")]
            print(f"{fmt:12s} peak memory in pieces, 4x the hours: {growth:.2f}x (target <= 1.15)", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=2.0, help="the short file; the long one is 4x (default 2)")
    ap.add_argument("--formats", default="shimmer", help="comma-separated: shimmer, " + ", ".join(FORMATS))
    ap.add_argument("--whole", action="store_true", help="also convert each file of --formats in one piece")
    args = ap.parse_args()
    others = [f for f in args.formats.split(",") if f != "shimmer"]
    if others:
        main_formats(args.hours, others, args.whole)
    if "shimmer" not in args.formats.split(","):
        return
    with tempfile.TemporaryDirectory() as tmp:
        rows = []
        for hours in (args.hours, 4 * args.hours):
            src = Path(tmp) / f"shimmer_{hours:g}h.csv"
            n = int(hours * 3600 * 51.2)
            host_clock_csv(src, n)
            size_mb = src.stat().st_size / 1e6
            for pieces in (True, False):
                r = convert(src, Path(tmp) / "out.mcap", pieces)
                rows.append((hours, n, size_mb, "pieces" if pieces else "one piece", r))
                print(
                    f"{hours:5.1f} h  {n / 1e6:5.2f} M samples  {size_mb:6.0f} MB text  {rows[-1][3]:9s}  "
                    f"peak {r['peak_mb']:6.0f} MB  cpu {r['cpu_s']:6.1f} s  wall {r['wall_s']:6.1f} s",
                    flush=True,
                )
        by = {(h, k): r for h, _, _, k, r in rows}
        short, long = args.hours, 4 * args.hours
        print(
            f"peak memory, 4x the hours: pieces {by[(long, 'pieces')]['peak_mb'] / by[(short, 'pieces')]['peak_mb']:.2f}x, "
            f"one piece {by[(long, 'one piece')]['peak_mb'] / by[(short, 'one piece')]['peak_mb']:.2f}x"
        )
        print(
            f"pieces / one piece at {long:g} h: peak {by[(long, 'pieces')]['peak_mb'] / by[(long, 'one piece')]['peak_mb']:.2f}x, "
            f"cpu {by[(long, 'pieces')]['cpu_s'] / by[(long, 'one piece')]['cpu_s']:.2f}x"
        )


if __name__ == "__main__":
    main()
