"""The MAVLink face of a group of vehicles: one server per vehicle on shared links, and
lockstep rounds that step them all at once.

Every link carries every vehicle: each sends its own heartbeat and telemetry with its own
system id (``--sysid`` … ``--sysid + N − 1``), and a message reaches the vehicle its
``target_system`` names (0: all of them). A message for a system id this process does
not host is counted and refused once in a while with a STATUSTEXT; it never holds up the
others.

Lockstep rounds (docs/mavlink.md, "A fleet in lockstep"): SET_ACTUATOR_CONTROL_TARGET
addressed to each vehicle, stamped with the simulated time the round starts at. When
every vehicle has its command for the round, the group advances one control period in
one call of the physics and every vehicle's answer goes back together, in as few
datagrams as fit. A repeat of the last round's command (the client lost the answer) is
answered from the cache, without stepping again; a command stamped with any other time
is refused, and answered with the vehicle's current state so the client can see where
the simulator is.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from quadsitl.mavlink import mavlink as mav
from quadsitl.mavlink import telemetry as T
from quadsitl.mavlink.links import Link, Peer
from quadsitl.mavlink.motor_path import LOCKSTEP_IDLE, fly
from quadsitl.mavlink.ownership import Ownership, may_take
from quadsitl.mavlink.server import MOTOR_LINK, MavlinkServer
from quadsitl.mavlink.signing import is_signed
from quadsitl.mavlink.tlog import TlogWriter
from quadsitl.physics.layout import P_GEAR_HEIGHT
from quadsitl.vehicle.group import VehicleGroup
from quadsitl.vehicle.results import Severity
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.answer import answer_parts, field_slices
from quadsitl.wire.lockstep import RELEASE_LOCKSTEP, check_controls
from quadsitl.wire.state import ROW_BY_ROW, WireState
from quadsitl.wire.units import to_time_usec

FAST_IDS = frozenset({mav.MAVLINK_MSG_ID_SET_ACTUATOR_CONTROL_TARGET})
_ROUND = field_slices(mav.MAVLink_set_actuator_control_target_message)  # a round command's
WIRE_FIELDS = ("position_ned", "q_ned_frd", "velocity_frd", "rates_frd", "rotor_speeds")
TICK_PERIOD = 0.005  # wall s between two ticks of one vehicle (events, telemetry)
LOCKSTEP_TICK_PERIOD = 0.02  # the same in lockstep (telemetry capped on the wall clock)


class FleetServer:
    """Routes each link's messages to the vehicles' servers; runs lockstep rounds."""

    def __init__(
        self, group: VehicleGroup, servers: list[MavlinkServer], tlog: TlogWriter | None
    ) -> None:
        self.group, self.servers, self.tlog = group, servers, tlog
        self.by_system = {server.system_id: i for i, server in enumerate(servers)}
        self.pending: dict[int, list[float]] = {}  # vehicle index: controls of this round
        self.previous_round: int | None = None  # µs, start of the last round stepped
        self.cached: list[list[bytes]] = [[] for _ in servers]  # its answers
        self.counters = {"unknown_system": 0, "duplicates": 0, "rounds": 0}
        self._next_tick = 0  # the vehicle ticked next
        self._last_tick: float | None = None  # wall time of the last tick
        self._credit = 0.0  # vehicles owed a tick
        for i, server in enumerate(servers):
            for schedule in server.schedules.values():  # the vehicles' telemetry takes turns
                schedule.offset = i / len(servers) * T.FASTEST_INTERVAL
        self._round_wall = -math.inf  # wall time of the last round command
        self.ownership = Ownership()  # of the motor link: one client at a time
        # The messages routed here; the rest go to the vehicle they name (_dispatch).
        self.handlers: dict[int, Callable[[Any, Link, Peer], None]] = {
            mav.MAVLINK_MSG_ID_SET_ACTUATOR_CONTROL_TARGET: self._on_set_actuator_control_target,
            mav.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS: self._on_hil_actuator_controls,
        }

    # --- the loop's hooks -------------------------------------------------------------
    def receive(self, link: Link, received_at: float | None = None) -> None:
        """Dispatch what arrived on ``link`` in order; step a round once it is complete.
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
            if isinstance(message, FC.Frame):  # an unsigned round command, parsed fast
                link.accept(peer)  # (only when signing is off)
                values = message.unpack()
                target = values[_ROUND["target_system"].start]
                stamp = values[_ROUND["time_usec"].start]
                self._round_command(target, stamp, values[_ROUND["controls"]][:4], link)
                continue
            if self.tlog is not None and link.name != MOTOR_LINK:
                self.tlog.record(bytes(message.get_msgbuf()), received_at)
            new_peer = peer.heard is None
            handler = self.handlers.get(message.get_msgId(), self._dispatch)
            handler(message, link, peer)
            if new_peer and peer.heard is not None:  # accepted just now: it hears us now
                for server in self.servers:
                    server.greet()

    def _on_set_actuator_control_target(self, message: Any, link: Link, peer: Peer) -> None:
        """A round command through pymavlink (signed, or not on the motor link)."""
        controls = message.controls[:4]
        self._round_command(message.target_system, message.time_usec, controls, link, message, peer)

    def _on_hil_actuator_controls(self, message: Any, link: Link, peer: Peer) -> None:
        """One vehicle's motor command: its server flies it as a round of one
        (:func:`~quadsitl.mavlink.motor_path.fly`); refused where several vehicles share
        the links (it names none of them)."""
        if len(self.servers) > 1:
            self._refuse_unaddressed()
        else:
            self._dispatch(message, link, peer)

    def tick(self, wall_now: float) -> None:
        """Every vehicle's events, heartbeat and telemetry, the vehicles in turn: each
        is ticked about every TICK_PERIOD of wall time (LOCKSTEP_TICK_PERIOD in
        lockstep, where telemetry is rate-limited on the wall clock anyway), at least
        one vehicle per call, so that a large fleet's work is spread evenly over the
        physics steps. What the vehicles ticked in one call send goes out together, in
        datagrams of at most TELEMETRY_DATAGRAM bytes per link (as PX4 packs them)."""
        n = len(self.servers)
        period = LOCKSTEP_TICK_PERIOD if self.in_lockstep(wall_now) else TICK_PERIOD
        last = wall_now if self._last_tick is None else self._last_tick
        elapsed = min(max(wall_now - last, 0.0), period)
        self._last_tick = wall_now
        self._credit += n * elapsed / period
        count = min(n, max(1, int(self._credit)))
        self._credit = max(0.0, self._credit - count)
        links = self.servers[0].links
        for link in links:
            link.hold(FC.TELEMETRY_DATAGRAM)
        try:
            for _ in range(count):
                self.servers[self._next_tick].tick(wall_now)
                self._next_tick = (self._next_tick + 1) % n
        finally:
            for link in links:
                link.release()

    def in_lockstep(self, wall_now: float) -> bool:
        """Whether simulated time moves only with motor commands: always with
        ``--lockstep``, else until LOCKSTEP_IDLE wall seconds after the last one."""
        motors = self.servers[0].motors
        return motors.always_lockstep or wall_now - self.last_lockstep_wall < LOCKSTEP_IDLE

    @property
    def last_lockstep_wall(self) -> float:
        """Wall time of the last lockstep command (a round, or one vehicle's HIL)."""
        single = self.servers[0].motors.last_lockstep_wall if len(self.servers) == 1 else -1.0
        return max(self._round_wall, single)

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
            self.ownership.heard = now  # the owner's round or answer: the hot path
            return True
        check = self.servers[0].signing
        if fast:  # an unsigned round command
            kind, takes = "SET_ACTUATOR_CONTROL_TARGET", check is None
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
        index = self.by_system.get(target)
        if index is None:
            self._unknown(target)
            return
        self.servers[index].dispatch(message, link, peer)

    def _unknown(self, system_id: int) -> None:
        self.counters["unknown_system"] += 1
        if self.counters["unknown_system"] % 100 == 1:
            first, last = min(self.by_system), max(self.by_system)
            self.servers[0].statustext(
                Severity.WARNING,
                f"refused: no system {system_id} here ({first}..{last})",
            )

    def _refuse_unaddressed(self) -> None:
        problem = self.servers[0].motors.reject(
            "unaddressed",
            f"HIL_ACTUATOR_CONTROLS refused: {len(self.servers)} vehicles here; address "
            "each with SET_ACTUATOR_CONTROL_TARGET",
        )
        if problem is not None:
            self.servers[0].statustext(Severity.WARNING, problem)

    # --- lockstep rounds --------------------------------------------------------------
    def _round_command(
        self,
        target: int,
        stamp: int,
        controls: Any,
        link: Link,
        signed: Any = None,
        peer: Peer | None = None,
    ) -> None:
        """One vehicle's command of a round (``signed``: the pymavlink message, whose
        signature is checked when signing is on); the round runs once it is complete."""
        index = self.by_system.get(target)
        if index is None:
            self._unknown(target)
            return
        server = self.servers[index]
        if server.signing is not None and (signed is None or server.signing.verdict(signed)):
            return
        if peer is not None and (server.signing is None or is_signed(signed)):
            link.accept(peer)
        now = self.round_start
        if stamp == self.previous_round and stamp != now:
            self.counters["duplicates"] += 1  # its answer was lost: the same answer again
            for frames in self.cached[index]:
                link.send_bytes(frames)
            return
        controls = list(controls)
        problem = check_controls(controls)
        if problem is None and stamp != now:
            problem = (
                "wrong_round",
                f"motor command refused: stamped {stamp} µs, the round starts at {now} µs",
            )
        if problem is not None:
            reason = server.motors.reject(*problem)
            if reason is not None:
                server.statustext(Severity.WARNING, reason)
            for frames in self._answers(link, [index]):
                link.send_bytes(frames)
            return
        self.pending[index] = controls
        self._round_wall = time.monotonic()
        if len(self.pending) == len(self.servers):
            for frames in self._run_round(link):
                link.send_bytes(frames)

    @property
    def round_start(self) -> int:
        """µs: the simulated time of the group's vehicles (they share a clock)."""
        return to_time_usec(self.group.vehicles[0].time)

    def _run_round(self, link: Link) -> list[bytes]:
        started = self.round_start
        wall = time.monotonic()
        order = range(len(self.servers))
        paths = [self.servers[index].motors for index in order]
        controls = [self.pending[index] for index in order]
        warnings = fly(paths, controls, [True] * len(paths), self.group.rotor_cmd)
        for index, warning in zip(order, warnings, strict=True):
            paths[index].last_lockstep_wall = wall
            if warning is not None:
                self.servers[index].statustext(Severity.WARNING, warning)
        self.pending.clear()
        self.group.advance()
        self.previous_round = started
        self.counters["rounds"] += 1
        return self._answers(link, list(order))

    def _answers(self, link: Link, rows: list[int]) -> list[bytes]:
        """The state answers of vehicles ``rows`` (cached as their last answer)."""
        physics = self.group.physics
        time_usec = self.round_start
        gears = physics.params[rows, P_GEAR_HEIGHT]  # each vehicle's airframe's
        # The state each answer carries: the truth, or what the observation delay shows.
        states, contact_rows, touchdown_rows = self.group.episodes.observed(rows)
        if len(rows) <= ROW_BY_ROW:  # a whole-array conversion costs more for a few
            wires = [
                WireState.from_physics(state, gear, 0, 0, 0.0)
                for state, gear in zip(states, gears.tolist(), strict=True)
            ]
            columns = [[getattr(w, f).tolist() for w in wires] for f in WIRE_FIELDS]
        else:
            batch = WireState.from_physics(states, gears, 0, None, None)
            columns = [getattr(batch, f).tolist() for f in WIRE_FIELDS]
        contacts = contact_rows.tolist()
        touchdowns = touchdown_rows.tolist()
        out: list[bytes] = []
        for k, i in enumerate(rows):
            p, q, v, r, rotors = (column[k] for column in columns)
            frames = self._answer_frames(
                link, i, time_usec, (p, q, v, r, rotors), contacts[k], touchdowns[k]
            )
            self.cached[i] = frames
            out += frames
        return out

    def _answer_frames(
        self,
        link: Link,
        i: int,
        time_usec: int,
        state: tuple[list[float], ...],
        contact: int,
        touchdown: float,
    ) -> list[bytes]:
        """Vehicle i's answer, its frames joined (a datagram never splits it).
        ``state``: position NED, quaternion, body velocity and rates FRD, rotor speeds."""
        server = self.servers[i]
        sysid = server.system_id
        parts = answer_parts(time_usec, state, contact, touchdown, server.motors.resets, lean=True)
        signer = link.signing()
        return [
            b"".join(
                FC.pack(cls, values, link.next_seq(sysid), sysid, server.component_id, signer)
                for cls, values in parts
            )
        ]
