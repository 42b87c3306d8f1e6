"""`imulog view --web` rendered by headless Debian chromium (needs the `chromium` package; see .ci/run).

The page is driven over the Chrome DevTools protocol (tornado's websocket client) because the Rerun web
viewer loads its wasm and data asynchronously: a plain ``--screenshot`` fires before anything is drawn.
The screenshot is kept in ``test-artifacts/view_web.png``.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from procs import start

from imulog.view.layout import PHASE_COLORS
from imulog.view.server import free_port

pytestmark = pytest.mark.browser

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--window-size=1600,1000",
]


def _chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        message = "Debian chromium is not installed (apt-get install -y chromium; .ci/run does it)"
        if os.environ.get("CI"):
            pytest.fail(message)  # CI installs it: a missing browser there is a broken setup, not a skip
        pytest.skip(message)
    return exe


async def _devtools_screenshot(ws_url: str, png: Path, timeout_s: float, ready) -> tuple[dict, np.ndarray]:
    from PIL import Image
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
                return msg["result"]

    deadline = time.monotonic() + timeout_s
    page: dict = {}
    pixels = np.zeros((1, 1, 3), np.uint8)
    while time.monotonic() < deadline:
        await asyncio.sleep(3.0)
        probe = "JSON.stringify({title: document.title, canvases: document.querySelectorAll('canvas').length})"
        page = json.loads((await call("Runtime.evaluate", expression=probe, returnByValue=True))["result"]["value"])
        shot = await call("Page.captureScreenshot", format="png")
        png.write_bytes(base64.b64decode(shot["data"]))
        with Image.open(png) as img:
            pixels = np.asarray(img.convert("RGB"))
        if ready(page, pixels):
            break
    ws.close()
    return page, pixels


def _fraction_near(pixels: np.ndarray, rgba: int, tol: int = 10) -> float:
    """Fraction of pixels showing colour ``rgba``, drawn opaque or semi-transparent on a light or dark theme."""
    rgb = np.array([(rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255], dtype=float)
    sample = pixels[::2, ::2].astype(int)
    best = 0.0
    for background in (np.array([255.0, 255.0, 255.0]), np.array([13.0, 17.0, 19.0])):
        for alpha in (1.0, 0.9, 0.8, 0.7, 0.6):
            target = np.rint(alpha * rgb + (1 - alpha) * background)
            best = max(best, float(np.mean(np.all(np.abs(sample - target) <= tol, axis=2))))
    return best


def _phase_colours_drawn(pixels: np.ndarray) -> int:
    return sum(
        _fraction_near(pixels, PHASE_COLORS[p]) > 1e-4 for p in ("reach", "lift", "return_bottle", "return_hand")
    )


def test_web_viewer_renders_trial(repo_root, tmp_path):
    chromium = _chromium()
    web_port, grpc_port, devtools_port = free_port(), free_port(), free_port()
    server = start(
        [sys.executable, "-m", "imulog.cli", "view", "--sample", "30", "--web", "--port", str(web_port)]
        + ["--grpc-port", str(grpc_port), "--serve-seconds", "120"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    browser = None
    try:
        line = server.stdout.readline()
        assert line.startswith("Rerun web viewer: http://127.0.0.1:"), line + server.stderr.read()
        url = line.split(": ", 1)[1].strip()
        with urllib.request.urlopen(url, timeout=10) as response:  # the bundled viewer, served locally
            assert b"re_viewer" in response.read()

        profile = tempfile.mkdtemp(dir=tmp_path)
        browser = start(
            [chromium, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--remote-debugging-port={devtools_port}", url],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        targets: list = []
        for _ in range(100):
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{devtools_port}/json/list", timeout=1) as r:
                    targets = [t for t in json.load(r) if t["type"] == "page"]
                if targets:
                    break
            except OSError:
                pass
            time.sleep(0.2)
        assert targets, "chromium did not open a DevTools endpoint"

        artifacts = repo_root / "test-artifacts"
        artifacts.mkdir(exist_ok=True)
        png = artifacts / "view_web.png"
        page, pixels = asyncio.run(
            _devtools_screenshot(
                targets[0]["webSocketDebuggerUrl"],
                png,
                timeout_s=60.0,
                ready=lambda page, px: page.get("canvases", 0) > 0 and _phase_colours_drawn(px) == 4,
            )
        )
        assert png.is_file()
        assert page["title"] == "Rerun Viewer" and page["canvases"] >= 1, page
        # not blank: many colours and real contrast
        assert pixels.std() > 20
        assert len(np.unique(pixels.reshape(-1, 3)[::7], axis=0)) > 200
        # the trial itself was drawn: the four phase colours of the state timeline are on screen
        assert _phase_colours_drawn(pixels) == 4, f"phase colours missing in {png}"
    finally:
        if browser is not None:
            browser.terminate()
            browser.wait(10)
        server.terminate()
        server.wait(10)
