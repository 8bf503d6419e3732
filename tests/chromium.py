"""Headless Chromium for the web-viewer test, driven over the DevTools protocol on a
pipe (``--remote-debugging-pipe``: commands in on fd 3, replies out on fd 4, each a
JSON text ended by a NUL byte), so no WebDriver or websocket package is needed."""

from __future__ import annotations

import base64
import json
import os
import select
import shutil
import socket
import subprocess
from pathlib import Path
from typing import Any

REPLY_TIMEOUT = 60.0  # s: a stuck browser fails the test instead of hanging it
CANDIDATES = ("/usr/lib/chromium/chromium", "chromium", "chromium-browser", "google-chrome")


def web_viewer_process(words: list[str]) -> subprocess.Popen[str]:
    """A quadsitl command serving the web viewer (``--rerun-web``, ``--web``) on free
    loopback ports, its output captured (the first line says where to open it)."""
    env = dict(os.environ, QUADSITL_WEB_PORT=str(free_tcp_port()))
    env["QUADSITL_GRPC_PORT"] = str(free_tcp_port())
    return subprocess.Popen(
        words, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
    )


def printed_url(process: subprocess.Popen[str], what: str, seconds: float = 60) -> str:
    """The URL the web viewer's command printed first (``what`` names the command)."""
    assert process.stdout is not None
    ready, _, _ = select.select([process.stdout], [], [], seconds)
    assert ready, f"{what} printed no URL within {seconds:g} s"
    line = process.stdout.readline()  # the first line: where to open it
    assert line.startswith("Rerun web viewer: open http://127.0.0.1:"), line
    return line.split("open ", 1)[1].strip()


def free_tcp_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def chromium_executable() -> str | None:
    """The browser binary itself (Debian's ``/usr/bin/chromium`` is a shell wrapper)."""
    for name in CANDIDATES:
        found = name if Path(name).is_file() else shutil.which(name)
        if found:
            return found
    return None


class HeadlessChromium:
    def __init__(self, executable: str, url: str, size: tuple[int, int] = (1280, 720)) -> None:
        to_chrome_r, self.to_chrome = os.pipe()
        self.from_chrome, from_chrome_w = os.pipe()

        def onto_3_and_4() -> None:  # runs in the child, before the exec
            a, b = os.dup(to_chrome_r), os.dup(from_chrome_w)
            os.dup2(a, 3)
            os.dup2(b, 4)

        self.process = subprocess.Popen(
            [
                *(executable, "--headless", "--no-sandbox", "--remote-debugging-pipe"),
                *("--use-angle=swiftshader", "--enable-unsafe-swiftshader"),
                f"--window-size={size[0]},{size[1]}",
                url,
            ],
            pass_fds=(3, 4),
            preexec_fn=onto_3_and_4,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self.buffer = b""
        self.last_id = 0
        targets = self.call("Target.getTargets")["targetInfos"]
        page = next(t for t in targets if t["type"] == "page")
        attached = self.call("Target.attachToTarget", targetId=page["targetId"], flatten=True)
        self.session = attached["sessionId"]

    def call(self, method: str, session: str | None = None, **params: Any) -> dict[str, Any]:
        self.last_id += 1
        message: dict[str, Any] = {"id": self.last_id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        os.write(self.to_chrome, json.dumps(message).encode() + b"\0")
        while True:
            while b"\0" not in self.buffer:
                ready, _, _ = select.select([self.from_chrome], [], [], REPLY_TIMEOUT)
                if not ready:
                    raise TimeoutError(f"Chromium did not answer {method} in {REPLY_TIMEOUT} s")
                chunk = os.read(self.from_chrome, 1 << 20)
                if not chunk:
                    raise RuntimeError("Chromium closed its DevTools pipe")
                self.buffer += chunk
            raw, self.buffer = self.buffer.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self.last_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def screenshot(self) -> bytes:
        """The page as a PNG."""
        shot = self.call("Page.captureScreenshot", session=self.session, format="png")
        return base64.b64decode(shot["data"])

    def close(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=10)
        os.close(self.to_chrome)
        os.close(self.from_chrome)
