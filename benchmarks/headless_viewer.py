"""The Rerun viewer without a window, driven through its control API: what
``benchmarks/images.py`` takes its pictures with.

A fresh viewer per picture: started headless at WINDOW, its start-up notices waited out
(see below), the recording opened and waited for (the time cursor at the end, where
the layout sent with it puts it), the top bar hidden, and the screenshot saved at
WINDOW's size. Without a GPU the viewer needs a software Vulkan driver (Debian:
``mesa-vulkan-drivers``).

**Notices.** The viewer shows each message it logs at start-up ("Listening for gRPC
connections ...", "Software rasterizer detected", "Headless viewer running at
1600×900.") as a toast in its top-right corner for four seconds of drawn frames, over
whatever is there, hidden top bar or not; on a busy machine they were still there when
the picture was taken. So the viewer is made to draw until no toast is left, once on
its empty start screen and again before the picture is kept: a toast is a box of its
own fill colour (TOAST) along the window's right edge (:func:`toast_rows`).
"""

from __future__ import annotations

import io
import socket
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from quadsitl.viz.viewer import viewer_binary

WINDOW = (1600, 900)  # logical points; saved at this size in pixels
TOAST = (33, 33, 33)  # a notification's fill in the viewer's dark theme (0.41)
TOAST_COLUMN = 14  # points from the right edge: inside a toast's margin, right of its text
TOAST_TOP, TOAST_BOTTOM = 30, 450  # points: where the stack of toasts hangs
TOAST_ROWS = 12  # rows of toast fill down that column: a toast (each is over 30 tall)
SETTLE = 120.0  # s: the longest the notices may take to go


def toast_rows(image: Any) -> int:
    """Rows of the toast column (right edge, top) in a notification's fill colour, in a
    picture (PIL image) of the viewer; TOAST_ROWS or more: a toast is shown."""
    from PIL import Image

    rgb = image.convert("RGB")
    if rgb.size != WINDOW:
        rgb = rgb.resize(WINDOW, Image.Resampling.BILINEAR)
    pixels = np.asarray(rgb, dtype=np.int16)
    column = pixels[TOAST_TOP:TOAST_BOTTOM, WINDOW[0] - TOAST_COLUMN - 2 : WINDOW[0] - TOAST_COLUMN]
    return int(np.all(np.abs(column - np.array(TOAST)) <= 3, axis=(1, 2)).sum())


class HeadlessViewer:
    """One headless viewer process and its control client."""

    def __init__(self, window: tuple[int, int] = WINDOW) -> None:
        from rerun.experimental import ViewerClient

        executable = viewer_binary()
        if executable is None:
            raise RuntimeError("the Rerun viewer executable is missing (rerun-sdk)")
        port = free_tcp_port()
        self.errors = tempfile.TemporaryFile("w+")  # noqa: SIM115 (closed in close())
        size = f"{window[0]}x{window[1]}"
        self.process = subprocess.Popen(
            [
                *(executable, "--headless", "--window-size", size, "--port", str(port)),
                *("--hide-welcome-screen", "--bind", "127.0.0.1"),
            ],
            stdout=subprocess.DEVNULL,
            stderr=self.errors,  # a file: a pipe nobody reads could fill and stall it
        )
        deadline = time.monotonic() + 60
        while True:
            try:
                self.client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
                self.client.get_state()
                break
            except Exception as error:  # not listening yet
                if self.process.poll() is not None:
                    raise self._ended("did not start") from None
                if time.monotonic() > deadline:
                    self.close()
                    message = f"images.py: the headless viewer did not answer: {error}"
                    raise SystemExit(message) from None
                time.sleep(0.5)
        self.picture()  # the start-up notices gone, on the empty start screen

    def picture(self) -> bytes:
        """A PNG of the whole viewer without a notice over it: screenshots (each one a
        frame drawn) until no toast is left."""
        from PIL import Image

        deadline = time.monotonic() + SETTLE
        while True:
            png = self.take_screenshot(deadline)
            if toast_rows(Image.open(io.BytesIO(png))) < TOAST_ROWS:
                return png
            if time.monotonic() > deadline:
                raise RuntimeError(f"the viewer's notices were still shown after {SETTLE:g} s")
            time.sleep(0.25)

    def take_screenshot(self, deadline: float | None = None) -> bytes:
        """One frame drawn and saved as PNG. On a busy machine a software-rendered frame
        can outlast the control connection's own wait ("transport error"): asked again
        while the viewer lives, until ``deadline`` (monotonic s; SETTLE from now)."""
        deadline = time.monotonic() + SETTLE if deadline is None else deadline
        while True:
            try:
                return bytes(self.client.take_screenshot())
            except ConnectionError:
                if self.process.poll() is not None:  # no Vulkan driver: it ends drawing
                    raise self._ended("ended while drawing") from None
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)

    def _ended(self, what: str) -> SystemExit:
        """The viewer process has ended: its last word, and what it needs."""
        self.errors.seek(0)
        said = self.errors.read().strip()
        last = said.splitlines()[-1] if said else f"exit code {self.process.returncode}"
        return SystemExit(
            f"images.py: the headless Rerun viewer {what} ({last}); "
            "without a GPU it needs Debian's mesa-vulkan-drivers"
        )

    def screenshot(self, rrd: Path, png: Path) -> list[str]:
        """Open ``rrd``, wait until all of it has arrived (the cursor at the end of the
        time line and the end no longer moving), save the picture; returns the problems
        the views report."""
        self.client.open(str(rrd))
        timeline, kind, end = last_time(rrd)
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:  # the viewer ingests a file over many frames
            state = self.client.get_state()
            ends = [t.end for r in state.recordings for t in r.timelines if t.name == timeline]
            if not state.loading and ends and ends[0] is not None and ends[0] >= end:
                break
            time.sleep(0.5)
        else:
            raise RuntimeError(f"the viewer did not load all of {rrd} within 180 s")
        self.client.set_time(timeline, **time_argument(kind, end))
        self.client.run_command("ui.toggle_top_panel")  # its badges ("software rasterizer")
        time.sleep(2.0)  # a few frames: plots and map fitted to the data
        png.write_bytes(self.picture())
        shrink_to_window(png)
        return [
            f"{view.name}: {report.summary}"
            for view in self.client.get_state().views
            for report in view.reports
        ]

    def close(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=10)
        self.errors.close()


def last_time(rrd: Path) -> tuple[str, str, int]:
    """(the recording's main timeline — ``time``, else ``step`` —, its kind —
    ``sequence``, ``duration`` or ``timestamp`` —, its last value)."""
    import pyarrow as pa
    import rerun.chunk as rrc

    ends: dict[str, tuple[str, int]] = {}
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        for name in ("time", "step"):
            if name in batch.schema.names:
                column = batch.column(name)
                kind = (
                    "timestamp"
                    if pa.types.is_timestamp(column.type)
                    else "duration"
                    if pa.types.is_duration(column.type)
                    else "sequence"
                )
                top = max(column.cast("int64").to_pylist())
                ends[name] = (kind, max(ends.get(name, (kind, top))[1], top))
    name = "time" if "time" in ends else "step"
    return name, *ends[name]


def time_argument(kind: str, end: int) -> dict[str, Any]:
    """The cursor at ``end``: a sequence (steps), a duration (ns) or a timestamp (ns
    since the epoch)."""
    if kind == "sequence":
        return {"sequence": end}
    if kind == "duration":
        return {"duration": np.timedelta64(end, "ns")}
    return {"timestamp": np.datetime64(end, "ns")}


def free_tcp_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def shrink_to_window(png: Path) -> None:
    """The viewer renders at 2 pixels per point; the README wants the logical size."""
    from PIL import Image

    image = Image.open(png).convert("RGB")
    if image.width > WINDOW[0]:
        image = image.resize(WINDOW, Image.Resampling.LANCZOS)
    image.save(png, optimize=True)
