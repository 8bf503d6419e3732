"""The Rerun pictures of the documentation, made from real runs (``make images``).

    python benchmarks/images.py [NAME ...]          # PNGs into build/images/
    python benchmarks/images.py --docs [NAME ...]   # and copied into docs/images/

Each recording is made the way a user makes it — the mission demo (``quadsitl demo``,
in still air and in wind with moderate turbulence, replayed), a replay of a
foreign-style (PX4-like) log, of the real PX4's and ArduPilot's own logs of
tests/data/, ``quadsitl eval --rerun`` of each shipped policy, a
4-vehicle fleet (``quadsitl sim --vehicles 4``, each vehicle flying its own mission,
its log replayed), the live view of 64 vehicles (``sim --vehicles 64 --rerun-save``)
and, with ``QUADSITL_PX4_BUILD`` set, of a real PX4 (``sim --flight-stack px4
--rerun-save``) — and rendered by the Rerun viewer itself, headless
(:mod:`benchmarks.headless_viewer`), a fresh viewer per picture. The flights are
flown in real time (``--speed 1``), as a user's are: a log's clock is the wall's, and
a flight four times faster would last ten seconds of it, too short for a time axis to
carry more than one label. ``python benchmarks/figures.py`` draws the other pictures
of docs/images (trajectories, learning curves) the same way: into build/images/, and
into docs/images/ with ``--docs``.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.headless_viewer import HeadlessViewer  # noqa: E402
from benchmarks.replay import synthesise  # noqa: E402
from gcs_tools.client import VehicleClient, mav  # noqa: E402
from gcs_tools.demo import (  # noqa: E402
    connect_while_starting,
    run_demo,
    start_simulator,
    stop_simulator,
)
from gcs_tools.replay import convert  # noqa: E402
from gcs_tools.scripted_flight import Waypoint, mission_items  # noqa: E402
from quadsitl.wire.addresses import free_udp_port  # noqa: E402

OUT = ROOT / "build" / "images"  # ignored by git: a render never dirties the tree
DOCS = ROOT / "docs" / "images"  # the tracked pictures, replaced only with --docs
SPEED = 1.0  # times real time: the flights' (see above)
POLICIES = ("hover", "land", "random_waypoint", "static_waypoint", "target_follow")


def demo_recording(folder: Path, *sim_args: str) -> Path:
    """``quadsitl demo [SIM_ARGS]``: a mission flown through MAVLink, then replayed."""
    logs = folder / ("demo_wind" if sim_args else "demo")
    if run_demo(speed=SPEED, logs=str(logs), sim_args=sim_args) != 0:
        raise RuntimeError("the demo flight failed")
    return next(logs.glob("*.rrd"))


def foreign_recording(folder: Path) -> Path:
    """A PX4-style log (ODOMETRY, GPS_RAW_INT, ACTUATOR_OUTPUT_STATUS ...), replayed."""
    log = folder / "px4_style.tlog"
    synthesise(log, seconds=120)
    out = folder / "px4_style.rrd"
    convert(log, out)
    return out


def flight_stack_log_recording(folder: Path, log: Path) -> Path:
    """A real autopilot's own log (tests/data: PX4's ULog, ArduPilot's DataFlash, of a
    flight on quadsitl), replayed: estimate, setpoint and truth."""
    out = folder / f"{log.stem}.rrd"
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
        *("--gcs", f"udpin:127.0.0.1:{port}", "--api", "none", "--speed", str(SPEED)),
        *("--logs", str(logs), "--quiet"),
    )
    clients = [
        VehicleClient(f"udpout:127.0.0.1:{port}", target=1 + i) for i in range(len(FLEET_HEIGHTS))
    ]
    try:
        for client, up in zip(clients, FLEET_HEIGHTS, strict=True):
            connect_while_starting(client, sim)
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


CROWD_SIZE = 64  # vehicles of the live crowd's picture
CROWD_FOCUS = 10  # the one drawn in full


def live_fleet_recording(folder: Path) -> Path:
    """``quadsitl sim --vehicles 64 --rerun-save``: every vehicle takes off to one of
    eight heights, hops a few metres, and every other one lands; the live view draws
    vehicle 10 in full, the crowd dimmed."""
    out = folder / "live_fleet.rrd"
    port = free_udp_port()
    sim = start_simulator(
        *("--vehicles", str(CROWD_SIZE), "--spacing", "4", "--speed", str(SPEED)),
        *("--gcs", f"udpin:127.0.0.1:{port}", "--api", "none", "--logs", "none", "--quiet"),
        *("--rerun-save", str(out), "--rerun-focus", str(CROWD_FOCUS)),
    )
    clients = [VehicleClient(f"udpout:127.0.0.1:{port}", target=1 + i) for i in range(CROWD_SIZE)]

    def pump_for(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for client in clients:
                client.drain()
            time.sleep(0.05)

    try:
        for client in clients:
            connect_while_starting(client, sim)
        heights = [2.0 + (i % 8) * 0.8 for i in range(CROWD_SIZE)]
        for client, up in zip(clients, heights, strict=True):
            client.drain()
            client.arm()
            client.takeoff(up)
        pump_for(12.0)
        for i, (client, up) in enumerate(zip(clients, heights, strict=True)):
            client.drain()
            client.goto(3.0 * (i % 3 - 1), 3.0 * (i // 3 % 3 - 1), up)
        pump_for(12.0)
        for client in clients[::2]:
            client.drain()
            client.land()
        pump_for(10.0)
    finally:
        for client in clients:
            client.close()
        stop_simulator(sim)
    return out


def live_px4_recording(folder: Path, build: Path) -> Path:
    """``quadsitl sim --flight-stack px4 --rerun-save``: a real PX4 (its SITL build at
    ``build``) takes off, flies a 6 m square mission and lands; the view draws its
    estimate beside the truth."""
    from quadsitl.bridges.px4_airframe import parameter_folder
    from quadsitl.bridges.px4_hil import PEER_PORT, PORT
    from tests.test_px4_real import _fly, free_instance

    out = folder / "live_px4.rrd"
    instance = free_instance()
    command = [sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", "px4"]
    command += ["--flight-stack-port", str(PORT + instance), "--rerun-save", str(out)]
    sim = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL)
    work = folder / "px4"
    work.mkdir()
    path = f"{parameter_folder('iris')}:{os.environ['PATH']}"
    px4 = subprocess.Popen(
        [str(build / "bin" / "px4"), "-d", "-i", str(instance), str(build / "etc")],
        cwd=work,
        env={**os.environ, "PATH": path, "PX4_SIM_MODEL": "none_iris"},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        import tests.test_px4_real as flight

        flight.SQUARE, flight.ALTITUDE = 6.0, 3.0
        asyncio.run(asyncio.wait_for(_fly(PEER_PORT + instance), 400))
    finally:
        px4.terminate()
        px4.wait(30)
        sim.terminate()
        sim.wait(60)
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


PX4_ULOG = ROOT / "tests" / "data" / "px4_mission.ulg"
ARDUPILOT_LOG = ROOT / "tests" / "data" / "ardupilot_mission.bin"


def recordings(folder: Path) -> dict[str, Callable[[], Path]]:
    """Picture name -> how its recording is made."""
    made: dict[str, Callable[[], Path]] = {
        "rerun_demo": lambda: demo_recording(folder),
        "rerun_wind": lambda: demo_recording(folder, "--wind", "5,270", "--turbulence", "moderate"),
        "rerun_replay_px4": lambda: foreign_recording(folder),
        "rerun_fleet": lambda: fleet_recording(folder),
        "rerun_replay_ulog": lambda: flight_stack_log_recording(folder, PX4_ULOG),
    }
    made["rerun_live_fleet"] = lambda: live_fleet_recording(folder)
    build = os.environ.get("QUADSITL_PX4_BUILD")
    if build:  # a real PX4 flies it; without one the picture is left as it is
        made["rerun_live_px4"] = lambda: live_px4_recording(folder, Path(build))
    else:
        print("images.py: rerun_live_px4 skipped (set QUADSITL_PX4_BUILD to a PX4 SITL build)")
    if ARDUPILOT_LOG.exists():
        made["rerun_replay_dataflash"] = lambda: flight_stack_log_recording(folder, ARDUPILOT_LOG)
    for task in POLICIES:
        made[f"rerun_eval_{task}"] = lambda task=task: eval_recording(folder, task)
    return made


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="only these pictures (all without)")
    parser.add_argument("--docs", action="store_true", help="also copy into docs/images/")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        made = recordings(Path(tmp))
        unknown = set(args.names) - set(made)
        if unknown:
            raise SystemExit(f"images.py: unknown pictures {sorted(unknown)}; known: {list(made)}")
        for name, make in made.items():
            if args.names and name not in args.names:
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
            if args.docs:
                shutil.copyfile(png, DOCS / png.name)
                print(f"  copied to {(DOCS / png.name).relative_to(ROOT)}", flush=True)


if __name__ == "__main__":
    main()
