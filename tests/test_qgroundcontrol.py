"""QGroundControl's side of the wire, replayed with pymavlink over real UDP: its connect
sequence with its timeouts, the PX4 parameters its plugin reads, a Plan-view mission
(DO_JUMP, camera items, terrain frame), its guided actions (take-off before arming,
pause, change altitude, RTL by mode), Set Home, force arm, PARAM_ERROR, joystick, the
link-loss failsafe, STATUSTEXT chunks, and bad input. What QGC sends was read from its
source (src/Vehicle/InitialConnectStateMachine.cc, src/FirmwarePlugin/PX4/
PX4FirmwarePlugin.cc, src/MissionManager/PlanManager.cc, src/FactSystem/ParameterManager.cc).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil

from gcs_tools.demo import free_udp_port
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.simulator.identity import AVAILABLE_MODES
from quadsitl.simulator.links import Link
from quadsitl.simulator.server import MavlinkServer
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.modes import Mode
from quadsitl.wire.param_values import decode_value, encode_raw
from tests.conftest import wait_until_listening

COMMAND_ACK_TIMEOUT = 1.2  # s, QGC's (src/Vehicle/Vehicle.cc): then it resends ...
COMMAND_RETRIES = 3  # ... this many times
MISSION_ACK_TIMEOUT = 1.5  # s, QGC's PlanManager: then it asks again ...
MISSION_RETRIES = 5  # ... this many times
NAN = math.nan
# Parameters QGC's PX4 plugin reads without checking that they exist, and the values that
# make every setup page report "complete" (no "vehicle requires setup" dialog).
QGC_PX4_PARAMETERS = {
    "SYS_AUTOSTART": lambda v: v != 0,
    "CAL_GYRO0_ID": lambda v: v != 0,
    "CAL_ACC0_ID": lambda v: v != 0,
    "CAL_MAG0_ID": lambda v: v != 0,
    "SYS_HAS_MAG": lambda v: v == 1,
    "COM_RC_IN_MODE": lambda v: v == 1,
    "BAT1_SOURCE": lambda v: True,
    "BAT1_V_CHARGED": lambda v: v != 0,
    "BAT1_V_EMPTY": lambda v: v != 0,
    "BAT1_N_CELLS": lambda v: v != 0,
    "RTL_RETURN_ALT": lambda v: v > 0,
    "GF_ACTION": lambda v: True,
    "GF_MAX_HOR_DIST": lambda v: True,
    "GF_MAX_VER_DIST": lambda v: True,
    "NAV_DLL_ACT": lambda v: True,
    "COM_DL_LOSS_T": lambda v: v > 0,
    "COM_LOW_BAT_ACT": lambda v: True,
    "BAT_LOW_THR": lambda v: v > 0,
    "BAT_CRIT_THR": lambda v: v > 0,
    "BAT_EMERGEN_THR": lambda v: v > 0,
    "MIS_TAKEOFF_ALT": lambda v: v > 0,
    "MPC_XY_VEL_MAX": lambda v: v > 0,
}


class Station:
    """A ground station the way QGC is one: listens on a UDP port, heartbeats as a GCS."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.texts: list[str] = []
        self.chunks: dict[int, list[str]] = {}
        self.last_heartbeat = 0.0
        self.heartbeats = True

    def beat(self) -> None:
        self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        self.last_heartbeat = time.monotonic()

    def recv(self, timeout: float = 0.1):  # type: ignore[no-untyped-def]
        if self.heartbeats and time.monotonic() - self.last_heartbeat > 1.0:
            self.beat()
        msg = self.conn.recv_match(blocking=True, timeout=timeout)
        if msg is not None and msg.get_type() == "STATUSTEXT":
            self._statustext(msg)
        return msg

    def _statustext(self, msg) -> None:  # type: ignore[no-untyped-def]
        """Whole texts, chunks joined by their id (as QGC's StatusTextHandler does)."""
        if msg.id == 0:
            self.texts.append(msg.text)
            return
        self.chunks.setdefault(msg.id, []).append(msg.text)
        if len(msg.text) < 50:
            self.texts.append("".join(self.chunks.pop(msg.id)))

    def wait(self, kind: str, timeout: float = 5.0, check=None):  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.recv()
            if msg is not None and msg.get_type() == kind and (check is None or check(msg)):
                return msg
        raise AssertionError(f"no {kind} within {timeout} s")

    def command(self, command: int, *params: float, expect=mav.MAV_RESULT_ACCEPTED):  # type: ignore[no-untyped-def]
        """COMMAND_LONG as QGC sends it: sent again, confirmation + 1, while no ACK comes
        within QGC's timeout (a loaded machine may be slower; QGC then resends too);
        asserts the ACK's result and returns it."""
        values = [*params, *([0.0] * (7 - len(params)))]
        for confirmation in range(COMMAND_RETRIES + 1):
            self.conn.mav.command_long_send(1, 1, command, confirmation, *values)
            try:
                ack = self.wait("COMMAND_ACK", COMMAND_ACK_TIMEOUT, lambda m: m.command == command)
            except AssertionError:
                continue
            assert ack.result == expect, (command, ack.result, self.texts[-3:])
            return ack
        raise AssertionError(f"no COMMAND_ACK for {command} after {COMMAND_RETRIES} resends")

    def set_mode(self, mode: Mode) -> None:
        """As QGC's PX4 plugin sets modes: SET_MODE, then the heartbeat shows it."""
        self.conn.mav.set_mode_send(1, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode.custom_mode)
        self.wait("HEARTBEAT", 3, lambda m: m.custom_mode == mode.custom_mode)

    def altitude(self) -> float:
        return self.wait("GLOBAL_POSITION_INT").relative_alt / 1000

    def until(self, predicate, timeout: float, what: str) -> None:  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out waiting for {what}; texts: {self.texts[-5:]}")

    def close(self) -> None:
        self.conn.close()


@pytest.fixture
def qgc() -> Iterator[Station]:
    """The simulator sending to a ground station's port, as to QGC's 14550."""
    port = free_udp_port()
    command = f"sim --gcs udpout:127.0.0.1:{port} --api none --speed 4 --logs none"
    sim = subprocess.Popen(
        [sys.executable, "-m", "quadsitl.cli", *command.split()],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    wait_until_listening(sim)  # its udpout link
    station = Station(port)
    try:
        station.wait("HEARTBEAT", 30)
        station.beat()  # now that the station knows where the vehicle is
        yield station
    finally:
        station.close()
        sim.terminate()
        sim.wait(10)


def test_connect_sequence_is_answered_as_qgc_asks_it(qgc):
    hb = qgc.wait("HEARTBEAT")
    assert hb.autopilot == mav.MAV_AUTOPILOT_PX4 and hb.type == mav.MAV_TYPE_QUADROTOR
    qgc.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    version = qgc.wait("AUTOPILOT_VERSION")
    major, minor = version.flight_sw_version >> 24, (version.flight_sw_version >> 16) & 0xFF
    assert (major, minor) >= (1, 4)  # QGC warns about older PX4 firmware
    for bit in ("MISSION_INT", "COMMAND_INT", "MAVLINK2", "PARAM_ENCODE_BYTEWISE"):
        assert version.capabilities & getattr(mav, f"MAV_PROTOCOL_CAPABILITY_{bit}"), bit
    names = []
    index, count = 1, None
    while count is None or index <= count:  # QGC asks for the modes one by one
        qgc.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AVAILABLE_MODES, index)
        modes = qgc.wait("AVAILABLE_MODES", check=lambda m, i=index: m.mode_index == i)
        count = modes.number_modes
        names.append(modes.mode_name)
        index += 1
    assert names == [entry.name for entry in AVAILABLE_MODES]
    for metadata in (397, 395):  # COMPONENT_METADATA, COMPONENT_INFORMATION: a prompt NACK
        qgc.command(mav.MAV_CMD_REQUEST_MESSAGE, metadata, expect=mav.MAV_RESULT_UNSUPPORTED)
    qgc.conn.mav.param_request_list_send(1, 0)  # QGC targets component 0
    params: dict[str, float] = {}
    total = None
    while total is None or len(params) < total:
        msg = qgc.wait("PARAM_VALUE")
        params[msg.param_id] = decode_value(msg.param_value, msg.param_type)
        total = msg.param_count
    for name, complete in QGC_PX4_PARAMETERS.items():
        assert name in params and complete(params[name]), name
    for mission_type in (0, 1, 2):  # mission, then geofence and rally
        answer = _mission_count(qgc, mission_type)
        assert answer.count == 0
    home = qgc.wait("HOME_POSITION", 5)  # streamed: QGC does not ask for it
    assert home.latitude != 0


def _plan_item(seq, command, frame, params=(0.0, 0.0, 0.0, NAN), lat=0.0, lon=0.0, alt=0.0):  # type: ignore[no-untyped-def]
    return (seq, frame, command, 0, 1, *params, round(lat * 1e7), round(lon * 1e7), alt)


def _mission_count(qgc: Station, mission_type: int):  # type: ignore[no-untyped-def]
    """MISSION_REQUEST_LIST as QGC's PlanManager sends it: again while no MISSION_COUNT
    comes within its timeout."""
    for _ in range(MISSION_RETRIES + 1):
        qgc.conn.mav.mission_request_list_send(1, 1, mission_type)
        try:
            return qgc.wait(
                "MISSION_COUNT", MISSION_ACK_TIMEOUT, lambda m: m.mission_type == mission_type
            )
        except AssertionError:
            continue
    raise AssertionError(f"no MISSION_COUNT of type {mission_type}")


def _upload(qgc: Station, items: list[tuple]) -> int:  # type: ignore[type-arg]
    qgc.conn.mav.mission_count_send(1, 1, len(items), 0)
    while True:
        msg = qgc.wait("MISSION_REQUEST_INT", 2)
        qgc.conn.mav.mission_item_int_send(1, 1, *items[msg.seq], 0)
        if msg.seq == len(items) - 1:
            return int(qgc.wait("MISSION_ACK").type)


def test_plan_view_mission_with_jump_camera_and_terrain_items_flies_to_complete(qgc):
    home = qgc.wait("HOME_POSITION", 5)
    lat0, lon0 = home.latitude * 1e-7, home.longitude * 1e-7
    dlat, dlon = 1 / 111_320, 1 / (111_320 * math.cos(math.radians(lat0)))
    items = [
        _plan_item(0, 22, 3, (0, 0, 0, NAN), lat0, lon0, 4.0),  # take-off, relative frame
        _plan_item(1, 206, 2, (20.0, 0, 1, NAN)),  # Survey: camera trigger distance
        _plan_item(2, 16, 3, (0, 0, 0, NAN), lat0 + 6 * dlat, lon0, 4.0),
        _plan_item(3, 2000, 2, (0, 0, 1, NAN)),  # image start capture
        _plan_item(4, 16, 10, (0, 0, 0, NAN), lat0 + 6 * dlat, lon0 + 6 * dlon, 5.0),  # terrain
        _plan_item(5, 177, 2, (2, 1, 0, 0)),  # DO_JUMP to item 2, once
        _plan_item(6, 21, 3, (0, 0, 0, NAN), lat0, lon0, 0.0),  # land
    ]
    assert _upload(qgc, items) == mav.MAV_MISSION_ACCEPTED
    qgc.conn.mav.mission_request_list_send(1, 1, 0)  # downloaded back unchanged
    assert qgc.wait("MISSION_COUNT").count == len(items)
    for seq, sent in enumerate(items):
        qgc.conn.mav.mission_request_int_send(1, 1, seq, 0)
        got = qgc.wait("MISSION_ITEM_INT", 2, lambda m, s=seq: m.seq == s)
        fields = (
            got.frame,
            got.command,
            got.param1,
            got.param2,
            got.param3,
            got.param4,
            got.x,
            got.y,
            got.z,
        )
        expected = (sent[1], sent[2], *sent[5:])
        assert all(
            a == b or (math.isnan(a) and math.isnan(b))
            for a, b in zip(fields, expected, strict=True)
        ), (seq, fields, expected)
    qgc.conn.mav.mission_ack_send(1, 1, mav.MAV_MISSION_ACCEPTED, 0)
    qgc.set_mode(Mode.MISSION)  # QGC's Start Mission: the mode, then arm
    qgc.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    reached: list[int] = []
    states: list[int] = []

    def done() -> bool:
        msg = qgc.recv()
        if msg is not None and msg.get_type() == "MISSION_ITEM_REACHED":
            reached.append(msg.seq)
        if msg is not None and msg.get_type() == "MISSION_CURRENT":
            states.append(msg.mission_state)
        return bool(states) and states[-1] == mav.MISSION_STATE_COMPLETE

    qgc.until(done, 120, "MISSION_STATE_COMPLETE")
    assert reached == [0, 1, 2, 3, 4, 2, 3, 4, 5, 6]
    assert mav.MISSION_STATE_ACTIVE in states
    assert sum("skipped (no payload)" in t for t in qgc.texts) == 3
    qgc.until(
        lambda: not qgc.wait("HEARTBEAT").base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED,
        30,
        "auto-disarm",
    )


def test_guided_takeoff_pause_change_altitude_and_return(qgc):
    gps = qgc.wait("GLOBAL_POSITION_INT")
    amsl = gps.alt / 1000
    # QGC's Takeoff: NAV_TAKEOFF while disarmed, param7 = AMSL of here + the height...
    qgc.command(mav.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, NAN, NAN, NAN, amsl + 5.0)
    qgc.wait("HEARTBEAT", 3, lambda m: m.custom_mode == Mode.TAKEOFF.custom_mode)
    qgc.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)  # ... then it arms
    qgc.until(lambda: qgc.altitude() > 4.8, 30, "5 m")
    qgc.wait("HEARTBEAT", 10, lambda m: m.custom_mode == Mode.LOITER.custom_mode)
    # Change Altitude: DO_REPOSITION with an AMSL altitude, position NaN (stay here).
    qgc.command(mav.MAV_CMD_DO_REPOSITION, -1, 1, 0, NAN, NAN, NAN, amsl + 8.0)
    qgc.until(lambda: abs(qgc.altitude() - 8.0) < 0.2, 30, "8 m")
    # Go to Location 40 m north (DO_REPOSITION with a position), and on the way...
    home = qgc.wait("HOME_POSITION", 5)
    north_40 = home.latitude + round(40 / 111_320 * 1e7)
    go_to = (-1, 1, 0, NAN, north_40, home.longitude, amsl + 8.0)  # ..., yaw, lat, lon, alt
    qgc.conn.mav.command_int_send(1, 1, 0, mav.MAV_CMD_DO_REPOSITION, 0, 0, *go_to)  # AMSL
    qgc.wait("COMMAND_ACK", 3, lambda m: m.command == mav.MAV_CMD_DO_REPOSITION)
    qgc.wait("LOCAL_POSITION_NED", 30, lambda m: m.x > 5.0 and m.vx > 1.0)
    # ... Pause: DO_REPOSITION with everything NaN holds where the vehicle is.
    qgc.command(mav.MAV_CMD_DO_REPOSITION, -1, 1, 0, NAN, NAN, NAN, NAN)
    paused = qgc.wait("LOCAL_POSITION_NED")  # where the pause found it, at 4 m/s or so
    track = []  # the next 10 s of simulated time
    while not track or track[-1].time_boot_ms < paused.time_boot_ms + 10_000:
        track.append(qgc.wait("LOCAL_POSITION_NED"))
    assert max(m.x for m in track) < paused.x + 6.0  # it braked, and did not go on
    held = track[-1]  # ... and came back to where it was paused, and holds there
    # (within a telemetry interval of the pause: 20 ms, 160 ms when a busy machine slows it)
    assert math.hypot(held.x - paused.x, held.y - paused.y) < 1.0 and abs(held.z + 8.0) < 0.3
    assert math.hypot(held.vx, held.vy, held.vz) < 0.2
    qgc.set_mode(Mode.RTL)  # QGC's RTL is a mode change
    qgc.until(
        lambda: not qgc.wait("HEARTBEAT").base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED,
        60,
        "return and auto-disarm",
    )


def test_set_home_force_arm_and_parameter_refusal(qgc):
    home = qgc.wait("HOME_POSITION", 5)
    lat = home.latitude * 1e-7 + 10 / 111_320  # 10 m north, 3 m up
    qgc.command(
        mav.MAV_CMD_DO_SET_HOME, 0, 0, 0, 0, lat, home.longitude * 1e-7, home.altitude / 1000 + 3.0
    )
    moved = qgc.wait("HOME_POSITION", 1, lambda m: m.latitude != home.latitude)
    # COMMAND_LONG carries latitude as a float32: about 0.4 m of resolution here.
    assert moved.x == pytest.approx(10.0, abs=0.5) and moved.z == pytest.approx(-3.0, abs=0.01)
    assert qgc.wait("GLOBAL_POSITION_INT").relative_alt == pytest.approx(-3000, abs=20)
    qgc.command(mav.MAV_CMD_DO_SET_HOME, 1)  # back to the current position
    qgc.wait("HOME_POSITION", 1, lambda m: abs(m.latitude - home.latitude) < 2)
    # Force-disarm in flight: QGC's 2989 as well as 21196.
    qgc.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    qgc.command(mav.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, NAN, NAN, NAN, NAN)  # MIS_TAKEOFF_ALT
    qgc.until(lambda: qgc.altitude() > 1.0, 20, "lift-off")
    qgc.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, expect=mav.MAV_RESULT_DENIED)
    qgc.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 2989)
    # A refused write: one PARAM_ERROR, no PARAM_VALUE echo to resend on.
    qgc.conn.mav.param_set_send(1, 1, b"MPC_XY_CRUISE", 999.0, mav.MAV_PARAM_TYPE_REAL32)
    error = qgc.wait("PARAM_ERROR")
    assert (
        error.param_id == "MPC_XY_CRUISE" and error.error == mav.MAV_PARAM_ERROR_VALUE_OUT_OF_RANGE
    )
    deadline = time.monotonic() + 1.0
    while time.monotonic() < deadline:
        msg = qgc.recv()
        assert msg is None or msg.get_type() != "PARAM_VALUE"
    raw = encode_raw(2, mav.MAV_PARAM_TYPE_INT32)  # an INT32 write, bytewise as QGC sends it
    qgc.conn.mav.param_set_send(1, 1, b"NAV_DLL_ACT", raw, mav.MAV_PARAM_TYPE_INT32)
    echo = qgc.wait("PARAM_VALUE", 5, lambda m: m.param_id == "NAV_DLL_ACT")
    assert decode_value(echo.param_value, echo.param_type) == 2


def test_joystick_flies_position_mode(qgc):
    qgc.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    qgc.command(mav.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, NAN, NAN, NAN, NAN)
    qgc.wait("HEARTBEAT", 30, lambda m: m.custom_mode == Mode.LOITER.custom_mode)
    qgc.set_mode(Mode.POSCTL)
    start = qgc.wait("LOCAL_POSITION_NED")
    end = time.monotonic() + 1.0
    while time.monotonic() < end:  # full forward stick at ~25 Hz, as QGC's joystick sends
        qgc.conn.mav.manual_control_send(1, 1000, 0, 500, 0, 0)
        qgc.recv(0.04)
    qgc.conn.mav.manual_control_send(1, 0, 0, 500, 0, 0)
    moved = qgc.wait("LOCAL_POSITION_NED")
    assert math.hypot(moved.x - start.x, moved.y - start.y) > 3.0  # forward, fast


def test_link_loss_triggers_nav_dll_act(qgc):
    raw = encode_raw(3, mav.MAV_PARAM_TYPE_INT32)  # land
    qgc.conn.mav.param_set_send(1, 1, b"NAV_DLL_ACT", raw, mav.MAV_PARAM_TYPE_INT32)
    qgc.conn.mav.param_set_send(1, 1, b"COM_DL_LOSS_T", 5.0, mav.MAV_PARAM_TYPE_REAL32)
    qgc.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    qgc.command(mav.MAV_CMD_NAV_TAKEOFF, -1, 0, 0, NAN, NAN, NAN, NAN)
    qgc.wait("HEARTBEAT", 30, lambda m: m.custom_mode == Mode.LOITER.custom_mode)
    qgc.heartbeats = False  # the ground station goes silent (its heartbeat stops)
    qgc.wait("HEARTBEAT", 15, lambda m: m.custom_mode == Mode.LAND.custom_mode)
    assert any("ground station link lost" in t for t in qgc.texts)


@pytest.mark.parametrize(
    ("length", "chunks"),
    [(49, [49]), (50, [50]), (99, [50, 49]), (100, [50, 50, 0]), (150, [50, 50, 50, 0])],
)
def test_statustext_chunks_end_short_as_qgc_expects(length, chunks):
    """A text split over several STATUSTEXTs ends with a chunk under 50 bytes (an empty one
    when the text is a multiple of 50), else QGC waits a second and appends " ... "."""
    port = free_udp_port()
    station = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
    link = Link(f"udpout:127.0.0.1:{port}", "gcs", 1, 1)
    try:
        server = MavlinkServer(Vehicle(), [link])
        server.statustext(mav.MAV_SEVERITY_INFO, "x" * length)
        got = [station.recv_match(type="STATUSTEXT", blocking=True, timeout=2) for _ in chunks]
    finally:
        link.close()
        station.close()
    assert [len(m.text) for m in got] == chunks
    assert [m.chunk_seq for m in got] == list(range(len(chunks)))
    assert len({m.id for m in got}) == 1 and (got[0].id != 0) == (len(chunks) > 1)


def test_bad_input_is_refused_with_a_reason_and_the_old_mission_stays(qgc):
    qgc.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, NAN, expect=mav.MAV_RESULT_DENIED)
    assert any("param1 must be 0 or 1, got nan" in t for t in qgc.texts)
    amsl = qgc.wait("GLOBAL_POSITION_INT").alt / 1000
    too_high = (-1, 0, 0, NAN, NAN, NAN, amsl + 600.0)  # 600 m above home: over the limit
    qgc.command(mav.MAV_CMD_NAV_TAKEOFF, *too_high, expect=mav.MAV_RESULT_DENIED)
    assert any("take-off denied" in t for t in qgc.texts)
    good = [_plan_item(0, 22, 3, (0, 0, 0, NAN), 0, 0, 4.0)]
    assert _upload(qgc, good) == mav.MAV_MISSION_ACCEPTED
    bad = [*good, _plan_item(1, 31000, 3, (0, 0, 0, NAN), 0, 0, 4.0)]
    assert _upload(qgc, bad) == mav.MAV_MISSION_UNSUPPORTED
    assert any("mission item 1: unsupported mission command 31000" in t for t in qgc.texts)
    jump = [*good, _plan_item(1, 177, 2, (7, 1, 0, 0))]
    assert _upload(qgc, jump) == mav.MAV_MISSION_INVALID_SEQUENCE
    qgc.conn.mav.mission_request_list_send(1, 1, 0)
    assert qgc.wait("MISSION_COUNT").count == 1  # the previous mission stays
