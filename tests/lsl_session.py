"""An LSL configuration of this test process's own: no other LSL program on the machine can hide its streams.

With ``ResolveScope = machine`` liblsl finds streams by sending its query to 127.0.0.1 on the multicast port
(16571 by default) and to each port of the service range (16572-16603). Every outlet on the machine binds the
multicast port (with SO_REUSEADDR) and Linux hands a datagram sent to 127.0.0.1 to one of those sockets only; the
service ports are shared by every outlet and resolver on the machine, and an outlet made while they are all taken
gets a random port, which the unicast sweep never reaches. Another LSL process (a second CI run, a user's
LabRecorder) can thus hide a test's streams from ``imulog record`` (benchmarks/lsl_crowd.py: with 34 outlets of
another session on the default ports, one of our two streams was never seen); a ``SessionID`` of one's own does
not help, since the other process's responders take the query and ignore it. Here each test
process gets a ``SessionID`` and a block of ports (multicast port + service range) of its own, reserved against
the other test processes of the machine by a lock file held for the process's life, and checked free.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import random
import socket
import tempfile
import uuid
from pathlib import Path

#: port blocks below Linux's ephemeral range (32768-60999), so that no random port of another program lands in one
FIRST_PORT, LAST_PORT = 20000, 32000
#: ports per block: the multicast port, then the service range (liblsl's default range is 32 ports)
PORT_RANGE = 32
BLOCK = 40

_held: dict[str, object] = {}


def _free(port: int) -> bool:
    """Nothing bound to UDP or TCP ``port`` on this machine (right now)."""
    for kind in (socket.SOCK_DGRAM, socket.SOCK_STREAM):
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("0.0.0.0", port))
            except OSError:
                return False
    return True


def reserve_ports() -> int:
    """The first port of a block of :data:`BLOCK` ports that this process holds (a lock file per block, in the
    temporary folder, locked until the process ends) and that nothing has bound; the same block on every call."""
    if "port" in _held:
        return int(_held["port"])  # type: ignore[arg-type]
    folder = Path(tempfile.gettempdir()) / "imulog-test-lsl-ports"
    folder.mkdir(exist_ok=True)
    blocks = list(range(FIRST_PORT, LAST_PORT - BLOCK, BLOCK))
    start = random.SystemRandom().randrange(len(blocks))  # concurrent runs start apart
    for port in blocks[start:] + blocks[:start]:
        lock = open(folder / f"{port}.lock", "w")  # noqa: SIM115  (held open: the lock lives as long as the process)
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        if all(_free(p) for p in range(port, port + PORT_RANGE + 1)):
            _held.update(port=port, lock=lock)
            return port
        with contextlib.suppress(OSError):
            lock.close()
    raise RuntimeError(f"no free block of {BLOCK} ports in {FIRST_PORT}-{LAST_PORT} for an LSL session")


def config_text(session_id: str, port: int | None) -> str:
    """liblsl's configuration: this machine only, ``session_id``, the multicast port ``port`` and the service
    ports after it (None: liblsl's default ports, shared by the machine), IPv6 off, only fatal log lines."""
    ports = f"MulticastPort = {port}\nBasePort = {port + 1}\nPortRange = {PORT_RANGE}\n" if port else ""
    return (
        f"[ports]\n{ports}IPv6 = disable\n[multicast]\nResolveScope = machine\n"
        f"[lab]\nSessionID = {session_id}\n[log]\nlevel = -3\n"
    )


def session_config(folder: Path) -> Path:
    """This process's LSL configuration file in ``folder`` (written once per process: liblsl reads its
    configuration once, so outlets made in the test process must share the session of the commands it starts)."""
    if "cfg" not in _held:
        session = f"imulog-test-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        cfg = folder / "lsl_api.cfg"
        cfg.write_text(config_text(session, reserve_ports()))
        _held["cfg"] = cfg
    return Path(_held["cfg"])  # type: ignore[arg-type]
