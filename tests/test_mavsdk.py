"""MAVSDK (the pip ``mavsdk`` package, its native library, no mocks) flies the simulator
with its ordinary calls, as a PX4 vehicle and as a generic one: connect on the API port,
health, arm, take-off to ``set_takeoff_altitude``, goto, a mission with speeds, a raw
mission with a DO_JUMP, ``is_mission_finished``, return to launch, auto-disarm; and
ODOMETRY and the IMU messages on request, a parameter write of the wrong type refused,
quadsitl's version as the vendor version, a fence upload refused with its reason."""

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
from mavsdk.asyncio.plugins.geofence import GeofenceAsync  # noqa: E402
from mavsdk.asyncio.plugins.info import InfoAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission import MissionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.param import ParamAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.plugins.geofence import (  # noqa: E402
    FenceType,
    GeofenceData,
    GeofenceError,
    Point,
    Polygon,
)
from mavsdk.plugins.mission import MissionItem, MissionPlan  # noqa: E402
from mavsdk.plugins.mission_raw import MissionItem as RawItem  # noqa: E402
from mavsdk.plugins.param import ParamError  # noqa: E402

import quadsitl  # noqa: E402
from gcs_tools.demo import free_udp_port  # noqa: E402
from tests.conftest import cli, wait_until_listening  # noqa: E402

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

        async def finished_at(lat: float, lon: float, alt: float) -> bool:
            """Finished, and where its last item is: right after an upload MAVSDK can
            still hold the previous mission's "finished" (a loaded machine sees it)."""
            return await mission.is_mission_finished() and await at(lat, lon, alt)

        await mission.upload_mission(plan)
        await mission.start_mission()
        await _wait(lambda: finished_at(home.latitude_deg, east, 5.0), 60, "the mission to end")

        # A raw mission that goes round twice: A, B, DO_JUMP back to A once.
        items = [
            _raw(0, 16, north, home.longitude_deg, 5.0),
            _raw(1, 16, north, east, 5.0),
            _raw(2, 177, 0.0, 0.0, 0.0, p1=0, p2=1),
            _raw(3, 16, home.latitude_deg, east, 4.0),
        ]
        await raw.upload_mission(items)
        await raw.start_mission()
        await _wait(lambda: finished_at(home.latitude_deg, east, 4.0), 90, "the jump mission")

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
        wait_until_listening(sim)  # its udpout link
        try:
            asyncio.run(asyncio.wait_for(_fly(port, identity), 240))
        finally:
            sim.terminate()
            sim.wait(10)
    text = Path(events).read_text()
    assert "mission item 2: jump to 0 (1/1)" in text  # the raw mission went round twice
    assert "denied" not in text and "refused" not in text, text


async def _first(stream, seconds: float, what: str):  # type: ignore[no-untyped-def]
    """The first value of a MAVSDK subscription, within ``seconds``."""

    async def first():  # type: ignore[no-untyped-def]
        async for value in stream:
            return value

    try:
        return await asyncio.wait_for(first(), seconds)
    except TimeoutError:
        raise AssertionError(f"no {what} within {seconds} s") from None


async def _streams_params_version_fence(port: int) -> None:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await sdk.first_autopilot(timeout_s=30.0)
        assert system is not None
        telemetry = TelemetryAsync(system)

        # ODOMETRY and the IMU messages, streamed on request, at rest on the ground.
        await telemetry.set_rate_odometry(10.0)
        odometry = await _first(telemetry.subscribe_odometry(), 10, "ODOMETRY")
        assert abs(odometry.position_body.z_m) < 0.05  # local NED, on the ground
        q = odometry.q
        assert math.isclose(q.w**2 + q.x**2 + q.y**2 + q.z**2, 1.0, rel_tol=1e-5)
        await telemetry.set_rate_imu(10.0)
        imu = await _first(telemetry.subscribe_imu(), 10, "HIGHRES_IMU")
        # Specific force, from the noisy accelerometer model (σ ≈ 0.03 m/s² a sample).
        assert imu.acceleration_frd.down_m_s2 == pytest.approx(-9.81, abs=0.2)
        assert imu.acceleration_frd.forward_m_s2 == pytest.approx(0.0, abs=0.2)
        assert (
            0.4
            < math.hypot(
                imu.magnetic_field_frd.forward_gauss,
                imu.magnetic_field_frd.right_gauss,
                imu.magnetic_field_frd.down_gauss,
            )
            < 0.6
        )
        await telemetry.set_rate_raw_imu(10.0)
        raw = await _first(telemetry.subscribe_raw_imu(), 10, "RAW_IMU")
        assert raw.acceleration_frd.down_m_s2 == pytest.approx(-1000, abs=20)  # mG, as sent
        # The polling calls give the latest of each.
        latest = await asyncio.wait_for(telemetry.odometry(), 5)
        assert latest.time_usec >= odometry.time_usec > 0
        assert (await asyncio.wait_for(telemetry.imu(), 5)).timestamp_us > 0
        assert (await asyncio.wait_for(telemetry.raw_imu(), 5)).timestamp_us > 0

        # A write of the wrong type is an error, and changes nothing.
        param = ParamAsync(system)
        with pytest.raises(ParamError):
            await param.set_param_int("MPC_XY_CRUISE", 3)
        assert await param.get_param_float("MPC_XY_CRUISE") == pytest.approx(5.0)

        # quadsitl's version as the vendor's.
        version = await InfoAsync(system).get_version()
        vendor = (
            version.flight_sw_vendor_major,
            version.flight_sw_vendor_minor,
            version.flight_sw_vendor_patch,
        )
        assert vendor == tuple(int(p) for p in quadsitl.__version__.split(".")[:3])

        # A fence is refused (the reason is in a STATUSTEXT; see the events below).
        point = Point(47.3977, 8.5456)
        fence = GeofenceData(
            [Polygon([point, Point(47.3987, 8.5456), Point(47.3987, 8.5466)], FenceType.INCLUSION)],
            [],
        )
        with pytest.raises(GeofenceError):
            await GeofenceAsync(system).upload_geofence(fence)


def test_mavsdk_streams_odometry_and_imu_refuses_wrong_types_and_fences(tmp_path):
    port = free_udp_port()
    events = tmp_path / "events.txt"
    with open(events, "w") as out:
        sim = subprocess.Popen(
            cli(f"sim --gcs none --api udpout:127.0.0.1:{port} --logs none"),
            stdout=out,
            stderr=subprocess.STDOUT,
            text=True,
        )
        wait_until_listening(sim)  # its udpout link
        try:
            asyncio.run(asyncio.wait_for(_streams_params_version_fence(port), 120))
        finally:
            sim.terminate()
            sim.wait(10)
    text = Path(events).read_text()
    assert "param set refused: MPC_XY_CRUISE is REAL32" in text, text
    assert "upload refused: no geofence" in text, text
    assert "is not streamed" not in text, text
