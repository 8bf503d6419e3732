"""A real ArduCopter flies quadsitl's physics (opt-in: no autopilot binary ships or builds here).

Set ``QUADSITL_ARDUPILOT_BIN`` to an ``arducopter`` SITL binary built from ArduPilot's own
instructions and run ``pytest -m ardupilot tests/test_ardupilot_real.py -s``. ArduCopter
flies the iris and paper-x-fast presets through its JSON backend in lockstep with ``quadsitl sim
--flight-stack ardupilot`` and the shipped parameter file and nothing else; pymavlink, on
ArduCopter's own MAVLink port, arms it in GUIDED, takes off to 5 m, uploads and flies a
4-waypoint AUTO mission ending in a landing, and waits for the disarm. The flight's
real-time factor is printed.
"""

from __future__ import annotations

import math
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from quadsitl.bridges.ardupilot_udp import parameter_file

BINARY = os.environ.get("QUADSITL_ARDUPILOT_BIN")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.ardupilot,
    pytest.mark.skipif(
        not BINARY, reason="set QUADSITL_ARDUPILOT_BIN to an ArduCopter SITL binary to fly it"
    ),
]

HOME = (-35.363261, 149.165230, 584.0, 353.0)  # ArduPilot's default SITL home (CMAC)
ALTITUDE = 5.0  # m
SQUARE = 20.0  # m, side of the mission's square
GUIDED, AUTO = 4, 3  # ArduCopter custom modes


def free_instance() -> int:
    """An ArduPilot ``-I`` whose physics (UDP 9002 + 10 i) and MAVLink (TCP 5760 + 10 i)
    ports are free, so that the test does not meet another SITL on this host."""
    for instance in range(3, 60):
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as u:
                u.bind(("127.0.0.1", 9002 + 10 * instance))
            for tcp in range(5760, 5764):
                with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as t:
                    t.bind(("127.0.0.1", tcp + 10 * instance))
        except OSError:
            continue
        return instance
    raise AssertionError("no free ArduPilot instance ports")


def offset(north: float, east: float) -> tuple[int, int]:
    """(lat, lon) in 1e-7 degrees of a point north/east metres from HOME."""
    lat = HOME[0] + math.degrees(north / 6378137.0)
    lon = HOME[1] + math.degrees(east / (6378137.0 * math.cos(math.radians(HOME[0]))))
    return round(lat * 1e7), round(lon * 1e7)


class Copter:
    """pymavlink on ArduCopter's SERIAL0, with waits that fail after a wall-clock limit."""

    def __init__(self, port: int) -> None:
        from pymavlink import mavutil

        self.mavutil = mavutil
        deadline = time.monotonic() + 60
        while True:
            try:
                self.link = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", autoreconnect=False)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        self.link.wait_heartbeat(timeout=60)
        self.texts: list[str] = []

    def recv(self, types: list[str], timeout: float) -> object | None:
        message = self.link.recv_match(type=[*types, "STATUSTEXT"], blocking=True, timeout=timeout)
        if message is not None and message.get_type() == "STATUSTEXT":
            self.texts.append(message.text)
            print("ArduCopter:", message.text)
            return None
        return message

    def wait(self, types: list[str], check, timeout: float, what: str):  # type: ignore[no-untyped-def]
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            message = self.recv(types, 1.0)
            if message is not None and check(message):
                return message
        raise AssertionError(f"{what}: not within {timeout} s; ArduCopter said {self.texts[-8:]}")

    def command(self, command: int, *params: float) -> int:
        p = list(params) + [0.0] * (7 - len(params))
        self.link.mav.command_long_send(1, 1, command, 0, *p)
        ack = self.wait(["COMMAND_ACK"], lambda m: m.command == command, 10, f"ack of {command}")
        return int(ack.result)

    def mode(self, mode: int) -> None:
        self.link.mav.set_mode_send(1, self.mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)
        self.wait(["HEARTBEAT"], lambda m: m.custom_mode == mode, 10, f"mode {mode}")


def upload_mission(copter: Copter) -> None:
    """Home, 4 corners of a square at ALTITUDE, then LAND."""
    mavlink = copter.mavutil.mavlink
    corners = [(SQUARE, 0.0), (SQUARE, SQUARE), (0.0, SQUARE), (0.0, 0.0)]
    items = [(mavlink.MAV_CMD_NAV_WAYPOINT, *offset(0, 0), 0.0)]  # 0: home, as ArduPilot keeps it
    items += [(mavlink.MAV_CMD_NAV_WAYPOINT, *offset(n, e), ALTITUDE) for n, e in corners]
    items += [(mavlink.MAV_CMD_NAV_LAND, 0, 0, 0.0)]
    copter.link.mav.mission_count_send(1, 1, len(items), 0)
    while True:
        request = copter.wait(
            ["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"], lambda m: True, 10, "upload"
        )
        if request.get_type() == "MISSION_ACK":
            assert request.type == mavlink.MAV_MISSION_ACCEPTED, request
            return
        command, lat, lon, alt = items[request.seq]
        frame = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        copter.link.mav.mission_item_int_send(
            1, 1, request.seq, frame, command, 0, 1, 0, 0, 0, 0, lat, lon, alt, 0
        )


@pytest.mark.parametrize("airframe", ["iris", "paper-x-fast"])
def test_arducopter_takes_off_flies_a_mission_and_lands_on_quadsitl(
    airframe: str, tmp_path: Path
) -> None:
    instance = free_instance()
    parm = parameter_file(airframe)
    assert parm is not None and BINARY is not None
    command = [sys.executable, "-m", "quadsitl.cli", "sim", "--flight-stack", "ardupilot"]
    sim = subprocess.Popen(
        [*command, "--airframe", airframe, "--flight-stack-port", str(9002 + 10 * instance)],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert sim.stdout is not None
    while "vehicle 0:" not in sim.stdout.readline():
        assert sim.poll() is None, "the simulator did not start"
    home = ",".join(str(v) for v in HOME)
    copter_log = open(tmp_path / "arducopter.log", "w")  # noqa: SIM115 - closed below
    arducopter = subprocess.Popen(
        [
            BINARY,
            "--model",
            "JSON",
            "--defaults",
            str(parm),
            "-I",
            str(instance),
            "-w",
            "--home",
            home,
            "--speedup",
            "100",
        ],
        cwd=tmp_path,  # its eeprom.bin and logs
        stdout=copter_log,
        stderr=subprocess.STDOUT,
    )
    try:
        copter = Copter(5760 + 10 * instance)
        mavlink = copter.mavutil.mavlink
        copter.link.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_ALL, 10, 1)
        # GUIDED flies by position: wait for ArduCopter's EKF to use GPS before choosing it.
        copter.wait(
            ["HEARTBEAT"], lambda m: any("using GPS" in t for t in copter.texts), 240, "GPS"
        )
        copter.mode(GUIDED)
        deadline = time.monotonic() + 240
        while copter.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) != 0:
            assert time.monotonic() < deadline, f"no arming: {copter.texts[-8:]}"
            time.sleep(1.0)  # the EKF converges and GPS locks in ArduCopter's own time
        # At once: a copter left armed on the ground disarms itself after 10 s (DISARM_DELAY),
        # under a second of wall time in lockstep.
        assert copter.command(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, ALTITUDE) == 0
        started_wall = time.monotonic()
        started_sim = copter.wait(["SYSTEM_TIME"], lambda m: True, 10, "time").time_boot_ms

        def height(m) -> float:  # type: ignore[no-untyped-def]
            return m.relative_alt / 1000.0

        copter.wait(["GLOBAL_POSITION_INT"], lambda m: height(m) > ALTITUDE - 0.3, 60, "take-off")
        upload_mission(copter)
        copter.mode(AUTO)
        reached = set()
        while len(reached) < 4:
            m = copter.wait(["MISSION_ITEM_REACHED"], lambda m: True, 120, f"waypoints {reached}")
            reached.add(m.seq)
        copter.wait(
            ["HEARTBEAT"],
            lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED,
            180,
            "landing and disarm",
        )
        ended_sim = copter.wait(["SYSTEM_TIME"], lambda m: True, 10, "time").time_boot_ms
        factor = (ended_sim - started_sim) / 1000.0 / (time.monotonic() - started_wall)
        position = copter.wait(["GLOBAL_POSITION_INT"], lambda m: True, 10, "position")
        flown = (ended_sim - started_sim) / 1000.0
        print(
            f"ArduCopter on {airframe} flew the mission and landed: waypoints "
            f"{sorted(reached)}, landed at {height(position):.2f} m; {flown:.1f} s flown in "
            f"{time.monotonic() - started_wall:.1f} s: {factor:.1f}x real time in lockstep"
        )
        assert {1, 2, 3, 4} <= reached and abs(height(position)) < 0.5
    finally:
        arducopter.terminate()
        try:
            arducopter.wait(timeout=10)
        except subprocess.TimeoutExpired:  # stuck waiting for its physics
            arducopter.kill()
            arducopter.wait()
        copter_log.close()
        sim.terminate()
        sim.wait(timeout=30)
