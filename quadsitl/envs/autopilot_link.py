"""Autopilots flown from outside, in lockstep: their simulator, their processes and their
MAVLink links, owned by the env that trains through them.

The env is the autopilots' simulator (PX4's simulator_mavlink over TCP 4560 + i, served
here by :class:`~quadsitl.bridges.px4_tcp.Px4TcpServer` around one batched physics), so
it holds each autopilot's clock: in lockstep PX4 waits for each HIL_SENSOR, and it gets
the next one only while :meth:`Autopilots.advance` serves rounds. Between env steps the
autopilots are paused, however long the learner takes; every timeout of an autopilot
(offboard loss, the setpoint stream's rate, heartbeats) runs on simulated time. The env
talks to each autopilot as a companion computer does, over its onboard MAVLink link
(UDP: PX4 sends to 14540 + i and listens on 14580 + i), and reads the autopilot's own
estimate there.

An autopilot that exits, disconnects or stops answering is marked failed and no longer
waited for: the others fly on (:meth:`Autopilots.advance` returns who failed), and
:meth:`Autopilots.restart` starts it again.
"""

from __future__ import annotations

import contextlib
import socket
import subprocess
import sys
import time
import weakref
from collections.abc import Sequence
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

BOOT_GUARD_S = 120.0  # wall s an autopilot may take to start and lead in lockstep
STALL_S = 10.0  # wall s without a round, once in lockstep, before it is called stalled
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

    @property
    def time_ms(self) -> int:
        """The clock of its oldest part (position or attitude)."""
        return min(self.position_time_ms, self.attitude_time_ms)


class Autopilot:
    """One autopilot instance: its process and its onboard MAVLink link."""

    def __init__(self, instance: int) -> None:
        self.instance = instance
        self.link = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.link.bind(("127.0.0.1", PEER_PORT + instance))
        self.link.setblocking(False)
        self.peer = ("127.0.0.1", LINK_PORT + instance)
        self.mav = mav.MAVLink(None, srcSystem=COMPANION_SYSTEM, srcComponent=COMPANION_COMPONENT)
        self.mav.robust_parsing = True
        self.estimate = Estimate()
        self.process: subprocess.Popen[bytes] | None = None
        self.failure: str | None = None  # why it is no longer flown (None: it flies)
        self.next_heartbeat_us = 0
        self.local_origin = np.zeros(3)  # its local frame's origin in the simulator's (ENU)

    def start_process(self, command: list[str]) -> None:
        self.stop_process()
        self.read()  # what the old one sent and did not deliver is dropped
        filled = [a.format(port=PORT, instance=self.instance) for a in command]
        self.process = subprocess.Popen(filled, stdin=subprocess.DEVNULL)
        # ended with the link, or at exit if the env was never closed
        self._finalizer = weakref.finalize(self, terminate, self.process, 10.0)
        self.estimate = Estimate()
        self.failure = None
        self.next_heartbeat_us = 0

    def stop_process(self) -> None:
        if self.process is not None:
            self._finalizer()

    def exited(self) -> str | None:
        """Why it is gone, if its process has exited."""
        code = self.process.poll() if self.process is not None else 1
        return None if code is None else f"the autopilot exited with code {code}"

    def close(self) -> None:
        self.stop_process()
        self.link.close()

    # --- the MAVLink link ---------------------------------------------------------
    def send(self, msg: Any) -> None:
        with contextlib.suppress(OSError):
            self.link.sendto(msg.pack(self.mav), self.peer)

    def read(self) -> None:
        """Take what the autopilot sent so far."""
        for msg in pending_messages(self.link, self.mav):
            self._take(msg)

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


class Autopilots:
    """Autopilot instances ``first_instance`` .. ``first_instance + n - 1`` started with
    ``command`` (a list; ``{port}`` and ``{instance}`` in it are filled in), each flying a
    vehicle of ``airframe`` on one batched physics."""

    def __init__(
        self, command: list[str], n: int = 1, first_instance: int = 0, airframe: str = "iris"
    ) -> None:
        self.start_command, self.airframe = command, airframe
        self.notices: list[str] = []
        self.physics = HilPhysics(Fleet(n, airframe), notice=self.notices.append)
        self.fleet = self.physics.fleet
        self.server = Px4TcpServer(self.physics, "127.0.0.1", PORT + first_instance)
        # One round when an autopilot connects, then only those it answers: the rounds
        # before it leads in lockstep are then the same every time (the fake answers the
        # first; a real PX4 that does not is sent another each second).
        self.server.wall_round_s = STARTING_ROUND_S
        self.pilots: list[Autopilot] = []
        try:
            for i in range(n):
                self.pilots.append(Autopilot(first_instance + i))
        except OSError:
            self.close()
            raise
        # How much older than the step's end an estimate may be stamped: the fake sends
        # the state of every round; a real PX4 stamps its estimator's output.
        self.estimate_lag_ms = 0

    @property
    def n(self) -> int:
        return len(self.pilots)

    def time_us(self, row: int) -> int:
        """Vehicle ``row``'s simulated time (its autopilot's clock)."""
        return self.physics.peers[row].time_us

    # --- the processes --------------------------------------------------------------
    def start(self, rows: Sequence[int] | None = None) -> list[int]:
        """Start the autopilots of ``rows`` (all) and serve them until each leads in
        lockstep and its estimate of the vehicle at rest comes; the rows that failed
        (each one's ``failure`` says why)."""
        rows = list(range(self.n)) if rows is None else list(rows)
        before = {row: self.physics.peers[row] for row in rows}  # a connection makes anew
        for row in rows:
            self.server.hold_at_us[row] = 0  # its rounds wait for advance() from the first
            self.pilots[row].start_process(self.start_command)
        deadline = time.monotonic() + BOOT_GUARD_S
        waiting = set(rows)
        while waiting:
            for row in list(waiting):
                pilot, peer = self.pilots[row], self.physics.peers[row]
                if peer is not before[row] and peer.lockstep:
                    waiting.discard(row)  # it leads from now on
                elif pilot.exited() or time.monotonic() > deadline:
                    pilot.failure = pilot.exited() or (
                        f"the autopilot did not start within {BOOT_GUARD_S:g} s"
                    )
                    waiting.discard(row)
            self.server.serve(0.05)
        live = [row for row in rows if self.pilots[row].failure is None]
        self._read_estimates(live, BOOT_GUARD_S)
        for row in live:
            # Where the autopilot's local frame has its origin in the simulator's (ENU,
            # m): PX4 puts it where its estimator started, at ground level (not the centre
            # of mass, which rests at the gear's height). Measured now, at rest.
            pilot = self.pilots[row]
            local = frames.ned_to_enu(np.array(pilot.estimate.position))
            pilot.local_origin = self.fleet.state[row, :3] - local
        return [row for row in rows if self.pilots[row].failure is not None]

    def restart(self, rows: Sequence[int]) -> list[int]:
        """New autopilot processes for ``rows``; the rows that failed to start."""
        for row in rows:
            self.pilots[row].stop_process()
        return self.start(rows)

    def close(self) -> None:
        for pilot in self.pilots:
            pilot.close()
        self.server.close()

    # --- time ---------------------------------------------------------------------
    def advance(self, seconds: float, rows: Sequence[int] | None = None) -> list[int]:
        """Let the autopilots of ``rows`` (all that fly) fly ``seconds`` of simulated time
        (whole rounds of 4 ms) while the others wait, then hold each there and read its
        estimate of that instant. The rows whose autopilot failed meanwhile (marked, and
        no longer waited for: the others fly on)."""
        if rows is None:
            rows = range(self.n)
        rows = [row for row in rows if self.pilots[row].failure is None]
        rounds = round(seconds * 1e6 / ROUND_US)
        target = {row: self.time_us(row) + rounds * ROUND_US for row in rows}
        for row in rows:
            # The round of the last step's end was held back: the autopilot gets it now,
            # after what the env sent since, and the round of this step's end is held.
            self.server.hold_at_us[row] = target[row]
            self.server.release(row)
        flying, failed = set(rows), []
        progress = {row: (self.time_us(row), time.monotonic()) for row in rows}
        while flying:
            for row in list(flying):
                why = self._fault(row, progress)
                if why is not None:
                    self.pilots[row].failure = why
                    flying.discard(row)
                    failed.append(row)
                elif self.time_us(row) >= target[row]:
                    flying.discard(row)
                else:
                    self._heartbeat(row)
            if flying:
                self.server.serve(0.05)
        # The estimate of the round before the step's end: its telemetry came before the
        # motor outputs that ended the step (the round of the end itself is held).
        self._read_estimates([row for row in rows if row not in failed], ESTIMATE_WAIT_S)
        return failed

    def _fault(self, row: int, progress: dict[int, tuple[int, float]]) -> str | None:
        """Why the autopilot of ``row`` cannot fly on, if it cannot."""
        if self.server.connections[row] is None:
            return self.pilots[row].exited() or "the autopilot disconnected from its simulator"
        now, (last_us, since) = time.monotonic(), progress[row]
        if self.time_us(row) != last_us:
            progress[row] = (self.time_us(row), now)
        elif now - since > STALL_S:
            return self.pilots[row].exited() or f"the autopilot stalled for {STALL_S:g} s"
        return None

    def _heartbeat(self, row: int) -> None:
        pilot = self.pilots[row]
        if self.time_us(row) >= pilot.next_heartbeat_us:
            pilot.next_heartbeat_us = self.time_us(row) + int(HEARTBEAT_S * 1e6)
            kind, none = mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID
            pilot.send(pilot.mav.heartbeat_encode(kind, none, 0, 0, 0))

    def _read_estimates(self, rows: Sequence[int], wait_s: float) -> None:
        """Read until each estimate is stamped at its vehicle's last round or later (an
        autopilot sends it from its own thread), waiting at most ``wait_s``."""
        stamp = {r: (self.time_us(r) - ROUND_US) // 1000 - self.estimate_lag_ms for r in rows}
        deadline = time.monotonic() + wait_s
        waiting = list(rows)
        while True:
            for row in waiting:
                self.pilots[row].read()
            waiting = [r for r in waiting if self.pilots[r].estimate.time_ms < stamp[r]]
            if not waiting or time.monotonic() > deadline:
                return
            time.sleep(0.0002)

    # --- commands -----------------------------------------------------------------
    def command(self, rows: Sequence[int], command: int, *params: float) -> dict[int, int]:
        """COMMAND_LONG to the autopilots of ``rows``, each answered within a simulated
        second; each one's result (-1: none came)."""
        values = [*params, *[0.0] * (7 - len(params))]
        for row in rows:
            pilot = self.pilots[row]
            pilot.estimate.acks.pop(command, None)
            pilot.send(pilot.mav.command_long_encode(1, 1, command, 0, *values))
        waiting = list(rows)
        for _ in range(round(1e6 / ROUND_US)):
            waiting = [r for r in waiting if command not in self.pilots[r].estimate.acks]
            if not waiting:
                break
            self.advance(ROUND_US * 1e-6, waiting)
            for row in waiting:
                self.pilots[row].read()
        return {row: self.pilots[row].estimate.acks.get(command, -1) for row in rows}


def fake_px4_command(airframe: str = "iris") -> list[str]:
    """The in-repository fake (:mod:`quadsitl.fake_stacks.offboard_px4`) as a process."""
    module = "quadsitl.fake_stacks.offboard_px4"
    return [sys.executable, "-m", module, "-i", "{instance}", "--port", "{port}",
            "--airframe", airframe]  # fmt: skip
