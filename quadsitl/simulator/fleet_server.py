"""The MAVLink face of a group of vehicles: one server per vehicle on shared links, and
the motor path of them all.

Every link carries every vehicle: each sends its own heartbeat and telemetry with its own
system id (``--sysid`` … ``--sysid + N − 1``), and a message reaches the vehicle its
``target_system`` names (0: all of them). A message for a system id this process does
not host is counted and refused once in a while with a STATUSTEXT; it never holds up the
others.

Motor commands (SET_ACTUATOR_CONTROL_TARGET to a vehicle; HIL_ACTUATOR_CONTROLS, only
where there is one vehicle) are routed to the one motor path of the group
(:mod:`.motor_path`), which holds each round until it is complete, flies it and says
whom to answer; this module only routes them, owns the links (and who may command on
the motor link: :mod:`.ownership`) and sends the answers, in as few datagrams as fit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

from quadsitl.flight_software.group import VehicleGroup
from quadsitl.flight_software.results import Severity
from quadsitl.simulator import telemetry as T
from quadsitl.simulator.links import Link, Peer
from quadsitl.simulator.motor_path import MotorPath, Reply
from quadsitl.simulator.ownership import Ownership, may_take
from quadsitl.simulator.server import MOTOR_LINK, MavlinkServer
from quadsitl.simulator.tlog import TlogWriter
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.answer import field_slices
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import RELEASE_LOCKSTEP

ROUND = mav.MAVLINK_MSG_ID_SET_ACTUATOR_CONTROL_TARGET
HIL = mav.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS
FAST_IDS = frozenset({ROUND, HIL})  # motor commands, parsed without pymavlink (unsigned)
_ROUND = field_slices(mav.MAVLink_set_actuator_control_target_message)
_HIL = field_slices(mav.MAVLink_hil_actuator_controls_message)
TICK_PERIOD = 0.005  # wall s between two ticks of one vehicle (events, telemetry)
LOCKSTEP_TICK_PERIOD = 0.02  # the same in lockstep (telemetry capped on the wall clock)


class FleetServer:
    """Routes each link's messages to the vehicles' servers and to their motor path."""

    def __init__(
        self, group: VehicleGroup, servers: list[MavlinkServer], tlog: TlogWriter | None
    ) -> None:
        self.group, self.servers, self.tlog = group, servers, tlog
        self.by_system = {server.system_id: i for i, server in enumerate(servers)}
        lockstep = any(server.lockstep for server in servers)
        self.motors = MotorPath(group.batch, [server.motors for server in servers], lockstep)
        self.counters = {"unknown_system": 0}
        self._next_tick = 0  # the vehicle ticked next
        self._last_tick: float | None = None  # wall time of the last tick
        self._credit = 0.0  # vehicles owed a tick
        for i, server in enumerate(servers):
            for schedule in server.schedules.values():  # the vehicles' telemetry takes turns
                schedule.offset = i / len(servers) * T.FASTEST_INTERVAL
        self.ownership = Ownership()  # of the motor link: one client at a time
        # The messages routed here; the rest go to the vehicle they name (_dispatch).
        self.handlers: dict[int, Callable[[Any, Link, Peer], None]] = {
            ROUND: self._on_set_actuator_control_target,
            HIL: self._on_hil_actuator_controls,
        }

    # --- the loop's hooks -------------------------------------------------------------
    def receive(self, link: Link, received_at: float | None = None) -> None:
        """Dispatch what arrived on ``link`` in order; a round flies once it is complete.
        The answers go back in the order of what they answer (a client matches a reset's
        answer by what precedes it), together in one datagram or a few."""
        link.hold()
        try:
            self._receive(link, received_at)
        finally:
            link.release()

    def _receive(self, link: Link, received_at: float | None) -> None:
        signing = any(server.signing is not None for server in self.servers)
        fast = FAST_IDS if link.name == MOTOR_LINK and not signing else frozenset()
        for message, peer in link.receive(fast):
            if link.name == MOTOR_LINK and not self._admit(message, peer.address, link):
                continue
            if isinstance(message, FC.Frame):  # an unsigned motor command, parsed fast
                link.accept(peer)  # (only when signing is off)
                self._on_frame(message, link)
                continue
            if self.tlog is not None and link.name != MOTOR_LINK:
                self.tlog.record(bytes(message.get_msgbuf()), received_at)
            new_peer = peer.heard is None
            handler = self.handlers.get(message.get_msgId(), self._dispatch)
            handler(message, link, peer)
            if new_peer and peer.heard is not None:  # accepted just now: it hears us now
                for server in self.servers:
                    server.greet()

    def tick(self, wall_now: float, deadline: float = math.inf) -> None:
        """Every vehicle's events, heartbeat and telemetry, the vehicles in turn: each
        is ticked about every TICK_PERIOD of wall time (LOCKSTEP_TICK_PERIOD in
        lockstep, where telemetry is rate-limited on the wall clock anyway), at least
        one vehicle per call, so that a large fleet's work is spread evenly over the
        physics steps. No further vehicle is ticked once the monotonic clock reaches
        ``deadline`` (the next physics step's): those left over are ticked first next
        call, so that telemetry waits rather than the physics. What the vehicles ticked
        in one call send goes out together, in datagrams of at most TELEMETRY_DATAGRAM
        bytes per link (as PX4 packs them)."""
        n = len(self.servers)
        lockstep = self.motors.in_lockstep(wall_now)
        period = LOCKSTEP_TICK_PERIOD if lockstep else TICK_PERIOD
        last = wall_now if self._last_tick is None else self._last_tick
        elapsed = min(max(wall_now - last, 0.0), period)
        self._last_tick = wall_now
        self._credit = min(float(n), self._credit + n * elapsed / period)
        count = min(n, max(1, int(self._credit)))
        links = self.servers[0].links
        for link in links:
            link.hold(FC.TELEMETRY_DATAGRAM)
        ticked = 0
        try:
            while ticked < count and (ticked == 0 or time.monotonic() < deadline):
                self.servers[self._next_tick].tick(wall_now, lockstep)
                self._next_tick = (self._next_tick + 1) % n
                ticked += 1
        finally:
            self._credit = max(0.0, self._credit - ticked)
            for link in links:
                link.release()

    def slow_telemetry(self, factor: float) -> None:
        """Every vehicle's telemetry streams ``factor`` times less often on every link
        (1: their full rates), as :mod:`.degrade` decides under load."""
        for server in self.servers:
            for schedule in server.schedules.values():
                schedule.slow_down(factor)

    def statustext(self, severity: int, text: str) -> None:
        """From every vehicle (e.g. the log stopped: it concerns them all), printed on
        the console once."""
        for index, server in enumerate(self.servers):
            server.statustext(severity, text, echo=index == 0)

    # --- ownership of the motor link (ownership.py) ------------------------------------
    def _admit(self, message: Any, address: Any, link: Link) -> bool:
        """Whether a message on the motor link comes from its owner (or takes a free
        link); a stranger is told who owns it, and hears nothing else there."""
        now = time.monotonic()
        fast = isinstance(message, FC.Frame)
        if address == self.ownership.owner and (fast or message.get_type() != "COMMAND_LONG"):
            self.ownership.heard = now  # the owner's command or answer: the hot path
            return True
        check = self.servers[0].signing
        if fast:  # an unsigned motor command
            kind, takes = mav.mavlink_map[message.msgid].msgname, check is None
        else:
            kind, takes = message.get_type(), may_take(check, message)
        if kind == "COMMAND_LONG" and message.command == RELEASE_LOCKSTEP:
            if takes:
                self.ownership.release(address)
            link.only = self.ownership.owner
            return False
        admitted = self.ownership.admit(address, kind, now, takes)
        link.only = self.ownership.owner
        if not admitted:
            text = self.ownership.tell(address, now)
            if text is not None:
                server = self.servers[0]
                notice = server.encoder.statustext_encode(Severity.WARNING, text.encode(), 0, 0)
                link.send_to(link.pack(notice, server.system_id), address)
        return admitted

    # --- routing ----------------------------------------------------------------------
    def _dispatch(self, message: Any, link: Link, peer: Peer) -> None:
        target = getattr(message, "target_system", 0)
        if target == 0:
            for server in self.servers:
                server.dispatch(message, link, peer)
            return
        index = self._index(target)
        if index is not None:
            self.servers[index].dispatch(message, link, peer)

    def _index(self, system_id: int) -> int | None:
        """The vehicle of ``system_id``; None (counted, said now and then) if none."""
        index = self.by_system.get(system_id)
        if index is None:
            self.counters["unknown_system"] += 1
            if self.counters["unknown_system"] % 100 == 1:
                first, last = min(self.by_system), max(self.by_system)
                self.servers[0].statustext(
                    Severity.WARNING,
                    f"refused: no system {system_id} here ({first}..{last})",
                )
        return index

    # --- motor commands (motor_path.py) ------------------------------------------------
    def _on_frame(self, frame: FC.Frame, link: Link) -> None:
        """An unsigned motor command parsed fast, the lockstep clients' hot path."""
        values = frame.unpack()
        if frame.msgid == ROUND:
            index = self._index(values[_ROUND["target_system"].start])
            if index is not None:
                stamp, controls = values[_ROUND["time_usec"].start], values[_ROUND["controls"]]
                self._answer(link, self.motors.round_command(index, stamp, controls), False)
        elif self._lone():
            sender = (frame.sysid, frame.compid, frame.data[4])  # data[4]: its sequence
            time_usec, flags = values[_HIL["time_usec"].start], values[_HIL["flags"].start]
            controls, mode = values[_HIL["controls"]], values[_HIL["mode"].start]
            reply = self.motors.hil_command(sender, time_usec, flags, controls, mode)
            self._answer_hil(link, reply)

    def _on_set_actuator_control_target(self, message: Any, link: Link, peer: Peer) -> None:
        """A round command through pymavlink (signed, or not on the motor link)."""
        index = self._index(message.target_system)
        if index is not None and self.servers[index].admit(message, link, peer):
            reply = self.motors.round_command(index, message.time_usec, message.controls)
            self._answer(link, reply, False)

    def _on_hil_actuator_controls(self, message: Any, link: Link, peer: Peer) -> None:
        """The lone vehicle's motor command through pymavlink: a round of one."""
        if self._lone() and self.servers[0].admit(message, link, peer):
            sender = (message.get_srcSystem(), message.get_srcComponent(), message.get_seq())
            fields = (message.time_usec, message.flags, message.controls, message.mode)
            self._answer_hil(link, self.motors.hil_command(sender, *fields))

    def _lone(self) -> bool:
        """Whether HIL_ACTUATOR_CONTROLS (which names no vehicle) can be flown: refused
        where several vehicles share the links."""
        if len(self.servers) == 1:
            return True
        problem = self.servers[0].motors.reject(
            "unaddressed",
            f"HIL_ACTUATOR_CONTROLS refused: {len(self.servers)} vehicles here; address "
            "each with SET_ACTUATOR_CONTROL_TARGET",
        )
        if problem is not None:
            self.servers[0].statustext(Severity.WARNING, problem)
        return False

    def _answer_hil(self, link: Link, reply: Reply) -> None:
        """A HIL_ACTUATOR_CONTROLS' answer: full, with HIL_STATE_QUATERNION unless the
        link's client turned it off."""
        self._answer(link, reply, True, [self.servers[0].hil_state(link)])

    def _answer(self, link: Link, reply: Reply, full: bool, hil_state: Sequence[bool] = ()) -> None:
        """Say the reply's warnings, then send its answers, each vehicle's frames joined
        (a datagram never splits one); logged as every frame is, but on the motor link."""
        for index, text in reply.warnings:
            self.servers[index].statustext(Severity.WARNING, text)
        if not reply.rows:
            return
        for frames in self.motors.answer(link, reply.rows, full, hil_state):
            link.send_bytes(b"".join(frames))
            if self.tlog is not None and link.name != MOTOR_LINK:
                for frame in frames:
                    self.tlog.record(frame)
