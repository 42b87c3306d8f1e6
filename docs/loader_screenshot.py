"""Screenshot of a trial opened by Rerun's own MCAP loader (no imulog code in the viewer path).

    imulog demo -o demo-output
    python docs/loader_screenshot.py demo-output/trial.mcap --start 100 --seconds 40 -o docs/rerun_mcap_loader.png
    python docs/loader_screenshot.py demo-output/trial.rrd -o docs/viewer_r2g.png   # imulog's own .rrd

A ``.rrd`` (e.g. written by ``imulog view --save``) is served as it is, with its blueprint.

Converts the trial with the ``rerun`` executable shipped in rerun-sdk (``rerun mcap convert``: Rerun's own
MCAP loader; the viewer twins under ``/derived/viewer/`` become Scalars plots, Points3D, Transform3D and
TextLog, see docs/schemas.md), serves the result with ``rerun --web-viewer``, opens the page in headless
chromium (``apt-get install -y chromium``)
and saves what it draws, driven over the Chrome DevTools protocol (tornado's websocket client) because the
web viewer loads its wasm and the data asynchronously.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rerun_exe() -> str:
    exe = Path(sys.executable).parent / "rerun"
    return str(exe) if exe.is_file() else (shutil.which("rerun") or "rerun")


async def _shoot(ws_url: str, png: Path, wait_s: float) -> None:
    from tornado.websocket import websocket_connect

    ws = await websocket_connect(ws_url, max_message_size=256 * 2**20)
    next_id = 0

    async def call(method: str, **params):
        nonlocal next_id
        next_id += 1
        ws.write_message(json.dumps({"id": next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(await ws.read_message())
            if msg.get("id") == next_id:
                return msg.get("result", {})

    await asyncio.sleep(wait_s)  # wasm start, MCAP import, first frames
    shot = await call("Page.captureScreenshot", format="png")
    png.write_bytes(base64.b64decode(shot["data"]))
    ws.close()


def _log_time_range(trial: Path, start_s: float, seconds: float | None) -> list[str]:
    """``--start-time/--end-time`` for ``rerun mcap convert``: a window of the file's log times (mcap summary)."""
    if seconds is None:
        return []
    from mcap.reader import make_reader

    with open(trial, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    t0 = stats.message_start_time + int(start_s * 1e9)
    return ["--start-time", f"{t0}ns", "--end-time", f"{t0 + int(seconds * 1e9)}ns"]


def screenshot(
    trial: Path,
    png: Path,
    *,
    topics: str = "^/derived/viewer/",
    start_s: float = 0.0,
    seconds: float | None = None,
    wait_s: float = 30.0,
    size: str = "1600,1000",
) -> Path:
    """Open ``trial`` (an MCAP archive, or a ``.rrd`` served as it is) with ``rerun --web-viewer`` in headless
    chromium and save a PNG of the page.

    ``topics``: a regex of the MCAP topics Rerun imports (``rerun mcap convert -y``; "" for all); the
    default is the viewer twins, what a Rerun user opens (docs/schemas.md). ``start_s``/``seconds``: import
    only that window of log time (the whole file when ``seconds`` is None).
    """
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        raise SystemExit("chromium not found (apt-get install -y chromium)")
    web, grpc, devtools = _free_port(), _free_port(), _free_port()
    work = Path(tempfile.mkdtemp())
    rrd = work / "trial.rrd"  # Rerun's own MCAP import, done once ahead (the page then loads in seconds)
    if trial.suffix == ".rrd":
        rrd = trial
    else:
        select = (["-y", topics] if topics else []) + _log_time_range(trial, start_s, seconds)
        subprocess.run(
            [_rerun_exe(), "mcap", "convert", str(trial), *select, "-o", str(rrd)], check=True, capture_output=True
        )
    viewer = subprocess.Popen(
        [_rerun_exe(), "--web-viewer", "--web-viewer-port", str(web), "--port", str(grpc)]
        + ["--bind", "127.0.0.1", "--hide-welcome-screen", str(rrd)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # .venv/bin/rerun is a Python wrapper: stop its viewer child with it (killpg)
    )
    browser = None
    try:
        url = f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc}%2Fproxy"
        for _ in range(100):
            try:
                urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=1).close()
                break
            except OSError:
                time.sleep(0.2)
        profile = tempfile.mkdtemp(dir=work)
        browser = subprocess.Popen(
            [chromium, *FLAGS, f"--window-size={size}", f"--user-data-dir={profile}"]
            + [f"--remote-debugging-port={devtools}", url],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        targets: list = []
        for _ in range(100):
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{devtools}/json/list", timeout=1) as r:
                    targets = [t for t in json.load(r) if t["type"] == "page"]
                if targets:
                    break
            except OSError:
                pass
            time.sleep(0.2)
        if not targets:
            raise SystemExit("chromium did not open a DevTools endpoint")
        png.parent.mkdir(parents=True, exist_ok=True)
        asyncio.run(_shoot(targets[0]["webSocketDebuggerUrl"], png, wait_s))
    finally:
        if browser is not None:
            browser.terminate()
            browser.wait(10)
        os.killpg(viewer.pid, signal.SIGTERM)  # the wrapper and the viewer it started
        viewer.wait(10)
        shutil.rmtree(work, ignore_errors=True)
    return png


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "trial", type=Path, help="a processed trial, e.g. demo-output/trial.mcap (imulog demo), or an .rrd"
    )
    parser.add_argument("-o", "--output", type=Path, default=Path("docs/rerun_mcap_loader.png"))
    parser.add_argument("--topics", default="^/derived/viewer/", help='regex of topics to import ("" for all)')
    parser.add_argument("--start", type=float, default=0.0, help="window start, s after the file's first message")
    parser.add_argument("--seconds", type=float, default=None, help="window length in s (default: the whole file)")
    parser.add_argument("--wait", type=float, default=30.0, help="seconds to let the viewer load before the shot")
    args = parser.parse_args(argv)
    print(
        screenshot(
            args.trial, args.output, topics=args.topics, start_s=args.start, seconds=args.seconds, wait_s=args.wait
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
