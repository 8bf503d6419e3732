"""The Rerun pictures of the documentation, made from real runs (``make images``).

    python benchmarks/images.py [NAME ...]     # PNGs into docs/images/, .rrd beside them

Each recording is made the way a user makes it — the mission demo (``quadsitl demo``,
in still air and in wind with moderate turbulence,
replayed), a replay of a foreign-style (PX4-like) log, ``quadsitl eval --rerun`` of
each shipped policy, a 4-vehicle fleet (``quadsitl sim --vehicles 4``, each vehicle
flying its own mission, its log replayed) — and rendered by the Rerun viewer itself,
headless, through its control API, a fresh viewer per picture: the recording is
opened, the loading waited for (the time cursor at the end, where the layout sent with
the recording puts it), the top bar hidden (no notices over the content), and a
screenshot taken, saved at 1600x900. Without a GPU the viewer needs a software Vulkan
driver (Debian: ``mesa-vulkan-drivers``).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.replay import synthesise  # noqa: E402
from gcs_tools.client import VehicleClient, mav  # noqa: E402
from gcs_tools.demo import run_demo, start_simulator, stop_simulator  # noqa: E402
from gcs_tools.replay import convert  # noqa: E402
from gcs_tools.scripted_flight import Waypoint, mission_items  # noqa: E402
from quadsitl.viz.viewer import viewer_binary  # noqa: E402
from quadsitl.wire.addresses import free_udp_port  # noqa: E402

OUT = ROOT / "docs" / "images"
WINDOW = "1600x900"  # logical points; saved at this size in pixels
POLICIES = ("hover", "land", "random_waypoint", "static_waypoint", "target_follow")


def demo_recording(folder: Path, *sim_args: str) -> Path:
    """``quadsitl demo [SIM_ARGS]``: a mission flown through MAVLink, then replayed."""
    logs = folder / ("demo_wind" if sim_args else "demo")
    if run_demo(speed=4.0, logs=str(logs), sim_args=sim_args) != 0:
        raise RuntimeError("the demo flight failed")
    return next(logs.glob("*.rrd"))


def foreign_recording(folder: Path) -> Path:
    """A PX4-style log (ODOMETRY, GPS_RAW_INT, ACTUATOR_OUTPUT_STATUS ...), replayed."""
    log = folder / "px4_style.tlog"
    synthesise(log, seconds=120)
    out = folder / "px4_style.rrd"
    convert(log, out)
    return out


FLEET_HEIGHTS = (3.0, 4.5, 6.0, 7.5)  # m, each vehicle's mission altitude
FLEET_SPACING = 6.0  # m between the vehicles' start positions


def fleet_recording(folder: Path) -> Path:
    """``quadsitl sim --vehicles 4``: each vehicle takes off to its own height, flies a
    square of its own size east and north of its start, and lands; the one log all four
    write is replayed (``quadsitl replay``)."""
    logs = folder / "fleet"
    logs.mkdir()
    port = free_udp_port()
    sim = start_simulator(
        *("--vehicles", str(len(FLEET_HEIGHTS)), "--spacing", str(FLEET_SPACING)),
        *("--gcs", f"udpin:127.0.0.1:{port}", "--api", "none", "--speed", "4"),
        *("--logs", str(logs), "--quiet"),
    )
    clients = [
        VehicleClient(f"udpout:127.0.0.1:{port}", target=1 + i) for i in range(len(FLEET_HEIGHTS))
    ]
    try:
        for client, up in zip(clients, FLEET_HEIGHTS, strict=True):
            client.connect(timeout=60)
            client.drain()
            side = up / 2  # m
            square = ((0, 0), (side, 0), (side, side), (0, side), (0, 0))
            items = mission_items(tuple(Waypoint(e, n, up) for e, n in square))
            if client.upload_mission(items) != mav.MAV_MISSION_ACCEPTED:
                raise RuntimeError(f"system {client.target} refused its mission")
        for client in clients:
            client.drain()
            client.arm()
            client.set_mode("MISSION")
        deadline = time.monotonic() + 300
        while not all(len(c.reached) >= 5 and not c.armed for c in clients):
            if time.monotonic() > deadline:
                raise RuntimeError(f"the fleet did not land: {[c.reached for c in clients]}")
            for client in clients:
                client.pump(0.005)
    finally:
        for client in clients:
            client.close()
        stop_simulator(sim)
    out = folder / "fleet.rrd"
    convert(next(logs.glob("*.tlog")), out)
    return out


def eval_recording(folder: Path, task: str) -> Path:
    """``quadsitl eval policies/checkpoints/TASK.pt --episodes 3 --rerun TASK.rrd``."""
    out = folder / f"eval_{task}.rrd"
    checkpoint = ROOT / "policies" / "checkpoints" / f"{task}.pt"
    subprocess.run(
        [
            *(sys.executable, "-m", "quadsitl.cli", "eval", str(checkpoint)),
            *("--episodes", "3", "--rerun", str(out)),
        ],
        check=True,
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
    )
    return out


class HeadlessViewer:
    """The Rerun viewer without a window, driven through its control API."""

    def __init__(self, window: str = WINDOW) -> None:
        from rerun.experimental import ViewerClient

        executable = viewer_binary()
        if executable is None:
            raise RuntimeError("the Rerun viewer executable is missing (rerun-sdk)")
        port = free_tcp_port()
        self.errors = tempfile.TemporaryFile("w+")  # noqa: SIM115 (closed in close())
        self.process = subprocess.Popen(
            [
                *(executable, "--headless", "--window-size", window, "--port", str(port)),
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
                    self.errors.seek(0)
                    said = self.errors.read().strip()
                    last = said.splitlines()[-1] if said else f"exit code {self.process.returncode}"
                    raise SystemExit(
                        f"images.py: the headless Rerun viewer did not start ({last}); "
                        "without a GPU it needs Debian's mesa-vulkan-drivers"
                    ) from None
                if time.monotonic() > deadline:
                    self.close()
                    message = f"images.py: the headless viewer did not answer: {error}"
                    raise SystemExit(message) from None
                time.sleep(0.5)

    def screenshot(self, rrd: Path, png: Path) -> list[str]:
        """Open ``rrd``, wait until all of it has arrived (the cursor at the end of the
        time line and the end no longer moving), save the picture; returns the problems
        the views report."""
        self.client.open(str(rrd))
        timeline, end = last_time(rrd)
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline:  # the viewer ingests a file over many frames
            state = self.client.get_state()
            ends = [t.end for r in state.recordings for t in r.timelines if t.name == timeline]
            if not state.loading and ends and ends[0] is not None and ends[0] >= end:
                break
            time.sleep(0.5)
        else:
            raise RuntimeError(f"the viewer did not load all of {rrd} within 180 s")
        self.client.set_time(timeline, **time_argument(timeline, end))
        self.client.run_command("ui.toggle_top_panel")  # its notices ("software rasterizer")
        time.sleep(2.0)  # a few frames: plots and map fitted to the data
        png.write_bytes(self.client.take_screenshot())
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


def last_time(rrd: Path) -> tuple[str, int]:
    """(the recording's main timeline — ``time`` or ``step`` —, its last value)."""
    import rerun.chunk as rrc

    ends: dict[str, int] = {}
    for chunk in rrc.RrdReader(rrd).store().stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        for name in ("time", "step"):
            if name in batch.schema.names:
                top = max(batch.column(name).cast("int64").to_pylist())
                ends[name] = max(ends.get(name, top), top)
    name = "time" if "time" in ends else "step"
    return name, ends[name]


def time_argument(timeline: str, end: int) -> dict[str, Any]:
    """The cursor at ``end``: a sequence (step) or a timestamp (ns since the epoch)."""
    return {"sequence": end} if timeline == "step" else {"timestamp": np.datetime64(end, "ns")}


def free_tcp_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def shrink_to_window(png: Path) -> None:
    """The viewer renders at 2 pixels per point; the README wants the logical size."""
    from PIL import Image

    width, height = (int(v) for v in WINDOW.split("x"))
    image = Image.open(png).convert("RGB")
    if image.width > width:
        image = image.resize((width, height), Image.LANCZOS)
    image.save(png, optimize=True)


def recordings(folder: Path) -> dict[str, Callable[[], Path]]:
    """Picture name -> how its recording is made."""
    made: dict[str, Callable[[], Path]] = {
        "rerun_demo": lambda: demo_recording(folder),
        "rerun_wind": lambda: demo_recording(folder, "--wind", "5,270", "--turbulence", "moderate"),
        "rerun_replay_px4": lambda: foreign_recording(folder),
        "rerun_fleet": lambda: fleet_recording(folder),
    }
    for task in POLICIES:
        made[f"rerun_eval_{task}"] = lambda task=task: eval_recording(folder, task)
    return made


def main(names: list[str]) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        made = recordings(Path(tmp))
        unknown = set(names) - set(made)
        if unknown:
            raise SystemExit(f"images.py: unknown pictures {sorted(unknown)}; known: {list(made)}")
        for name, make in made.items():
            if names and name not in names:
                continue
            rrd = make()
            png = OUT / f"{name}.png"
            viewer = HeadlessViewer()  # a fresh one: nothing of the previous picture
            try:
                problems = viewer.screenshot(rrd, png)
            finally:
                viewer.close()
            print(f"{png.relative_to(ROOT)}  (from {rrd.name})", flush=True)
            for problem in problems:
                print(f"  view problem: {problem}")


if __name__ == "__main__":
    main(sys.argv[1:])
