"""The MAVLink server: a handler per incoming message id (:attr:`MavlinkServer.handlers`),
telemetry out.

It owns no sockets and no clock: the loop in :mod:`.runner` passes messages in with the
link they came from, and calls :meth:`MavlinkServer.tick` after stepping the physics.
Every frame sent or received goes to the telemetry log, except on the motor-command
link (``hil``), whose thousands of round trips a second would swamp it. With a signing
key, messages other than HEARTBEAT and RADIO_STATUS must be signed (:mod:`.signing`).
Telemetry goes to a peer of a link only once a frame from it has been accepted here
(validly signed, when signing is on; :meth:`.links.Link.accept`). The mission protocol's
messages (:attr:`MavlinkServer.to_sender`) are answered to their sender alone: two ground
stations with the same ids never hear each other's transfer.
What the vehicle presents itself as (PX4-compatible or generic) is :mod:`.identity`;
parameters, missions and pilot input (modes, sticks, offboard setpoints:
:mod:`.pilot_input`) have their own modules.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from quadsitl.flight_software.results import Outcome, Severity
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.simulator import telemetry as T
from quadsitl.simulator import telemetry_status as status
from quadsitl.simulator.commands import Command, Commands
from quadsitl.simulator.identity import IDENTITIES, Identity
from quadsitl.simulator.links import Link, Peer
from quadsitl.simulator.mission_protocol import MissionProtocol, Origin
from quadsitl.simulator.motor_slot import MotorSlot
from quadsitl.simulator.param_protocol import ParamProtocol
from quadsitl.simulator.pilot_input import PilotInput
from quadsitl.simulator.signing import (
    SignatureCheck,
    SigningNotices,
    StreamTimestamps,
    is_signed,
)
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.simulator.tlog import TlogWriter
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.modes import Mode
from quadsitl.wire.statustext import split_text

MOTOR_LINK = "hil"  # the link name whose traffic is not logged and has no streams
Handler = Callable[[Any, Link], None]  # a message, the link it came on
ToSender = Callable[[Any, Origin], None]  # a message, where it came from (answers go there)
RESULTS = {
    Outcome.ACCEPTED: mav.MAV_RESULT_ACCEPTED,
    Outcome.TEMPORARILY_REJECTED: mav.MAV_RESULT_TEMPORARILY_REJECTED,
    Outcome.DENIED: mav.MAV_RESULT_DENIED,
    Outcome.UNSUPPORTED: mav.MAV_RESULT_UNSUPPORTED,
    Outcome.FAILED: mav.MAV_RESULT_FAILED,
}


class MavlinkServer:
    def __init__(
        self,
        vehicle: Vehicle,
        links: list[Link],
        tlog: TlogWriter | None = None,
        system_id: int = 1,
        component_id: int = 1,
        echo: Callable[[str], None] | None = None,
        lockstep: bool = False,
        signing_key: bytes | None = None,
        identity: Identity = IDENTITIES["px4"],
    ) -> None:
        self.vehicle = vehicle
        self.identity = identity
        self.links = links
        self.tlog = tlog
        self.system_id, self.component_id = system_id, component_id
        self.echo = echo  # prints vehicle events for the user
        self.encoder = mav.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.schedules = {id(link): T.Schedule(streams=link.name != MOTOR_LINK) for link in links}
        self.lockstep = lockstep  # --lockstep: the motor path's (:mod:`.motor_path`)
        self.motors = MotorSlot(vehicle, system_id, component_id)  # this vehicle's part
        self.without_hil_state: set[int] = set()  # links whose answers leave it out
        self.signing: SignatureCheck | None = None
        self.signing_notices = SigningNotices(lambda text: self.statustext(Severity.WARNING, text))
        self._statustext_id = 0  # the id of this vehicle's last chunked STATUSTEXT
        if signing_key is not None:
            self.set_signing_key(signing_key)
        self.missions = MissionProtocol(vehicle, self.encoder, self.statustext)
        self.params = ParamProtocol(vehicle, self.encoder, self.statustext)
        self.last_heartbeat = -math.inf
        self.gcs_heard: float | None = None  # wall s of the last ground-station heartbeat
        self.gcs_lost = False
        self.last_mission_progress: tuple[int, int, int] | None = None
        self.last_state: tuple[bool, Mode, bool, bool] | None = None
        self.after_ack: list[Any] = []
        self.commands = Commands(self)
        self.counters = {"ignored": 0, "bad_values": 0}
        self.pilot = PilotInput(vehicle, self.statustext, self.counters)
        self.handlers: dict[int, Handler] = {  # message id: its handler
            mav.MAVLINK_MSG_ID_HEARTBEAT: self._on_heartbeat,
            mav.MAVLINK_MSG_ID_SETUP_SIGNING: self._on_setup_signing,
            mav.MAVLINK_MSG_ID_PING: self._on_ping,
            mav.MAVLINK_MSG_ID_TIMESYNC: self._on_timesync,
            mav.MAVLINK_MSG_ID_COMMAND_LONG: self._command,
            mav.MAVLINK_MSG_ID_COMMAND_INT: self._command,
            # pilot input: modes, sticks, offboard setpoints (pilot_input.py)
            mav.MAVLINK_MSG_ID_SET_MODE: self.pilot.on_set_mode,
            mav.MAVLINK_MSG_ID_MANUAL_CONTROL: self.pilot.on_manual_control,
            mav.MAVLINK_MSG_ID_REQUEST_DATA_STREAM: self._on_request_data_stream,
            mav.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED: self.pilot.on_set_position_target,
            mav.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET: self.pilot.on_set_attitude_target,
            # parameters (param_protocol.py)
            mav.MAVLINK_MSG_ID_PARAM_REQUEST_LIST: self._replying(self.params.on_request_list),
            mav.MAVLINK_MSG_ID_PARAM_REQUEST_READ: self._replying(self.params.on_request_read),
            mav.MAVLINK_MSG_ID_PARAM_SET: self._on_param_set,
            mav.MAVLINK_MSG_ID_MISSION_SET_CURRENT: self._on_mission_set_current,
        }
        # Transfers (mission_protocol.py): they belong to their sender, known by its link
        # and remote address as well as its ids, and are answered to it alone.
        self.to_sender: dict[int, ToSender] = {
            mav.MAVLINK_MSG_ID_MISSION_COUNT: self._timed(self.missions.on_count),
            mav.MAVLINK_MSG_ID_MISSION_ITEM_INT: self._timed(self.missions.on_item),
            mav.MAVLINK_MSG_ID_MISSION_ITEM: self._timed(self.missions.on_item),
            mav.MAVLINK_MSG_ID_MISSION_REQUEST_LIST: self.missions.on_request_list,
            mav.MAVLINK_MSG_ID_MISSION_REQUEST_INT: self.missions.on_request,
            mav.MAVLINK_MSG_ID_MISSION_REQUEST: self.missions.on_request,
            mav.MAVLINK_MSG_ID_MISSION_CLEAR_ALL: self.missions.on_clear_all,
        }

    def set_signing_key(self, key: bytes | None) -> None:
        """Require signed messages (and sign ours) with ``key``; None turns signing off.
        Streams start from the timestamps kept for this key (replays across restarts)."""
        self.signing = None
        if key is not None:
            self.signing = SignatureCheck(key, StreamTimestamps.for_key(key))
        for link_id, link in enumerate(self.links):
            link.set_signing(key, link_id)

    # --- sending ----------------------------------------------------------------------
    def send(self, message: Any, link: Link | None = None) -> None:
        """Send on one link, or on all."""
        for target in [link] if link is not None else self.links:
            frame = target.pack(message, self.system_id)
            target.send_bytes(frame)
            if self.tlog is not None and target.name != MOTOR_LINK:
                self.tlog.record(frame)

    def send_together(self, messages: list[Any], link: Link) -> None:
        """Several messages in one datagram (one system call, one wake-up at the peer)."""
        frames = [link.pack(message, self.system_id) for message in messages]
        link.send_bytes(b"".join(frames))
        if self.tlog is not None and link.name != MOTOR_LINK:
            for frame in frames:
                self.tlog.record(frame)

    def statustext(self, severity: int, text: str, echo: bool = True) -> None:
        """STATUSTEXT on every link; long texts are split into chunks
        (:mod:`quadsitl.wire.statustext`). ``echo``: also print it on the console (a fleet
        prints a text that concerns all its vehicles once)."""
        if echo and self.echo is not None:
            self.echo(f"[{self.vehicle.time:8.2f} s] {text}")
        chunks = split_text(text)
        chunk_id = 0
        if len(chunks) > 1:  # a counter: two texts' chunks never share an id (1..65535)
            self._statustext_id = self._statustext_id % 65535 + 1
            chunk_id = self._statustext_id
        for seq, chunk in enumerate(chunks):
            self.send(self.encoder.statustext_encode(severity, chunk, chunk_id, seq))

    @property
    def comm_errors(self) -> int:
        return sum(link.bad_frames for link in self.links)

    @property
    def error_counts(self) -> tuple[int, int, int, int]:
        """SYS_STATUS errors_count1..4: unsigned, badly signed and replayed messages
        rejected by signing, and rejected motor commands."""
        r = self.signing.rejected if self.signing is not None else {}
        return (
            r.get("unsigned", 0),
            r.get("bad_signature", 0),
            r.get("replayed", 0) + r.get("ahead", 0),
            self.motors.counters["rejected"],
        )

    # --- the loop's hooks -------------------------------------------------------------
    def dispatch(self, message: Any, link: Link, peer: Peer | None = None) -> None:
        """Check and handle one message from ``peer`` of ``link``; a message that passes
        (signed with the key, when signing is on) makes the peer live (telemetry)."""
        target = getattr(message, "target_system", 0)
        if target not in (0, self.system_id):
            self.counters["ignored"] += 1
            if peer is not None and self.signing is None:
                link.accept(peer)
            return
        if not self.admit(message, link, peer):
            return
        to_sender = self.to_sender.get(message.get_msgId())
        handler = self.handlers.get(message.get_msgId())
        try:
            if to_sender is not None:
                to_sender(message, self._origin(link, peer))
            elif handler is not None:
                handler(message, link)
        except (ValueError, TypeError, OverflowError) as error:
            # Out-of-range fields must never stop the vehicle: report and carry on.
            self.counters["bad_values"] += 1
            self.statustext(Severity.WARNING, f"rejected {message.get_type()}: {error}")

    def admit(self, message: Any, link: Link, peer: Peer | None) -> bool:
        """Whether ``message`` passes signing (when on; a rejection is counted and said);
        one that passes makes ``peer`` live (it hears this link's telemetry)."""
        if self.signing is not None and self.signing.verdict(message) is not None:
            self.signing_notices.rejected(self.signing, time.monotonic())
            return False
        if peer is not None and (self.signing is None or is_signed(message)):
            link.accept(peer)
        return True

    def tick(self, wall_now: float, lockstep: bool = False) -> None:
        """After the physics: events, heartbeat (wall clock), telemetry (sim clock; in
        ``lockstep`` also never faster than its rate on the wall clock)."""
        v = self.vehicle
        while v.events:
            severity, text = v.events.popleft()
            self.statustext(severity, text)
        while v.items_reached:
            self.send(self.encoder.mission_item_reached_encode(v.items_reached.popleft()))
        state = (v.armed, v.mode, v.crashed, v.motor_control)
        if wall_now - self.last_heartbeat >= T.HEARTBEAT_PERIOD or state != self.last_state:
            self.last_heartbeat, self.last_state = wall_now, state  # at once on a change
            self.send(status.build_heartbeat(v, self.identity.autopilot))
        self._watch_ground_station(wall_now)
        progress = (v.mission_current, len(v.mission), status.mission_state(v))
        if progress != self.last_mission_progress:  # at once, as PX4 does: MAVSDK's
            self.last_mission_progress = progress  # is_mission_finished reads it
            self.send(status.build_mission_current(self.snapshot()))
        self.missions.tick(wall_now)
        self.params.tick()
        if self.signing is not None:
            self.signing_notices.tick(self.signing, wall_now)
        wall_cap = wall_now if lockstep else None
        snapshot: Snapshot | None = None
        for link in self.links:
            due = self.schedules[id(link)].due(v.time, wall_cap)
            if not due:
                continue
            if snapshot is None:
                snapshot = self.snapshot()
            for message_id in due:
                if message_id == T.TRUTH_ONLY_BESIDE_ESTIMATE and not self.estimating:
                    continue  # the truth beside the truth would say nothing new
                self.send(T.BUILDERS[message_id](snapshot), link)

    @property
    def estimating(self) -> bool:
        """Whether the flight software flies on its estimate (EKF2_EN 1)."""
        return bool(self.vehicle.estimator.enabled)

    def snapshot(self) -> Snapshot:
        return Snapshot(
            self.vehicle, self.comm_errors, self.error_counts, self.identity, self.motors.resets
        )

    def greet(self) -> None:
        """Send the heartbeat at the next tick, not up to a second later: a peer just
        heard (a ground station, a lockstep client) waits for it to connect."""
        self.last_heartbeat = -math.inf

    # --- the ground station's heartbeat: link-loss failsafe (PX4's NAV_DLL_ACT) --------
    def _on_heartbeat(self, msg: Any, link: Link) -> None:
        if msg.type != mav.MAV_TYPE_GCS or link.name == MOTOR_LINK:
            return
        self.gcs_heard = time.monotonic()
        if self.gcs_lost:
            self.gcs_lost = False
            self.vehicle.datalink_regained()

    def _watch_ground_station(self, wall_now: float) -> None:
        """Link loss counts on the wall clock (the link lives there, not in simulated
        time) and only after a ground station has been heard."""
        if self.gcs_heard is None or self.gcs_lost:
            return
        silence = wall_now - self.gcs_heard
        if silence > self.vehicle.params["COM_DL_LOSS_T"]:
            self.gcs_lost = True
            self.vehicle.datalink_lost(silence)

    def close(self) -> None:
        """Keep the signing timestamps (the simulator is stopping)."""
        if self.signing is not None and self.signing.timestamps is not None:
            self.signing.timestamps.save()

    # --- signing ----------------------------------------------------------------------
    def _on_setup_signing(self, msg: Any, link: Link) -> None:
        """A new key from a ground station (MAVProxy's ``signing setup``). Once signing is
        on, only a message signed with the current key gets here; all zeros: off."""
        key = bytes(msg.secret_key)
        if getattr(msg, "target_component", 0) not in (0, self.component_id):
            return
        self.set_signing_key(None if not any(key) else key)
        self.statustext(Severity.NOTICE, "signing " + ("off" if not any(key) else "key set"))

    def hil_state(self, link: Link) -> bool:
        """Whether motor answers on ``link`` carry HIL_STATE_QUATERNION."""
        return id(link) not in self.without_hil_state

    # --- heartbeat, ping, time --------------------------------------------------------
    def _on_ping(self, msg: Any, link: Link) -> None:
        if msg.target_system == 0:  # a request, not an answer to one of ours
            self.send(
                self.encoder.ping_encode(
                    msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent()
                ),
                link,
            )

    def _on_timesync(self, msg: Any, link: Link) -> None:
        if msg.tc1 == 0:
            self.send(self.encoder.timesync_encode(time.monotonic_ns(), msg.ts1), link)

    # --- parameters (param_protocol.py) ------------------------------------------------
    def _on_param_set(self, msg: Any, link: Link) -> None:
        if getattr(msg, "target_component", 0) not in (0, self.component_id):
            return
        self.params.on_set(msg, self._reply(link), self.send)

    # --- commands ---------------------------------------------------------------------
    def _command(self, msg: Any, link: Link) -> None:
        if getattr(msg, "target_component", 0) not in (0, self.component_id):
            self.counters["ignored"] += 1
            return
        cmd = Command(msg)
        result = self.commands.run(cmd, link)
        if result.reason:
            self.statustext(Severity.WARNING if not result.ok else Severity.INFO, result.reason)
        self.send(
            self.encoder.command_ack_encode(
                cmd.id, RESULTS[result.outcome], 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            ),
            link,
        )
        if self.after_ack:  # requested messages follow their ACK (MAVLink spec)
            self.send_together(self.after_ack, link)
            self.after_ack = []

    def _on_request_data_stream(self, msg: Any, link: Link) -> None:
        ids = T.DATA_STREAMS.get(msg.req_stream_id, ())
        rate = float(msg.req_message_rate) if msg.start_stop else 0.0
        for message_id in ids:
            self.schedules[id(link)].set_rate(message_id, rate)

    # --- missions ---------------------------------------------------------------------
    def _reply(self, link: Link) -> Callable[[Any], None]:
        return lambda message: self.send(message, link)

    def _replying(self, on: Callable[[Any, Callable[[Any], None]], None]) -> Handler:
        """A handler calling a protocol's ``on(msg, reply)``, replies going back on the
        message's link."""
        return lambda msg, link: on(msg, self._reply(link))

    def _timed(self, on: Callable[[Any, Origin, float], None]) -> ToSender:
        """``on(msg, origin, now)`` called with the wall time."""
        return lambda msg, origin: on(msg, origin, time.monotonic())

    def _origin(self, link: Link, peer: Peer | None) -> Origin:
        """Where a message came from: answers go to ``peer`` alone (to every peer of the
        link when it is not known)."""
        if peer is None:
            return Origin(link.name, None, self._reply(link))
        address = peer.address
        return Origin(link.name, address, lambda message: self.answer(message, link, address))

    def answer(self, message: Any, link: Link, address: Any) -> None:
        """Send to one peer of ``link`` only."""
        frame = link.pack(message, self.system_id)
        link.send_to(frame, address)
        if self.tlog is not None and link.name != MOTOR_LINK:
            self.tlog.record(frame)

    def _on_mission_set_current(self, msg: Any, link: Link) -> None:
        result = self.vehicle.set_mission_current(msg.seq)
        if result.reason:
            self.statustext(Severity.WARNING, result.reason)
        self.send(status.build_mission_current(self.snapshot()), link)
