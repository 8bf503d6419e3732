"""One autopilot flown from outside, in lockstep: its simulator, its process and its
MAVLink link, owned by the env that trains through it.

The env is the autopilot's simulator (PX4's simulator_mavlink over TCP 4560 + i, served
here by :class:`~quadsitl.bridges.px4_tcp.Px4TcpServer`), so it holds the autopilot's
clock: in lockstep PX4 waits for each HIL_SENSOR, and it gets the next one only while
:meth:`AutopilotLink.advance` serves rounds. Between env steps the autopilot is paused,
however long the learner takes; every timeout of the autopilot (offboard loss, the
setpoint stream's rate, heartbeats) runs on simulated time. The env talks to the
autopilot as a companion computer does, over its onboard MAVLink link (UDP: PX4 sends to
14540 + i and listens on 14580 + i), and reads the autopilot's own estimate there.
"""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import time
import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.bridges.px4_hil import LINK_PORT, PEER_PORT, PORT, ROUND_US, HilPhysics
from quadsitl.bridges.px4_tcp import Px4TcpServer
from quadsitl.envs.sim_process import terminate
from quadsitl.physics.fleet import Fleet
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.udp_messages import pending_messages

HANG_GUARD_S = 120.0  # wall s an autopilot may take to answer before it is called stalled
ESTIMATE_WAIT_S = 1.0  # wall s to wait for the estimate of a step's end (then the last one)
HEARTBEAT_S = 1.0  # simulated s between the companion's heartbeats
STARTING_ROUND_S = 1.0  # wall s between rounds until the autopilot leads in lockstep
COMPANION_SYSTEM, COMPANION_COMPONENT = 255, mav.MAV_COMP_ID_ONBOARD_COMPUTER


class AutopilotError(RuntimeError):
    """The autopilot exited, disconnected or stalled (the message says which)."""


@dataclass
class Estimate:
    """What the autopilot last reported of its own state (NED/FRD, its clock)."""

    position_time_ms: int = -1
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, local NED
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s, local NED
    attitude_time_ms: int = -1
    quaternion: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # FRD -> NED
    rates: tuple[float, float, float] = (0.0, 0.0, 0.0)  # rad/s, FRD
    base_mode: int = 0
    custom_mode: int = 0
    acks: dict[int, int] = field(default_factory=dict)  # command -> result
    texts: list[str] = field(default_factory=list)

    @property
    def armed(self) -> bool:
        return bool(self.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)


class AutopilotLink:
    """PX4 instance ``instance`` started with ``command`` (a list; ``{port}`` and
    ``{instance}`` in it are filled in), flying a vehicle of ``airframe``."""

    def __init__(self, command: list[str], instance: int = 0, airframe: str = "iris") -> None:
        self.instance, self.airframe, self.start_command = instance, airframe, command
        self.notices: list[str] = []
        self.physics = HilPhysics(Fleet(1, airframe), notice=self.notices.append)
        self.fleet = self.physics.fleet
        self.server = Px4TcpServer(self.physics, "127.0.0.1", PORT + instance)
        # One round when the autopilot connects, then only those it answers: the rounds
        # before it leads in lockstep are then the same every time (the fake answers the
        # first; a real PX4 that does not is sent another each second).
        self.server.wall_round_s = STARTING_ROUND_S
        self.link = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.link.bind(("127.0.0.1", PEER_PORT + instance))
        self.link.setblocking(False)
        self.peer = ("127.0.0.1", LINK_PORT + instance)
        self.mav = mav.MAVLink(None, srcSystem=COMPANION_SYSTEM, srcComponent=COMPANION_COMPONENT)
        self.mav.robust_parsing = True
        self.estimate = Estimate()
        self.process: subprocess.Popen[bytes] | None = None
        self.next_heartbeat_us = 0
        # How much older than the step's end the estimate may be stamped: the fake sends
        # the state of every round; a real PX4 stamps its estimator's output.
        self.estimate_lag_ms = 0
        self.start()

    # --- the autopilot's process ------------------------------------------------------
    def start(self) -> None:
        """Start the autopilot and serve it until its estimate comes (a vehicle at rest)."""
        filled = [a.format(port=PORT, instance=self.instance) for a in self.start_command]
        before = self.physics.peers[0]  # a connection makes a new one
        self.server.hold_at_us[0] = 0  # its rounds wait for advance() from the first
        self.process = subprocess.Popen(filled, stdin=subprocess.DEVNULL)
        # ended with the link, or at exit if the env was never closed
        self._finalizer = weakref.finalize(self, terminate, self.process, 10.0)
        self.estimate = Estimate()
        deadline = time.monotonic() + HANG_GUARD_S
        while self.physics.peers[0] is before or not self.physics.peers[0].lockstep:
            self._check_alive(deadline)
            self.server.serve(0.05)  # until its first answer: it leads from now on
        self.read_until((self.time_us - ROUND_US) // 1000 - self.estimate_lag_ms, HANG_GUARD_S)
        # Where the autopilot's local frame has its origin in the simulator's (ENU, m):
        # PX4 puts it where its estimator started, at ground level (not the centre of
        # mass, which rests at the gear's height). Measured now, at rest.
        truth = self.fleet.state[0, :3]
        self.local_origin = truth - frames.ned_to_enu(np.array(self.estimate.position))

    def restart(self) -> None:
        """A new autopilot process; what the old one sent and did not deliver is dropped."""
        self.stop_process()
        self.read()
        self.next_heartbeat_us = 0
        self.start()

    def stop_process(self) -> None:
        if self.process is not None:
            self._finalizer()

    def close(self) -> None:
        self.stop_process()
        self.server.close()
        self.link.close()

    def _check_alive(self, deadline: float) -> None:
        code = self.process.poll() if self.process is not None else 1
        if code is not None:
            raise AutopilotError(f"the autopilot exited with code {code}")
        if time.monotonic() > deadline:
            raise AutopilotError(f"the autopilot did not answer within {HANG_GUARD_S:g} s")

    # --- time ---------------------------------------------------------------------
    @property
    def time_us(self) -> int:
        """The vehicle's simulated time (the autopilot's clock)."""
        return self.physics.peers[0].time_us

    def advance(self, seconds: float) -> None:
        """Let the autopilot fly ``seconds`` of simulated time (whole rounds of 4 ms),
        then hold it there and read its estimate of that instant."""
        target = self.time_us + round(seconds * 1e6 / ROUND_US) * ROUND_US
        deadline = time.monotonic() + HANG_GUARD_S
        # The round of the last step's end was held back: the autopilot gets it now,
        # after what the env sent since, and the round of this step's end is held.
        self.server.hold_at_us[0] = target
        self.server.release(0)
        while self.time_us < target:
            if self.server.connections[0] is None:
                self._check_alive(0.0)  # exited: say so; else it disconnected
                raise AutopilotError("the autopilot disconnected from its simulator")
            if self.time_us >= self.next_heartbeat_us:
                self.next_heartbeat_us = self.time_us + int(HEARTBEAT_S * 1e6)
                kind, none = mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID
                self.send(self.mav.heartbeat_encode(kind, none, 0, 0, 0))
            if self.server.serve(0.05) == 0:
                self._check_alive(deadline)
            else:
                deadline = time.monotonic() + HANG_GUARD_S
        # The estimate of the round before the step's end: its telemetry came before the
        # motor outputs that ended the step (the round of the end itself is held).
        self.read_until((target - ROUND_US) // 1000 - self.estimate_lag_ms)

    # --- the MAVLink link ---------------------------------------------------------
    def send(self, msg: Any) -> None:
        with contextlib.suppress(OSError):
            self.link.sendto(msg.pack(self.mav), self.peer)

    def read(self) -> None:
        """Take what the autopilot sent so far."""
        for msg in pending_messages(self.link, self.mav):
            self._take(msg)

    def read_until(self, time_ms: int, wait_s: float = ESTIMATE_WAIT_S) -> None:
        """Read until the estimate is stamped ``time_ms`` or later (the autopilot sends
        it from its own thread), waiting at most ``wait_s``."""
        deadline = time.monotonic() + wait_s
        e = self.estimate
        self.read()
        while min(e.position_time_ms, e.attitude_time_ms) < time_ms:
            if time.monotonic() > deadline:
                return
            time.sleep(0.0002)
            self.read()

    def _take(self, msg: Any) -> None:
        kind, e = msg.get_type(), self.estimate
        if kind == "LOCAL_POSITION_NED":
            e.position_time_ms = msg.time_boot_ms
            e.position, e.velocity = (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz)
        elif kind == "ATTITUDE_QUATERNION":
            e.attitude_time_ms = msg.time_boot_ms
            e.quaternion = (msg.q1, msg.q2, msg.q3, msg.q4)
            e.rates = (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
        elif kind == "HEARTBEAT" and msg.autopilot != mav.MAV_AUTOPILOT_INVALID:
            e.base_mode, e.custom_mode = msg.base_mode, msg.custom_mode
        elif kind == "COMMAND_ACK":
            e.acks[msg.command] = msg.result
        elif kind == "STATUSTEXT":
            e.texts.append(msg.text)

    def command(self, command: int, *params: float, within_s: float = 1.0) -> int:
        """COMMAND_LONG, answered within ``within_s`` simulated s; the result (or -1)."""
        values = [*params, *[0.0] * (7 - len(params))]
        self.estimate.acks.pop(command, None)
        self.send(self.mav.command_long_encode(1, 1, command, 0, *values))
        end = self.time_us + within_s * 1e6
        while command not in self.estimate.acks and self.time_us < end:
            self.advance(ROUND_US * 1e-6)
        return self.estimate.acks.get(command, -1)


def fake_px4_command(airframe: str = "iris") -> list[str]:
    """The in-repository fake (:mod:`quadsitl.fake_stacks.offboard_px4`) as a process."""
    module = "quadsitl.fake_stacks.offboard_px4"
    return [sys.executable, "-m", module, "-i", "{instance}", "--port", "{port}",
            "--airframe", airframe]  # fmt: skip
