"""A real PX4 flies quadsitl's physics (opt-in: no autopilot binary ships or builds here).

Set ``QUADSITL_PX4_BUILD`` to a PX4 SITL build folder (``build/px4_sitl_default`` of
PX4's own ``make px4_sitl_default``) and run ``pytest -m px4 tests/test_px4_real.py -s``.
PX4 (airframe none_iris, the shipped parameter file and nothing else) flies the iris
preset through simulator_mavlink in lockstep with ``quadsitl sim --flight-stack px4``;
MAVSDK, on PX4's own MAVLink API port, arms it, takes off to 5 m, flies a 4-waypoint
mission, lands and waits for the disarm. The flight's real-time factor is printed.
"""

from __future__ import annotations

import asyncio
import math
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from quadsitl.bridges.px4_airframe import parameter_folder
from quadsitl.bridges.px4_hil import PORT

BUILD = os.environ.get("QUADSITL_PX4_BUILD")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.px4,
    pytest.mark.skipif(
        not BUILD, reason="set QUADSITL_PX4_BUILD to a PX4 px4_sitl_default build to fly it"
    ),
]

ALTITUDE = 5.0  # m
SQUARE = 20.0  # m, side of the mission's square
METRE = 1 / 111_320  # degrees of latitude per metre, about


def free_instance() -> int:
    """A PX4 ``-i`` whose simulator (TCP 4560 + i) and MAVLink (UDP 14540 + i, 14550,
    18570 + i, 14580 + i) ports are free on this host."""
    for instance in range(3, 40):
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as t:
                t.bind(("127.0.0.1", PORT + instance))
            for udp in (14540, 18570, 14580):
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u:
                    u.bind(("127.0.0.1", udp + instance))
        except OSError:
            continue
        return instance
    raise AssertionError("no free PX4 instance ports")


async def _wait(condition, seconds: float, what: str) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + seconds
    while not await condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.1)


async def _fly(port: int) -> list[str]:
    """Take off, fly the square, land; what happened, line by line."""
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.mission import MissionAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    from mavsdk.plugins.mission import MissionItem, MissionPlan

    said = []
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await sdk.first_autopilot(timeout_s=60.0)
        assert system is not None
        telemetry, action, mission = (
            TelemetryAsync(system),
            ActionAsync(system),
            MissionAsync(system),
        )

        async def healthy() -> bool:
            return (await telemetry.health()).is_armable

        await _wait(healthy, 120, "PX4 armable (EKF2 aligned, GPS, home)")
        home = await telemetry.home()
        said.append(f"home {home.latitude_deg:.6f}, {home.longitude_deg:.6f}")
        lat0, lon0 = home.latitude_deg, home.longitude_deg
        east = METRE / math.cos(math.radians(lat0))
        corners = [(SQUARE, 0), (SQUARE, SQUARE), (0, SQUARE), (0, 0)]  # north, east m
        plan = MissionPlan(
            [
                MissionItem(
                    latitude_deg=lat0 + n * METRE,
                    longitude_deg=lon0 + e * east,
                    relative_altitude_m=ALTITUDE,
                    speed_m_s=5.0,
                    is_fly_through=True,
                    acceptance_radius_m=1.0,
                )
                for n, e in corners
            ]
        )
        await mission.upload_mission(plan)
        await action.set_takeoff_altitude(ALTITUDE)
        await action.arm()
        await action.takeoff()

        async def up() -> bool:
            return (await telemetry.position()).relative_altitude_m > ALTITUDE - 0.3

        await _wait(up, 60, f"{ALTITUDE} m up")
        said.append(f"took off to {(await telemetry.position()).relative_altitude_m:.2f} m")
        await mission.start_mission()
        await _wait(mission.is_mission_finished, 120, "the 4-waypoint mission to finish")
        p = await telemetry.position()
        said.append(
            f"mission finished at {(p.latitude_deg - lat0) / METRE:.1f} m north, "
            f"{(p.longitude_deg - lon0) / east:.1f} m east, {p.relative_altitude_m:.2f} m up"
        )
        await action.land()

        async def disarmed() -> bool:
            return not await telemetry.armed()

        await _wait(disarmed, 120, "landing and disarm")
        p = await telemetry.position()
        said.append(f"landed and disarmed at {p.relative_altitude_m:.2f} m")
    return said


def test_px4_flies_a_mission_on_quadsitl_in_lockstep() -> None:
    build = Path(BUILD or "")
    binary, etc = build / "bin" / "px4", build / "etc"
    assert binary.is_file() and etc.is_dir(), f"{build} is not a PX4 SITL build"
    instance = free_instance()
    folder = parameter_folder("iris")
    assert folder is not None
    sim = subprocess.Popen(
        [
            *(sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", "px4"),
            *("--airframe", "iris", "--flight-stack-port", str(PORT + instance)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert sim.stdout is not None
    assert "quadsitl sim: the aircraft" in sim.stdout.readline()
    with tempfile.TemporaryDirectory() as work:
        env = {**os.environ, "PATH": f"{folder}:{os.environ['PATH']}"}
        env["PX4_SIM_MODEL"] = "none_iris"
        px4 = subprocess.Popen(
            [str(binary), "-d", "-i", str(instance), str(etc)],
            cwd=work,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        started = time.monotonic()
        try:
            said = asyncio.run(asyncio.wait_for(_fly(14540 + instance), 400))
            wall = time.monotonic() - started
        finally:
            px4.terminate()
            px4.wait(30)
            sim.terminate()
            out, _ = sim.communicate(timeout=30)
    print("\n".join(said))
    print(out)
    assert "PX4 leads in lockstep" in out
    simulated = float(re.search(r"has flown ([0-9.]+) s of physics", out).group(1))  # type: ignore[union-attr]
    print(
        f"PX4 flew {simulated:.1f} s of physics in {wall:.1f} s: {simulated / wall:.1f}x real time"
    )
    assert said[-1].startswith("landed and disarmed")
