"""``simulate()``: one trial of a protocol as an in-memory Recording plus its ground truth."""

from __future__ import annotations

import dataclasses
import difflib
import zlib
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from imulog.model import ImuStream, Intervals, MarkerStream, Recording
from imulog.process import quaternion as quat
from imulog.simulate import clocks, imu_model, protocols, vicon_model
from imulog.simulate.motion import MotionPlan
from imulog.simulate.truth import GroundTruth

IMU_NAME = "wrist"
VICON_NAME = "vicon"


@dataclass(frozen=True)
class EnvironmentParams:
    gravity_mps2: float = imu_model.EARTH_G  # world gravity (brief: g = 9.81)
    field_uT: float = 46.0  # Earth field magnitude in Turin (IGRF ~46 uT)
    inclination_deg: float = 62.0  # Turin magnetic inclination (IGRF ~61-62 deg)
    north_heading_deg: float | None = None  # magnetic north's heading in the lab's x-y plane; None: random
    noise_free: bool = False  # ideal IMU (no noise/bias/scale/quantisation/drops) and Vicon (no noise/gaps)
    date: str = "2026-01-01"


@dataclass
class SimulatedTrial:
    """A simulated trial: ``recording`` as the converters read the written files, ``truth``."""

    protocol: str
    subject: int
    trial: int
    seed: int
    recording: Recording
    truth: GroundTruth
    params: dict[str, Any]
    adc: dict[str, Any] | None = None  # raw ADC counts for the 'adl' protocol (written as X= Y= Z= text)
    raw: dict[str, Any] | None = None  # exact decimal file values the writers use (see imu_model)

    @property
    def stem(self) -> str:
        """File stem the in-memory metadata's ``source`` names refer to."""
        return f"{self.protocol}_s{self.subject:02d}_t{self.trial:02d}"


def _param_classes(protocol_module) -> dict[str, type]:
    return {
        "protocol": protocol_module.Params,
        "imu": imu_model.ImuParams,
        "clock": clocks.ClockParams,
        "vicon": vicon_model.ViconParams,
        "environment": EnvironmentParams,
    }


def parameter_names(protocol: str) -> dict[str, list[str]]:
    """Names accepted as ``**overrides`` by :func:`simulate`, grouped by model part."""
    return {k: [f.name for f in fields(c)] for k, c in _param_classes(protocols.get(protocol)).items()}


def _split_overrides(protocol_module, overrides: dict[str, Any]) -> dict[str, Any]:
    classes = _param_classes(protocol_module)
    remaining = dict(overrides)
    built = {}
    for key, cls in classes.items():
        names = {f.name for f in fields(cls)}
        mine = {k: remaining.pop(k) for k in list(remaining) if k in names}
        built[key] = cls(**mine)
    if remaining:
        valid = sorted(n for c in classes.values() for n in (f.name for f in fields(c)))
        hints = []
        for name in sorted(remaining):
            close = difflib.get_close_matches(name, valid, n=1)
            hints.append(f"{name} (did you mean {close[0]}?)" if close else name)
        raise TypeError(
            f"unknown simulation parameter(s) {', '.join(hints)}; list them with parameter_names({protocol_module.__name__.rsplit('.', 1)[-1]!r})"
        )
    if built["environment"].noise_free:
        imu_overrides = {k: v for k, v in overrides.items() if k in {f.name for f in fields(imu_model.ImuParams)}}
        built["imu"] = dataclasses.replace(imu_model.ImuParams.ideal(), **imu_overrides)
    return built


def _rng(seed: int, *keys: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), *[int(k) for k in keys]]))


def _intervals(topic: str, items: list) -> Intervals:
    return Intervals(
        topic=topic,
        start_ns=np.array([round(i.start_s * 1e9) for i in items], dtype=np.int64),
        end_ns=np.array([round(i.end_s * 1e9) for i in items], dtype=np.int64),
        labels=[i.label for i in items],
        task_index=np.array([i.task_index for i in items], dtype=np.int64),
    )


def _simulate_adc(
    model: dict, plan, env: EnvironmentParams, start_s: float, stop_s: float, rng: np.random.Generator, noise_free: bool
) -> dict[str, Any]:
    """Raw 10-bit ADC counts of a co-located 3-axis accelerometer board (sensor frame = IMU frame),
    sampled at ``rate_hz`` on the reference clock from ``start_s`` (no time stamps in its text)."""
    rate = float(model["rate_hz"])
    n = int(np.floor((stop_s - start_s) * rate)) + 1
    t_ref_ns = np.round((start_s + np.arange(n) / rate) * 1e9).astype(np.int64)
    kin = plan.evaluate(t_ref_ns / 1e9)
    f = quat.rotate_inverse(kin.orientation, kin.acceleration + np.array([0.0, 0.0, env.gravity_mps2]))
    zero = np.asarray(model["zero_counts"], dtype=float)
    cpg = np.asarray(model["counts_per_g"], dtype=float)
    if noise_free:
        zero, cpg = np.full(3, 512.0), np.full(3, 256.0)
    counts = zero + cpg * f / imu_model.G0
    if not noise_free:
        counts = counts + rng.normal(0.0, model["noise_counts"], counts.shape)
    counts = np.clip(np.round(counts), 0, 1023).astype(np.int64)
    return {
        "counts": counts,
        "rate_hz": rate,
        "start_ref_ns": int(t_ref_ns[0]),
        "zero_counts": zero.tolist(),
        "counts_per_g": cpg.tolist(),
        "noise_counts": 0.0 if noise_free else float(model["noise_counts"]),
    }


def _build(module, p: dict, protocol: str, subject: int, trial: int, seed: int):
    """The protocol's motion plan and subject of one trial (its own random streams)."""
    pid = zlib.crc32(protocol.encode())
    return module.build(p["protocol"], _rng(seed, pid, subject, 1), _rng(seed, pid, subject, trial, 2), trial=trial)


def motion_plan(protocol: str, *, subject: int = 0, trial: int = 0, seed: int = 0, **overrides: Any) -> MotionPlan:
    """The motion plan :func:`simulate` evaluates for the same arguments (segments, time laws, true phases), for an
    analysis that needs the model behind the truth (benchmarks/boundary_limit.py)."""
    module = protocols.get(protocol)
    return _build(module, _split_overrides(module, overrides), protocol, subject, trial, seed).plan


def simulate(protocol: str, *, subject: int = 0, trial: int = 0, seed: int = 0, **overrides: Any) -> SimulatedTrial:
    """Simulate one trial of ``protocol`` (``r2g``, ``slide``, ``nhpt``, ``adl``).

    ``overrides`` set any parameter of the protocol, IMU, clock, Vicon or environment model
    (see :func:`parameter_names` and docs/simulate.md), e.g. ``repetitions=5``,
    ``noise_free=True``, ``residual_velocity_mps=0.01``, ``drift_ppm=40``. The same
    (protocol, subject, trial, seed, overrides) always give the same trial; the motion does not
    change with the sensor options (separate random streams).
    """
    module = protocols.get(protocol)
    p = _split_overrides(module, overrides)
    env: EnvironmentParams = p["environment"]
    pid = zlib.crc32(protocol.encode())
    device_rng = _rng(seed, 3)  # one physical device and lab set-up per seed
    clock_rng = _rng(seed, pid, subject, trial, 4)
    noise_rng = _rng(seed, pid, subject, trial, 5)
    vicon_rng = _rng(seed, pid, subject, trial, 6)
    drop_rng = _rng(seed, pid, subject, trial, 7)

    built = _build(module, p, protocol, subject, trial, seed)
    plan = built.plan

    # lab set-up and device (shared by every trial of a seed)
    device = imu_model.draw_device(p["imu"], device_rng)
    q_imu_to_cluster = vicon_model.draw_imu_to_cluster(p["vicon"], device_rng)
    north = env.north_heading_deg if env.north_heading_deg is not None else float(device_rng.uniform(0.0, 360.0))
    inc = np.radians(env.inclination_deg)
    psi = np.radians(north)
    field_world = env.field_uT * np.array([np.cos(inc) * np.cos(psi), np.cos(inc) * np.sin(psi), -np.sin(inc)])
    # the 9D orientation's global frame is ENU (y = magnetic north, imulog.process.orientation.GLOBAL_FRAME_9D)
    q_global_to_world = quat.from_rotation_vector(np.array([0.0, 0.0, psi - np.pi / 2]))

    # clocks and sample times
    vrate = p["clock"].vicon_rate_hz
    n_frames = int(np.floor(built.end_s * vrate)) + 1
    t_vicon = clocks.vicon_times_ns(n_frames, vrate)
    clock, imu_start_s, stop_early_s = clocks.draw_clock(p["clock"], clock_rng)
    t_dev_all = clocks.imu_device_times_ns(p["clock"], clock, imu_start_s, t_vicon[-1] / 1e9 - stop_early_s)
    keep = imu_model.dropped_mask(len(t_dev_all), p["imu"], drop_rng)
    t_dev = t_dev_all[keep]
    t_ref = clock.device_to_reference(t_dev)  # float ns, exact

    # IMU
    kin = plan.evaluate(t_ref / 1e9)
    f_world = kin.acceleration + np.array([0.0, 0.0, env.gravity_mps2])
    f_sensor = quat.rotate_inverse(kin.orientation, f_world)
    m_sensor = quat.rotate_inverse(kin.orientation, np.broadcast_to(field_world, f_world.shape))
    channels = imu_model.measure(f_sensor, kin.omega, m_sensor, (t_dev - t_dev[0]) / 1e9, p["imu"], device, noise_rng)
    stem = f"{protocol}_s{subject:02d}_t{trial:02d}"
    device_meta = {
        "model": "LSM9DS1 (BlueBuddy, simulated)",
        "serial": f"SIM-{seed:04d}",
        "rate_hz": p["clock"].imu_rate_hz,
        "acc_range_g": p["imu"].acc_range_g,
        "gyr_range_dps": p["imu"].gyr_range_dps,
        "mag_range_gauss": p["imu"].mag_range_gauss,
    }
    # metadata as the delimited converter reports it for the written file
    imu_meta = {
        "format": "delimited",
        **device_meta,
        "units": {q: ch.unit for q, ch in channels.items()},
        "time": {"column": "timestamp", "unit": "ms"},
        "source": f"{stem}_imu.csv",
    }
    imu = ImuStream(
        name=IMU_NAME,
        t_ns=t_dev,
        acc=channels["acc"].si,
        gyr=channels["gyr"].si,
        mag=channels["mag"].si,
        meta=dict(imu_meta),
    )

    # Vicon
    kin_v = plan.evaluate(t_vicon / 1e9)
    true_markers, marker_names = vicon_model.all_markers(
        t_vicon / 1e9,
        kin_v.position,
        kin_v.orientation,
        q_imu_to_cluster,
        p["vicon"],
        _rng(seed, pid, subject, trial, 8),
    )
    measured = vicon_model.add_noise_and_gaps(true_markers, vrate, p["vicon"], vicon_rng, env.noise_free)
    subject_prefix = f"{p['vicon'].subject_name}:" if p["vicon"].subject_name else ""
    labels = [subject_prefix + lab for lab in marker_names]
    vicon_source = f"{stem}_vicon.csv"
    markers = MarkerStream(
        name=VICON_NAME,
        t_ns=t_vicon,
        labels=labels,
        pos=measured,
        meta={"rate_hz": vrate, "units": "mm", "source": vicon_source},
    )

    alignment = {
        "reference": markers.topic,
        "imu": imu.topic,
        "offset_ns": int(clock.offset_ns),
        "drift_ppm": float(clock.drift_ppm),
        "t0_ns": int(clock.t0_ns),
        "rotation_imu_to_cluster": [float(v) for v in q_imu_to_cluster],
        "rotation_global_to_world": [float(v) for v in q_global_to_world],
        "method": "simulated",
        "score": 1.0,
    }
    trial_meta = {
        "subject": f"S{subject:02d}",
        "trial": int(trial),
        "task": built.task,
        "date": env.date,
        "simulated": True,
        "seed": int(seed),
        **built.trial_meta,
    }
    recording = Recording(
        imus=[imu],
        markers=[markers],
        metadata={
            "imulog.trial": trial_meta,
            "imulog.anthropometrics": dict(built.anthropometrics),
            f"imulog.device.{IMU_NAME}": imu_meta,
            f"imulog.device.{VICON_NAME}": {
                "format": "vicon-csv",
                "model": "Vicon Nexus",
                "source": vicon_source,
                "sections": ["Trajectories"],
                "rate_hz": vrate,
                "marker_units": "mm",
                "markers": len(labels),
            },
        },
    )

    adc = None
    if "adc_model" in built.extra:
        adc = _simulate_adc(
            built.extra.pop("adc_model"), plan, env, imu_start_s, t_ref[-1] / 1e9, noise_rng, env.noise_free
        )

    phase_items = [i for i in plan.intervals if i.task_index >= 0]
    event_items = [i for i in plan.intervals if i.task_index < 0]
    params_dict = {k: dataclasses.asdict(v) for k, v in p.items()}
    truth = GroundTruth(
        protocol=protocol,
        t_ns=t_vicon,
        position=kin_v.position,
        velocity=kin_v.velocity,
        acceleration=kin_v.acceleration,
        orientation=kin_v.orientation,
        angular_velocity=kin_v.omega,
        static_mask=~kin_v.moving,
        phases=_intervals("/truth/phases", phase_items),
        events=_intervals("/truth/events", event_items),
        alignment=alignment,
        imu_t_ref_ns=np.round(t_ref).astype(np.int64),
        imu_t_dev_ns=t_dev,
        imu_position=kin.position,
        imu_velocity=kin.velocity,
        imu_orientation=kin.orientation,
        imu_angular_velocity=kin.omega,
        imu_static_mask=~kin.moving,
        imu_dropped_t_dev_ns=t_dev_all[~keep],
        anthropometrics=dict(built.anthropometrics),
        info={
            "subject": subject,
            "trial": trial,
            "seed": seed,
            "params": params_dict,
            "device_errors": device.as_dict(),
            "magnetic_field_world_uT": field_world.tolist(),
            "gravity_mps2": env.gravity_mps2,
            "imu_rate_hz": p["clock"].imu_rate_hz,
            "vicon_rate_hz": vrate,
            "marker_offsets_m": [list(o) for o in p["vicon"].marker_offsets_m],
            **built.extra,
            **({"adc": {k: v for k, v in adc.items() if k != "counts"}} if adc is not None else {}),
        },
    )
    raw = {
        "imu_t_dev_ns": t_dev,
        "imu_channels": channels,
        "device": device_meta,
        "vicon_subject": p["vicon"].subject_name,
        "vicon_decimals": p["vicon"].decimals,
    }
    return SimulatedTrial(protocol, subject, trial, seed, recording, truth, params_dict, adc=adc, raw=raw)
