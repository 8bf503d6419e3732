"""MAVSDK (the pip ``mavsdk`` package, its native library, no mocks) flies the simulator
with its ordinary calls, as a PX4 vehicle and as a generic one: connect on the API port,
health, arm, take-off to ``set_takeoff_altitude``, goto, a mission with speeds, a raw
mission with a DO_JUMP, ``is_mission_finished``, return to launch, auto-disarm."""

from __future__ import annotations

import asyncio
import math
import subprocess
import time
from pathlib import Path

import pytest

mavsdk = pytest.importorskip("mavsdk.asyncio", reason="MAVSDK is a dev dependency")
from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission import MissionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.plugins.mission import MissionItem, MissionPlan  # noqa: E402
from mavsdk.plugins.mission_raw import MissionItem as RawItem  # noqa: E402

from gcs_tools.demo import free_udp_port  # noqa: E402
from tests.conftest import cli  # noqa: E402

SPEED = 4.0  # simulator speed factor
NAN = math.nan
METRE = 1 / 111_320  # degrees of latitude per metre, about


async def _wait(condition, seconds: float, what: str) -> None:
    deadline = time.monotonic() + seconds
    while not await condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.2)


def _item(lat: float, lon: float, alt: float, speed: float = NAN) -> MissionItem:
    return MissionItem(
        latitude_deg=lat,
        longitude_deg=lon,
        relative_altitude_m=alt,
        speed_m_s=speed,
        is_fly_through=True,
        acceptance_radius_m=0.5,
    )


def _raw(seq: int, command: int, lat: float, lon: float, alt: float, p1=0.0, p2=0.0) -> RawItem:
    return RawItem(
        seq=seq,
        frame=6,
        command=command,
        current=int(seq == 0),
        autocontinue=1,
        param1=p1,
        param2=p2,
        param3=0.0,
        param4=NAN,
        x=round(lat * 1e7),
        y=round(lon * 1e7),
        z=alt,
        mission_type=0,
    )


async def _fly(port: int, identity: str) -> None:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await sdk.first_autopilot(timeout_s=30.0)
        assert system is not None
        expected = Autopilot.PX4 if identity == "px4" else Autopilot.GENERIC
        assert await system.autopilot_type() == expected
        telemetry, action = TelemetryAsync(system), ActionAsync(system)
        mission, raw = MissionAsync(system), MissionRawAsync(system)

        async def healthy() -> bool:
            health = await telemetry.health()
            return health.is_global_position_ok and health.is_home_position_ok

        await _wait(healthy, 20, "health")
        home = await telemetry.home()

        await action.set_takeoff_altitude(4.0)
        await action.arm()
        await action.takeoff()

        async def at(lat: float, lon: float, alt: float, tolerance: float = 0.5) -> bool:
            p = await telemetry.position()
            north = (p.latitude_deg - lat) / METRE
            east = (p.longitude_deg - lon) / METRE * math.cos(math.radians(lat))
            return math.hypot(north, east, p.relative_altitude_m - alt) < tolerance

        await _wait(lambda: at(home.latitude_deg, home.longitude_deg, 4.0, 0.3), 20, "4 m up")

        north = home.latitude_deg + 10 * METRE
        await action.goto_location(north, home.longitude_deg, home.absolute_altitude_m + 6, NAN)
        await _wait(lambda: at(north, home.longitude_deg, 6.0), 30, "the goto target")

        # A mission with speeds: MAVSDK adds DO_CHANGE_SPEED items with z = NaN.
        east = home.longitude_deg + 8 * METRE / math.cos(math.radians(home.latitude_deg))
        plan = MissionPlan(
            [_item(north, east, 5.0, speed=3.0), _item(home.latitude_deg, east, 5.0, speed=2.0)]
        )
        await mission.upload_mission(plan)
        await mission.start_mission()
        await _wait(mission.is_mission_finished, 60, "the mission with speeds to finish")
        assert await at(home.latitude_deg, east, 5.0)

        # A raw mission that goes round twice: A, B, DO_JUMP back to A once.
        items = [
            _raw(0, 16, north, home.longitude_deg, 5.0),
            _raw(1, 16, north, east, 5.0),
            _raw(2, 177, 0.0, 0.0, 0.0, p1=0, p2=1),
            _raw(3, 16, home.latitude_deg, east, 4.0),
        ]
        await raw.upload_mission(items)
        await raw.start_mission()
        await _wait(mission.is_mission_finished, 90, "the mission with a jump to finish")
        assert await at(home.latitude_deg, east, 4.0)

        await action.return_to_launch()

        async def disarmed() -> bool:
            return not await telemetry.armed()

        await _wait(disarmed, 90, "return, landing and auto-disarm")
        assert await at(home.latitude_deg, home.longitude_deg, 0.0, 0.3)


@pytest.mark.parametrize("identity", ["px4", "generic"])
def test_mavsdk_flies_takeoff_goto_missions_and_return(identity, tmp_path):
    port = free_udp_port()
    events = tmp_path / "events.txt"
    with open(events, "w") as out:
        sim = subprocess.Popen(
            cli(
                f"sim --gcs none --api udpout:127.0.0.1:{port} --logs none --speed {SPEED}",
                "--autopilot-id",
                identity,
            ),
            stdout=out,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            asyncio.run(asyncio.wait_for(_fly(port, identity), 240))
        finally:
            sim.terminate()
            sim.wait(10)
    text = Path(events).read_text()
    assert "mission item 2: jump to 0 (1/1)" in text  # the raw mission went round twice
    assert "denied" not in text and "refused" not in text, text
