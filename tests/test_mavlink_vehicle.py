"""The vehicle over real UDP, driven by an independent pymavlink client."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from pymavlink import mavutil

from gcs_tools.client import ClientError, Waypoint, mav
from gcs_tools.scripted_flight import fly_mission
from quadsitl.flight_software.params import PARAMETERS


def _hold_position(client, seconds: float) -> np.ndarray:
    """Positions (ENU) received over ``seconds`` of wall time."""
    samples = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        msg = client.pump()
        if msg is not None and msg.get_type() == "LOCAL_POSITION_NED":
            samples.append(client.position_enu())
    return np.array(samples)


def test_a_ground_station_just_heard_is_greeted_with_the_heartbeat(client, sim):
    """``client``: the simulator is up. A second ground station's first heartbeat gets the
    vehicle's at once, before any telemetry stream: a peer that connects (a lockstep env's
    client too) does not wait for the next 1 Hz beat."""
    station = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{sim.port}", source_system=254, source_component=190
    )
    try:
        station.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        first = None
        deadline = time.monotonic() + 10
        while first is None or first.get_type() == "STATUSTEXT":
            assert time.monotonic() < deadline, "the vehicle sent nothing to a new station"
            first = station.recv_match(blocking=True, timeout=0.5)
        assert first.get_type() == "HEARTBEAT" and first.get_srcSystem() == 1
    finally:
        station.close()


def test_heartbeat_identifies_a_disarmed_quadrotor(client):
    hb = client.latest["HEARTBEAT"]
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert hb.type == mav.MAV_TYPE_QUADROTOR and hb.autopilot == mav.MAV_AUTOPILOT_PX4
    assert hb.system_status == mav.MAV_STATE_STANDBY and not client.armed
    assert hb.base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert client.mode == "LOITER"
    status = client.wait_message("SYS_STATUS", 5)
    assert status.onboard_control_sensors_health & mav.MAV_SYS_STATUS_PREARM_CHECK
    gps = client.wait_message("GLOBAL_POSITION_INT", 5)
    assert gps.lat != 0 and gps.lon != 0 and abs(gps.relative_alt) < 20  # mm, on the ground


def test_parameters_list_set_and_refuse(client):
    params = client.get_params()
    assert set(params) == {p.name for p in PARAMETERS}
    assert client.set_param("MPC_XY_CRUISE", 3.0) == pytest.approx(3.0)
    with pytest.raises(ClientError, match=r"PARAM_ERROR 2"):  # VALUE_OUT_OF_RANGE
        client.set_param("MPC_XY_CRUISE", 999.0)
    client.wait(lambda: any("outside" in t for t in client.texts), 3, "a refusal STATUSTEXT")
    with pytest.raises(ClientError, match=r"PARAM_ERROR 5"):  # READ_ONLY
        client.set_param("SYS_AUTOSTART", 10016)
    assert params["SYS_AUTOSTART"] == 4001 and params["COM_RC_IN_MODE"] == 1  # INT32, bytewise
    assert client.set_param("NAV_DLL_ACT", 2) == 2
    client.conn.mav.param_request_read_send(1, 1, b"MPC_XY_CRUISE", -1)
    assert client.wait_message("PARAM_VALUE", 3).param_value == pytest.approx(3.0)


def test_arm_takeoff_goto_land(client):
    client.arm()
    client.takeoff(3.0)
    client.wait(
        lambda: client.position_enu()[2] > 2.9 and client.mode == "LOITER", 20, "take-off to 3 m"
    )
    client.goto(8.0, -4.0, 4.0)
    client.wait(
        lambda: np.linalg.norm(np.subtract(client.position_enu(), (8, -4, 4))) < 0.15,
        30,
        "the goto target",
    )
    client.land()
    client.wait(lambda: not client.armed, 30, "landing and automatic disarm")
    east, north, up = client.position_enu()
    assert abs(up) < 0.05 and math.hypot(east - 8, north + 4) < 0.3
    extended = client.wait_message("EXTENDED_SYS_STATE", 5)
    assert extended.landed_state == mav.MAV_LANDED_STATE_ON_GROUND


def test_mission_round_trip_and_flight(client):
    waypoints = (Waypoint(0, 0, 3), Waypoint(6, 0, 3), Waypoint(6, 6, 4, hold=0.5))
    report = fly_mission(client, waypoints, timeout=60)
    assert client.reached == [0, 1, 2, 3]
    assert report.landed and max(report.waypoint_errors) < 0.1 and report.path_max < 0.4
    items = client.download_mission()
    assert [i.command for i in items] == [22, 16, 16, 21]
    lat, lon = client.to_global(6, 6)
    assert items[2].x == round(lat * 1e7) and items[2].y == round(lon * 1e7) and items[2].z == 4


def test_mission_upload_refuses_unsupported_items_and_huge_counts(client):
    client.conn.mav.mission_count_send(1, 1, 65535, 0)
    assert client.wait_message("MISSION_ACK", 3).type == mav.MAV_MISSION_NO_SPACE
    ack = client.upload_mission([(mav.MAV_CMD_NAV_VTOL_TAKEOFF, 0, 0, 5, 0)])
    assert ack == mav.MAV_MISSION_UNSUPPORTED
    assert client.command(mav.MAV_CMD_MISSION_START, check=False) == mav.MAV_RESULT_DENIED


def test_offboard_follows_setpoints_then_holds_when_they_stop(client):
    def send_target():
        client.conn.mav.set_position_target_local_ned_send(
            0,
            1,
            1,
            mav.MAV_FRAME_LOCAL_NED,
            0b0000_1111_1111_1000,
            3.0,
            2.0,
            -4.0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
        )

    assert client.command(mav.MAV_CMD_DO_SET_MODE, 1, 6, 0, check=False) == mav.MAV_RESULT_DENIED
    send_target()
    client.arm()
    client.set_mode("OFFBOARD")
    deadline = time.monotonic() + 30
    while np.linalg.norm(np.subtract(client.position_enu(), (2, 3, 4))) > 0.1:
        assert time.monotonic() < deadline, "offboard target not reached"
        send_target()
        for _ in range(5):
            client.pump(0.01)
    client.wait(lambda: client.mode == "LOITER", 5, "offboard loss -> hold")
    assert any("offboard setpoints lost" in t for t in client.texts)
    held = _hold_position(client, 1.0)
    assert np.abs(held - (2, 3, 4)).max() < 0.3


def test_unsupported_command_is_acknowledged_as_such(client):
    assert (
        client.command(mav.MAV_CMD_DO_SET_SERVO, 1, 1500, check=False) == mav.MAV_RESULT_UNSUPPORTED
    )


def test_message_interval_and_request_message(client):
    client.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, -1)
    drained = time.monotonic() + 0.3  # what was already on its way
    while time.monotonic() < drained:
        client.pump(0.01)
    start = time.monotonic()
    while time.monotonic() - start < 1.0:
        msg = client.pump()
        assert msg is None or msg.get_type() != "ATTITUDE"
    client.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    version = client.wait_message("AUTOPILOT_VERSION", 3)
    assert version.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2


def test_crash_denies_arming_until_reboot(client):
    client.arm()
    client.takeoff(3.0)
    client.wait(lambda: client.position_enu()[2] > 2.5, 20, "take-off")
    with pytest.raises(ClientError):
        client.disarm()  # refused in flight without force
    client.disarm(force=True)
    client.wait(lambda: any("crashed" in t for t in client.texts), 10, "the crash")
    assert client.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, check=False) == mav.MAV_RESULT_DENIED
    assert client.wait_message("HEARTBEAT", 3).system_status == mav.MAV_STATE_CRITICAL
    client.command(mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
    client.arm()


def test_tlog_replays_through_pymavlink(sim, client):
    client.get_params()
    client.arm()
    sim_output = sim.stop()
    assert "timing:" in sim_output
    logs = list(__import__("pathlib").Path(sim.log_dir).glob("*.tlog"))
    assert len(logs) == 1
    reader = mavutil.mavlink_connection(str(logs[0]))
    kinds: dict[str, int] = {}
    while (msg := reader.recv_match()) is not None:
        kinds[msg.get_type()] = kinds.get(msg.get_type(), 0) + 1
    # Both directions: the client's requests and the vehicle's answers.
    assert kinds["PARAM_REQUEST_LIST"] == 1 and kinds["COMMAND_LONG"] >= 1
    assert kinds["PARAM_VALUE"] >= len(PARAMETERS) and kinds["COMMAND_ACK"] >= 1
    assert kinds["HEARTBEAT"] >= 2 and kinds["ATTITUDE"] >= 1  # how many: the wall clock's
