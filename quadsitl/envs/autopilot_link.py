"""Autopilots flown from outside, in lockstep: their simulator, their processes and their
MAVLink links, owned by the env that trains through them.

The env is the autopilots' simulator (:mod:`.lockstep_sides`: PX4's simulator_mavlink,
ArduPilot's JSON interface, around one batched physics), so it holds each autopilot's
clock: in lockstep the autopilot waits for the simulator, and moves on only while
:meth:`Autopilots.advance` serves it. Between env steps the autopilots are paused,
however long the learner takes; every timeout of an autopilot (offboard loss, the
setpoint stream's rate, heartbeats) runs on simulated time. The env talks to each
autopilot as a companion computer does, over a MAVLink link of its own (UDP: PX4's
onboard link, 14540 + i and 14580 + i; ArduPilot's SERIAL0 as a UDP client of port
5760 + 10 i), and reads the autopilot's own estimate there.

An autopilot that exits, disconnects or stops answering is marked failed and no longer
waited for: the others fly on (:meth:`Autopilots.advance` returns who failed), and
:meth:`Autopilots.start` starts it again.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import subprocess
import tempfile
import time
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.bridges.ardupilot_json import PORT as JSON_PORT
from quadsitl.bridges.ardupilot_json import PORT_STRIDE
from quadsitl.bridges.px4_hil import LINK_PORT, PEER_PORT, PORT
from quadsitl.envs.autopilot_commands import AutopilotCommand
from quadsitl.envs.lockstep_sides import SIDES
from quadsitl.envs.sim_process import terminate
from quadsitl.physics.fleet import Fleet
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.udp_messages import pending_messages

BOOT_GUARD_S = 120.0  # wall s an autopilot may take to start and lead in lockstep
ESTIMATE_LIMIT_S = 60.0  # simulated s a new autopilot may take to report an estimate
ESTIMATE_STEP_S = 0.1  # simulated s between looks for it
STALL_S = 10.0  # wall s without a round, once in lockstep, before it is called stalled
ESTIMATE_WAIT_S = 1.0  # wall s to wait for the estimate of a step's end (then the last one)
HEARTBEAT_S = 1.0  # simulated s between the companion's heartbeats
COMMAND_SENDS = 3  # sends of a command left unanswered for a simulated second each
GCS_PORT = 14550  # where every PX4 instance sends its ground-station link
ARDUPILOT_LINK_PORT = 5760  # UDP port of ArduPilot instance i's SERIAL0: + 10 i (its TCP's)
COMPANION_SYSTEM, COMPANION_COMPONENT = 255, mav.MAV_COMP_ID_ONBOARD_COMPUTER
# Decoded by the fast codec: what comes every round (the rest is rare, and pymavlink's)
ESTIMATE_MESSAGES = frozenset(
    {mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION}
)


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
    autopilot: int = mav.MAV_AUTOPILOT_INVALID  # its HEARTBEAT's: PX4, ArduPilot, ...
    landed_state: int = mav.MAV_LANDED_STATE_UNDEFINED  # EXTENDED_SYS_STATE's
    outputs_us: tuple[int, ...] = ()  # SERVO_OUTPUT_RAW's channels 1..8 (µs)

    @property
    def armed(self) -> bool:
        return bool(self.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)

    def take(self, msg: Any) -> None:
        """Keep what ``msg`` (from the autopilot) says of its state."""
        kind = msg.get_type()
        if kind == "LOCAL_POSITION_NED":
            self.position_time_ms = msg.time_boot_ms
            self.position, self.velocity = (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz)
        elif kind == "ATTITUDE_QUATERNION":
            self.attitude_time_ms = msg.time_boot_ms
            self.quaternion = (msg.q1, msg.q2, msg.q3, msg.q4)
            self.rates = (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
        elif kind == "HEARTBEAT" and msg.autopilot != mav.MAV_AUTOPILOT_INVALID:
            self.base_mode, self.custom_mode = msg.base_mode, msg.custom_mode
            self.autopilot = msg.autopilot
        elif kind == "COMMAND_ACK":
            self.acks[msg.command] = msg.result
        elif kind == "STATUSTEXT":
            self.texts.append(msg.text)
        elif kind == "EXTENDED_SYS_STATE":
            self.landed_state = msg.landed_state
        elif kind == "SERVO_OUTPUT_RAW" and msg.port == 0:
            self.outputs_us = tuple(getattr(msg, f"servo{i}_raw") for i in range(1, 9))

    @property
    def time_ms(self) -> int:
        """The clock of its oldest part (position or attitude)."""
        return min(self.position_time_ms, self.attitude_time_ms)


class Autopilot:
    """One autopilot instance of ``stack``: its process and its MAVLink link."""

    def __init__(self, instance: int, stack: str = "px4") -> None:
        if stack == "ardupilot":
            # ArduPilot's -I i: JSON on 9002 + 10 i; SERIAL0 sends to the env's port
            if not 0 <= instance < (65535 - JSON_PORT) // PORT_STRIDE:
                raise ValueError(f"ArduPilot instance {instance} is not 0 .. 6000")
            port, peer, system_id = ARDUPILOT_LINK_PORT + PORT_STRIDE * instance, None, 1
        else:
            if not 0 <= instance < 255 or PEER_PORT + instance == GCS_PORT:
                raise ValueError(
                    f"PX4 instance {instance} cannot be flown from here: instances are 0 .. 254 "
                    f"(system id i + 1), and instance {GCS_PORT - PEER_PORT}'s onboard port is "
                    f"{GCS_PORT}, where every PX4 sends to its ground station"
                )
            port, peer = PEER_PORT + instance, ("127.0.0.1", LINK_PORT + instance)
            system_id = instance + 1  # PX4's MAV_SYS_ID (px4-rc.mavlink), and the fake's
        self.instance, self.stack = instance, stack
        self.link_port = port
        self.link = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.link.bind(("127.0.0.1", port))
        self.link.setblocking(False)
        # where its link listens: PX4's is known; ArduPilot's (a UDP client) is where it
        # sends from, learned from its first datagram
        self.known_peer: tuple[str, int] | None = peer
        self.peer = peer
        self.mav = mav.MAVLink(None, srcSystem=COMPANION_SYSTEM, srcComponent=COMPANION_COMPONENT)
        self.mav.robust_parsing = True
        self.estimate = Estimate()
        self.process: subprocess.Popen[bytes] | None = None
        self.folder: str | None = None
        self.failure: str | None = None  # why it is no longer flown (None: it flies)
        self.flown = False  # has flown since its process started (it is not fresh)
        self.system_id = system_id  # ArduPilot's SYSID_THISMAV: 1 (a link of its own)
        self.next_heartbeat_us = 0
        self.local_origin = np.zeros(3)  # its local frame's origin in the simulator's (ENU)

    def start_process(self, command: AutopilotCommand) -> None:
        self.stop_process()
        self.read()  # what the old one sent and did not deliver is dropped
        self.peer = self.known_peer
        sim_port = JSON_PORT if self.stack == "ardupilot" else PORT
        filled = [
            a.format(port=sim_port, instance=self.instance, link=self.link_port)
            for a in command.argv
        ]
        folder, output = None, None
        if command.own_folder:
            folder = tempfile.mkdtemp(prefix=f"quadsitl-autopilot{self.instance}-")
            for name, text in command.files.items():
                (Path(folder) / name).write_text(text)
            output = open(Path(folder) / "autopilot.log", "wb")  # noqa: SIM115
        try:
            self.process = subprocess.Popen(
                filled, stdin=subprocess.DEVNULL, stdout=output, stderr=output, cwd=folder,
                env={**os.environ, **command.environment},
            )  # fmt: skip
        finally:
            if output is not None:
                output.close()  # the process holds its own
        # ended with the link, or at exit if the env was never closed; its folder goes
        self._finalizer = weakref.finalize(self, _end, self.process, folder)
        self.folder = folder
        self.estimate = Estimate()
        self.failure = None
        self.flown = False
        self.next_heartbeat_us = 0

    def stop_process(self) -> None:
        if self.process is not None:
            self._finalizer()

    def exited(self) -> str | None:
        """Why it is gone, if its process has exited."""
        code = self.process.poll() if self.process is not None else 1
        if code is None:
            return None
        return f"the autopilot exited with code {code}{self._last_words()}"

    def _last_words(self) -> str:
        """The end of its output, where it was kept (its folder goes with it)."""
        if self.folder is None:
            return ""
        with contextlib.suppress(OSError):
            text = (Path(self.folder) / "autopilot.log").read_text(errors="replace")
            lines = [line for line in text.splitlines() if line.strip()][-3:]
            return "; its last words: " + " | ".join(lines) if lines else ""
        return ""

    def close(self) -> None:
        self.stop_process()
        self.link.close()

    # --- the MAVLink link ---------------------------------------------------------
    def send(self, msg: Any) -> None:
        if self.peer is None:
            return  # it has not spoken yet: nothing listens for us
        with contextlib.suppress(OSError):
            self.link.sendto(msg.pack(self.mav), self.peer)

    def read(self) -> None:
        """Take what the autopilot sent so far."""
        if self.peer is None:
            with contextlib.suppress(OSError):
                self.peer = self.link.recvfrom(1, socket.MSG_PEEK)[1]
        for msg in pending_messages(self.link, self.mav, ESTIMATE_MESSAGES):
            self._take(msg)

    def _take(self, msg: Any) -> None:
        if msg.get_srcSystem() != self.system_id:
            return  # another vehicle's (a port shared by mistake must not mix them)
        self.estimate.take(msg)


class Autopilots:
    """Autopilot instances ``first_instance`` .. ``first_instance + n - 1`` of ``stack``
    (``px4`` or ``ardupilot``) started with ``command``, each flying a vehicle of
    ``airframe`` on one batched physics (PX4's sensed with the sensor models' noise scaled
    by ``sensor_noise``, 0: the truth)."""

    def __init__(
        self, command: AutopilotCommand, n: int = 1, first_instance: int = 0,
        airframe: str = "iris", sensor_noise: float = 1.0, stack: str = "px4",
    ) -> None:  # fmt: skip
        self.start_command, self.airframe, self.stack = command, airframe, stack
        self.notices: list[str] = []
        self.side = SIDES[stack](Fleet(n, airframe), first_instance, sensor_noise,
                                 self.notices.append)  # fmt: skip
        self.fleet = self.side.fleet
        self.pilots: list[Autopilot] = []
        try:
            for i in range(n):
                self.pilots.append(Autopilot(first_instance + i, stack))
        except (OSError, ValueError):
            self.close()
            raise
        self.estimate_lag_ms = command.estimate_lag_ms

    @property
    def n(self) -> int:
        return len(self.pilots)

    def time_us(self, row: int) -> int:
        """Vehicle ``row``'s simulated time (its autopilot's clock)."""
        return self.side.time_us(row)

    # --- the processes --------------------------------------------------------------
    def start(self, rows: Sequence[int] | None = None) -> list[int]:
        """Start the autopilots of ``rows`` (all; a running one is stopped first: a
        restart) and serve them until each leads in lockstep and its estimate of the
        vehicle at rest comes; the rows that failed (each one's ``failure`` says why)."""
        rows = list(range(self.n)) if rows is None else list(rows)
        before = {}
        for row in rows:
            self.pilots[row].stop_process()
            before[row] = self.side.begin(row)  # held from its first round or frame
            self.pilots[row].start_process(self.start_command)
        deadline = time.monotonic() + BOOT_GUARD_S
        waiting = set(rows)
        while waiting:
            for row in list(waiting):
                pilot = self.pilots[row]
                if self.side.leading(row, before[row]):
                    waiting.discard(row)  # it leads from now on
                elif pilot.exited() or time.monotonic() > deadline:
                    pilot.failure = pilot.exited() or (
                        f"the autopilot did not start within {BOOT_GUARD_S:g} s"
                    )
                    waiting.discard(row)
            self.side.serve(0.05)
        live = [row for row in rows if self.pilots[row].failure is None]
        self._await(live, lambda e: e.autopilot != mav.MAV_AUTOPILOT_INVALID, "no heartbeat")
        live = [row for row in live if self.pilots[row].failure is None]
        answers: dict[int, list[int]] = {row: [] for row in live}
        for message, interval in self.start_command.streams_us.items():
            # once its MAVLink is up (it sent a heartbeat): each stream at its rate
            results = self.command(live, mav.MAV_CMD_SET_MESSAGE_INTERVAL, message, interval)
            for row, result in results.items():
                answers[row].append(result)
        self._await(live, lambda e: e.time_ms >= 0, "no estimate")
        for row in live:
            pilot = self.pilots[row]
            unanswered = any(result != mav.MAV_RESULT_ACCEPTED for result in answers[row])
            if pilot.failure is not None and unanswered:
                pilot.failure += f" (its stream requests were answered {answers[row]}; -1: none)"
        for row in live:
            if self.pilots[row].failure is None:
                self.measure_origin(row)
                self.pilots[row].flown = False  # what it flew to start is not an episode
        return [row for row in rows if self.pilots[row].failure is not None]

    def _await(self, rows: list[int], came: Any, what: str) -> None:
        """Let the autopilots of ``rows`` run, their vehicles at rest, until what each
        reported ``came`` (a real autopilot sends an estimate once its estimator has
        started), at most ESTIMATE_LIMIT_S of its clock; the late ones are marked failed
        (``what`` came)."""
        limit = ESTIMATE_LIMIT_S * 1e6
        waiting = [r for r in rows if not came(self.pilots[r].estimate)]
        while waiting:
            for row in self.advance(ESTIMATE_STEP_S, waiting):
                waiting.remove(row)  # failed: said in its failure
            for row in waiting:
                if self.time_us(row) > limit:
                    self.pilots[
                        row
                    ].failure = f"the autopilot sent {what} in {ESTIMATE_LIMIT_S:g} simulated s"
            waiting = [
                r for r in waiting
                if self.pilots[r].failure is None and not came(self.pilots[r].estimate)
            ]  # fmt: skip

    def estimated_position(self, row: int) -> np.ndarray:
        """Where the autopilot of ``row`` estimates its vehicle is, in the simulator's
        frame (ENU, m)."""
        pilot = self.pilots[row]
        return frames.ned_to_enu(np.array(pilot.estimate.position)) + pilot.local_origin

    def measure_origin(self, row: int) -> None:
        """Where the autopilot's local frame has its origin in the simulator's (ENU, m),
        measured with the vehicle at rest: PX4 puts it where its estimator started, at
        ground level (not the centre of mass, which rests at the gear's height)."""
        pilot = self.pilots[row]
        local = frames.ned_to_enu(np.array(pilot.estimate.position))
        pilot.local_origin = self.fleet.state[row, :3] - local

    def close(self) -> None:
        for pilot in self.pilots:
            pilot.close()
        self.side.close()

    # --- time ---------------------------------------------------------------------
    def advance(self, seconds: float, rows: Sequence[int] | None = None) -> list[int]:
        """Let the autopilots of ``rows`` (all that fly) fly ``seconds`` of simulated time
        (whole rounds of 4 ms) while the others wait, then hold each there and read its
        estimate of that instant. The rows whose autopilot failed meanwhile (marked, and
        no longer waited for: the others fly on)."""
        if rows is None:
            rows = range(self.n)
        rows = [row for row in rows if self.pilots[row].failure is None]
        frame_us = self.side.frame_us
        span = max(1, round(seconds * 1e6 / frame_us)) * frame_us
        target = {row: self.time_us(row) + span for row in rows}
        for row in rows:
            self.pilots[row].flown = True
            # The round of the last step's end was held back: the autopilot gets it now,
            # after what the env sent since, and the round of this step's end is held.
            self.side.hold(row, target[row])
        flying, failed = set(rows), []
        progress = {row: (self.time_us(row), time.monotonic()) for row in rows}
        while flying:
            for row in list(flying):
                why = self._fault(row, progress)
                if why is not None:
                    self.pilots[row].failure = why
                    flying.discard(row)
                    failed.append(row)
                elif self.side.reached(row, target[row]):
                    flying.discard(row)
                else:
                    self._heartbeat(row)
                    self.pilots[row].read()  # a long advance would overflow its socket
            if flying:
                self.side.serve(0.05)
        # The estimate of the round before the step's end: its telemetry came before the
        # motor outputs that ended the step (the round of the end itself is held).
        self._read_estimates([row for row in rows if row not in failed], ESTIMATE_WAIT_S)
        return failed

    def _fault(self, row: int, progress: dict[int, tuple[int, float]]) -> str | None:
        """Why the autopilot of ``row`` cannot fly on, if it cannot."""
        if not self.side.connected(row):
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
        """Read until each estimate is stamped at the last round its autopilot answered
        or later (it sends its telemetry before its motor outputs, maybe from another
        thread), waiting at most ``wait_s``."""
        stamp = {r: self.side.answered_us(r) // 1000 - self.estimate_lag_ms for r in rows}
        deadline = time.monotonic() + wait_s
        waiting = list(rows)
        while True:
            for row in waiting:
                self.pilots[row].read()
            # (one that has sent none yet is not waited for: its estimator is starting)
            waiting = [
                r for r in waiting
                if not self.side.sent_all(r) and 0 <= self.pilots[r].estimate.time_ms < stamp[r]
            ]  # fmt: skip
            if not waiting or time.monotonic() > deadline:
                return
            time.sleep(0.0002)

    # --- commands -----------------------------------------------------------------
    def command(self, rows: Sequence[int], command: int, *params: float) -> dict[int, int]:
        """COMMAND_LONG to the autopilots of ``rows``, sent again (its confirmation counted
        up) to each that has not answered within a simulated second, COMMAND_SENDS times
        in all, as MAVLink's command protocol has a sender do: a datagram may be lost.
        Each one's result (-1: none came)."""
        values = [*params, *[0.0] * (7 - len(params))]
        for row in rows:
            self.pilots[row].estimate.acks.pop(command, None)
        waiting = list(rows)
        for confirmation in range(COMMAND_SENDS):
            for row in waiting:
                pilot = self.pilots[row]
                pilot.send(
                    pilot.mav.command_long_encode(
                        pilot.system_id, 1, command, confirmation, *values
                    )
                )
            for _ in range(round(1e6 / self.side.frame_us)):
                waiting = [
                    r for r in waiting
                    if command not in self.pilots[r].estimate.acks
                    and self.pilots[r].failure is None
                ]  # fmt: skip
                if not waiting:
                    break
                self.advance(self.side.frame_us * 1e-6, waiting)  # (which reads the answers)
            if not waiting:
                break
        return {row: self.pilots[row].estimate.acks.get(command, -1) for row in rows}


def _end(process: subprocess.Popen[bytes], folder: str | None) -> None:
    terminate(process, 10.0)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
