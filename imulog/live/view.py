"""``imulog record --view``: the streams in Rerun while they are recorded, in the layout of ``imulog view``.

Every piece the recorder writes is sent to one Rerun recording with :func:`imulog.view.streams.log_streams` (the
columnar logging ``imulog view`` uses, so the entities and the blueprint are the same), plus each IMU's orientation
from VQF's online filter (``/derived/orientation/<imu>``, updated sample by sample with the filter's state kept
between pieces: the orientation ``imulog process orientation`` computes offline, by the same algorithm but
without its backward pass) and VQF's online rest detection as the static / moving state
(``/derived/orientation_static/<imu>``): movements as they happen. The view is not written to the archive: the trial is the same with or without it.
``web`` serves the viewer on localhost (:func:`imulog.view.server.start_web_server`); otherwise a native viewer
is spawned.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from imulog.model import ImuStream, Recording, SignalStream


class OnlineOrientation:
    """VQF, one filter per IMU, fed piece by piece (its state carries over): sensor-to-global quaternions."""

    def __init__(self) -> None:
        self._filters: dict[str, Any] = {}

    def update(self, imu: ImuStream, rate_hz: float) -> list[SignalStream]:
        """This piece's orientation and VQF's rest detection (1 = at rest: between movements), as derived streams."""
        if imu.gyr is None or imu.acc is None or not len(imu.t_ns):
            return []
        from vqf import VQF

        f = self._filters.get(imu.name)
        if f is None:
            if len(imu.t_ns) > 1 and rate_hz <= 0:
                rate_hz = 1e9 / float(np.median(np.diff(imu.t_ns)))
            f = self._filters[imu.name] = VQF(1.0 / (rate_hz if rate_hz > 0 else 100.0))
        gyr, acc = np.ascontiguousarray(imu.gyr), np.ascontiguousarray(imu.acc)
        out = f.updateBatch(gyr, acc)
        rest = np.asarray(out["restDetected"], dtype=np.float64)[:, None]
        t = imu.t_ns
        return [
            SignalStream(f"/derived/orientation/{imu.name}", t, ["qw", "qx", "qy", "qz"], ["1"] * 4, out["quat6D"]),
            SignalStream(f"/derived/orientation_static/{imu.name}", t, ["static"], ["1"], rest, frame_id=imu.name),
        ]


class LiveView:
    """A Rerun recording fed with every recorded piece; ``url`` is the web viewer's address (``web``)."""

    def __init__(self, *, web: bool, web_port: int = 9090, grpc_port: int = 9876, spawn_port: int = 9876) -> None:
        import rerun as rr

        from imulog.view.server import grpc_uri, start_web_server
        from imulog.view.session import new_recording

        self.rec = new_recording("imulog record (live)")
        self.server = None
        if web:
            self.server = start_web_server(web_port=web_port, grpc_port=grpc_port)
            self.rec.set_sinks(rr.GrpcSink(self.server.grpc_uri))
        else:
            rr.spawn(port=spawn_port, connect=False, memory_limit="50%")
            self.rec.set_sinks(rr.GrpcSink(grpc_uri(spawn_port)))
        self.orientation = OnlineOrientation()
        self.rates: dict[str, float] = {}
        self.metadata: dict[str, dict[str, Any]] = {}
        from imulog.view.streams import LoggedTrial

        self.logged = LoggedTrial(label="live", prefix="")  # every entity sent so far, for the blueprint
        self.rows = 0  # temporal rows sent (all entities)
        self.latencies_s: list[float] = []  # per piece after the first: its oldest sample's age when sent, s
        self._pieces = 0
        self.busy_s: list[float] = []  # time spent sending each piece, s

    def start(self) -> None:
        """Send pieces on a thread of their own, so that the view never delays recording or flushing."""
        import queue
        import threading

        self._queue: queue.Queue = queue.Queue()
        self._error: BaseException | None = None

        def work() -> None:
            while (item := self._queue.get()) is not None:
                if self._error is None:
                    try:
                        self.show(*item)
                    except Exception as exc:  # noqa: BLE001 - reported when the recording stops; it goes on
                        self._error = exc

        self._thread = threading.Thread(target=work, name="imulog-live-view", daemon=True)
        self._thread.start()

    def submit(self, piece: Recording, metadata: dict[str, dict[str, Any]]) -> None:
        """Queue a piece for the view (a snapshot of the metadata: the recorder goes on changing it)."""
        self._queue.put((piece, {k: dict(v) for k, v in metadata.items()}))

    @property
    def url(self) -> str | None:
        return self.server.url if self.server is not None else None

    def show(self, piece: Recording, metadata: dict[str, dict[str, Any]]) -> None:
        """Send one piece (its channels and the online orientation); the blueprint when new entities appear."""
        import time

        from imulog.view.blueprint import build_blueprint
        from imulog.view.streams import log_streams

        began = time.perf_counter()
        streams = [s for s in piece.streams() if not s.topic.endswith("_lsl_clock")]
        for imu in piece.imus:
            rate = float((metadata.get(f"imulog.device.{imu.name}") or {}).get("nominal_srate_hz") or 0.0)
            streams.extend(self.orientation.update(imu, rate))
        if not streams:
            return
        logged = log_streams(streams, metadata, recording=self.rec, label="live")
        self.rows += sum(e.rows for e in logged.entities)
        known = set(self.logged.paths())
        new = [e for e in logged.entities if e.path not in known]
        if new:
            self.logged.entities.extend(new)
            self.rec.send_blueprint(build_blueprint(self.logged), make_active=True, make_default=True)
        self.rec.flush()
        self.busy_s.append(time.perf_counter() - began)
        self._pieces += 1
        oldest = min((int(s.t_ns[0]) for s in streams if len(getattr(s, "t_ns", ()))), default=None)
        if oldest is not None and self._pieces > 1:  # the first piece waited for every stream (START_WAIT_S)
            from imulog.live.lsl import pylsl

            self.latencies_s.append(pylsl().local_clock() - oldest / 1e9)

    def summary(self) -> str:
        """One line: rows sent, and how old the oldest sample of a piece was when it was sent (sample-to-viewer)."""
        if not self.latencies_s:
            return f"live view: {self.rows} rows sent"
        lat = np.asarray(self.latencies_s)
        return (
            f"live view: {self.rows} rows sent; sample-to-viewer latency median {np.median(lat) * 1e3:.0f} ms, "
            f"max {lat.max() * 1e3:.0f} ms (sending a piece took at most {max(self.busy_s) * 1e3:.0f} ms)"
        )

    def close(self) -> None:
        """Send what is queued, then stop; raises the view's error, if it had one."""
        if getattr(self, "_thread", None) is not None:
            self._queue.put(None)
            self._thread.join()
        self.rec.flush()
        self.rec.disconnect()  # nothing is sent after the server stops
        if self.server is not None:
            self.server.stop()
        if getattr(self, "_error", None) is not None:
            raise RuntimeError(f"the live view failed: {type(self._error).__name__}: {self._error}")
