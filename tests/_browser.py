"""A minimal Chrome DevTools Protocol client for the viewer's tests: headless Chromium with software WebGL
(SwiftShader), one page, console and network events recorded, screenshots as arrays, synthetic mouse and keys.

Uses the ``websocket-client`` package (the ``test`` extra). The browser is ``$POLYJAX_CHROMIUM``, else the first
of ``chromium``, ``chromium-browser``, ``google-chrome`` on the ``PATH``.
"""

from __future__ import annotations

import base64
import io
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

FLAGS = ("--headless=new", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--enable-webgl",
         "--ignore-gpu-blocklist", "--no-first-run", "--no-default-browser-check", "--no-sandbox",
         "--disable-background-networking", "--disable-component-update", "--disable-extensions",
         "--disable-sync", "--mute-audio", "--disable-dev-shm-usage", "--remote-debugging-port=0")


def find_chromium() -> str | None:
    exe = os.environ.get("POLYJAX_CHROMIUM")
    if exe:
        return exe
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


class Browser:
    """One headless Chromium and one page attached through the browser's DevTools websocket."""

    def __init__(self, exe: str, extra_flags=(), timeout: float = 30.0):
        import websocket

        self.profile = tempfile.mkdtemp(prefix="polyjax-chromium-")
        self.proc = subprocess.Popen([exe, *FLAGS, *extra_flags, f"--user-data-dir={self.profile}", "about:blank"],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = Path(self.profile) / "DevToolsActivePort"
        t0 = time.monotonic()
        while not (port_file.exists() and len(port_file.read_text().split("\n")) >= 2):
            if self.proc.poll() is not None or time.monotonic() - t0 > timeout:
                self.close()
                raise RuntimeError(f"{exe} did not start its DevTools endpoint")
            time.sleep(0.05)
        port, path = port_file.read_text().split("\n")[:2]
        self.ws = websocket.create_connection(f"ws://127.0.0.1:{port}{path}", timeout=timeout, suppress_origin=True)
        self._id = 0
        self.events: list[dict] = []
        self.page_id = None
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.page_id = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        for domain in ("Page", "Runtime", "Log", "Network"):
            self.send(f"{domain}.enable")

    def send(self, method: str, params: dict | None = None) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if self.page_id is not None:
            msg["sessionId"] = self.page_id
        self.ws.send(json.dumps(msg))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            if "method" in reply:
                self.events.append(reply)

    def evaluate(self, expression: str):
        r = self.send("Runtime.evaluate", {"expression": expression, "returnByValue": True, "awaitPromise": True})
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expression}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def open(self, url: str, width: int = 1400, height: int = 1000, ready: str = "window.polyjaxView && "
             "(window.polyjaxView.ready || window.polyjaxView.error !== null)", timeout: float = 60.0):
        """Navigate to ``url`` at a ``width x height`` viewport (device scale 1) and wait until ``ready``."""
        self.events.clear()
        self.send("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1,
                                                         "mobile": False})
        self.send("Page.navigate", {"url": url})
        self.wait_for(ready, timeout)

    def wait_for(self, expression: str, timeout: float = 30.0):
        t0 = time.monotonic()
        while not self.evaluate(f"!!({expression})"):
            if time.monotonic() - t0 > timeout:
                raise TimeoutError(f"page: {expression} not true after {timeout} s")
            time.sleep(0.05)

    def errors(self) -> list[str]:
        """Console errors and warnings, uncaught exceptions and log errors recorded since the last :meth:`open`."""
        out = []
        for e in self.events:
            m, p = e["method"], e.get("params", {})
            if m == "Runtime.consoleAPICalled" and p.get("type") in ("error", "warning", "assert"):
                out.append("console: " + " ".join(str(a.get("value", a.get("description"))) for a in p["args"]))
            elif m == "Runtime.exceptionThrown":
                out.append("exception: " + json.dumps(p["exceptionDetails"])[:500])
            elif m == "Log.entryAdded" and p["entry"].get("level") in ("error", "warning"):
                out.append("log: " + p["entry"].get("text", ""))
        return out

    def requests(self) -> list[str]:
        return [e["params"]["request"]["url"] for e in self.events if e["method"] == "Network.requestWillBeSent"]

    def box(self, selector: str) -> dict:
        return self.evaluate(f"(() => {{ const r = document.querySelector({json.dumps(selector)})"
                             ".getBoundingClientRect(); "
                             "return {x: r.x, y: r.y, width: r.width, height: r.height}; })()")

    def screenshot(self, selector: str | None = None) -> np.ndarray:
        """A PNG screenshot of the viewport or of one element, as ``(H, W, 3)`` uint8."""
        import matplotlib.image

        params = {"format": "png"}
        if selector is not None:
            params["clip"] = dict(self.box(selector), scale=1)
        data = base64.b64decode(self.send("Page.captureScreenshot", params)["data"])
        image = matplotlib.image.imread(io.BytesIO(data), format="png")  # 8-bit PNG -> floats k / 255
        return np.round(image[..., :3] * 255).astype(np.uint8)

    def mouse(self, kind: str, x: float, y: float, buttons: int = 1) -> None:
        self.send("Input.dispatchMouseEvent", {"type": kind, "x": x, "y": y, "button": "left", "buttons": buttons,
                                               "clickCount": 1})

    def drag(self, x0: float, y0: float, x1: float, y1: float, steps: int = 4) -> None:
        self.mouse("mousePressed", x0, y0)
        for s in range(1, steps + 1):
            self.mouse("mouseMoved", x0 + (x1 - x0) * s / steps, y0 + (y1 - y0) * s / steps)
        self.mouse("mouseReleased", x1, y1, 0)

    def key(self, key: str, code: int) -> None:
        for kind in ("rawKeyDown", "keyUp"):
            self.send("Input.dispatchKeyEvent", {"type": kind, "key": key, "code": key, "windowsVirtualKeyCode": code})

    def close(self) -> None:
        try:
            if getattr(self, "ws", None) is not None:
                self.ws.close()
        finally:
            if self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
            shutil.rmtree(self.profile, ignore_errors=True)
