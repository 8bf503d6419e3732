"""The MAVLink server: one ``handle_<message>`` per incoming message, telemetry out.

It owns no sockets and no clock: the loop in :mod:`.runner` passes messages in with the
link they came from, and calls :meth:`MavlinkServer.tick` after stepping the physics.
Every frame sent or received goes to the telemetry log, except on the motor-command
link (``hil``), whose thousands of round trips a second would swamp it. With a signing
key, messages other than HEARTBEAT and RADIO_STATUS must be signed (:mod:`.signing`).
What the vehicle presents itself as (PX4-compatible or generic) is :mod:`.identity`;
parameters, missions and offboard setpoints have their own modules.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from quadsitl import frames
from quadsitl.mavlink import mavlink as mav
from quadsitl.mavlink import offboard
from quadsitl.mavlink import telemetry as T
from quadsitl.mavlink.identity import AVAILABLE_MODES, IDENTITIES, Identity, available_modes_message
from quadsitl.mavlink.links import Link
from quadsitl.mavlink.mission_protocol import MissionProtocol
from quadsitl.mavlink.motor_path import RESET_STATE, STAGE_MOTION, MotorPath
from quadsitl.mavlink.param_protocol import ParamProtocol
from quadsitl.mavlink.signing import SignatureCheck, sign_outgoing
from quadsitl.mavlink.tlog import TlogWriter
from quadsitl.vehicle.modes import Mode
from quadsitl.vehicle.results import ACCEPTED, Outcome, Result, Severity
from quadsitl.vehicle.vehicle import Vehicle

# COMPONENT_ARM_DISARM param2 values that force the action: PX4's and ArduPilot's
# emergency 21196, and 2989, which QGroundControl's "force arm" sends (src/Vehicle/Vehicle.cc).
FORCE_MAGIC = (21196, 2989)
STATUSTEXT_LENGTH = 50
SIGNING_REPORT_PERIOD = 10.0  # wall s between STATUSTEXT summaries of rejected messages
MOTOR_LINK = "hil"  # the link name whose traffic is not logged and has no streams
RESULTS = {
    Outcome.ACCEPTED: mav.MAV_RESULT_ACCEPTED,
    Outcome.TEMPORARILY_REJECTED: mav.MAV_RESULT_TEMPORARILY_REJECTED,
    Outcome.DENIED: mav.MAV_RESULT_DENIED,
    Outcome.UNSUPPORTED: mav.MAV_RESULT_UNSUPPORTED,
    Outcome.FAILED: mav.MAV_RESULT_FAILED,
}


class Command:
    """COMMAND_LONG and COMMAND_INT in one shape: params 1..7 (x, y as degrees)."""

    def __init__(self, msg: Any) -> None:
        self.id = msg.command
        self.is_int = msg.get_type() == "COMMAND_INT"
        self.frame = msg.frame if self.is_int else mav.MAV_FRAME_GLOBAL
        if self.is_int:
            x = msg.x * 1e-7 if msg.x != 0 or msg.y != 0 else math.nan
            y = msg.y * 1e-7 if msg.x != 0 or msg.y != 0 else math.nan
            self.params = [msg.param1, msg.param2, msg.param3, msg.param4, x, y, msg.z]
        else:
            self.params = [getattr(msg, f"param{i}") for i in range(1, 8)]


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
        self.motors = MotorPath(vehicle, lockstep)
        self.without_hil_state: set[int] = set()  # links whose answers leave it out
        self.signing: SignatureCheck | None = None
        self._signing_reported: tuple[float, int] = (-math.inf, 0)
        if signing_key is not None:
            self.set_signing_key(signing_key)
        self.missions = MissionProtocol(vehicle, self.encoder, self.statustext)
        self.params = ParamProtocol(vehicle, self.encoder, self.statustext)
        self.last_heartbeat = -math.inf
        self.gcs_heard: float | None = None  # wall s of the last ground-station heartbeat
        self.gcs_lost = False
        self.last_mission_progress: tuple[int, int, int] | None = None
        self.last_state: tuple[bool, Mode, bool, bool] | None = None
        self._after_ack: list[Any] = []
        self.commands = self._commands()
        self.counters = {"ignored": 0, "bad_values": 0}
        self.handlers: dict[str, Callable[[Any, Link], None]] = {
            name[len("handle_") :].upper(): getattr(self, name)
            for name in dir(self)
            if name.startswith("handle_")
        }

    def set_signing_key(self, key: bytes | None) -> None:
        """Require signed messages (and sign ours) with ``key``; None turns signing off."""
        self.signing = SignatureCheck(key) if key is not None else None
        for link_id, link in enumerate(self.links):
            if key is None:
                link.mav.signing.sign_outgoing = False
                link.mav.signing.secret_key = None
            else:
                sign_outgoing(link.mav, key, link_id)

    # --- sending ----------------------------------------------------------------------
    def send(self, message: Any, link: Link | None = None) -> None:
        """Send on one link, or on all."""
        for target in [link] if link is not None else self.links:
            frame = target.pack(message)
            target.send_bytes(frame)
            if self.tlog is not None and target.name != MOTOR_LINK:
                self.tlog.record(frame)

    def send_together(self, messages: list[Any], link: Link) -> None:
        """Several messages in one datagram (one system call, one wake-up at the peer)."""
        frames = [link.pack(message) for message in messages]
        link.send_bytes(b"".join(frames))
        if self.tlog is not None and link.name != MOTOR_LINK:
            for frame in frames:
                self.tlog.record(frame)

    def statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT on every link; long texts are split into chunks (MAVLink 2). A
        chunked text ends with a chunk shorter than 50 bytes, an empty one if need be
        (QGroundControl waits for it, src/MAVLink/StatusTextHandler.cc)."""
        if self.echo is not None:
            self.echo(f"[{self.vehicle.time:8.2f} s] {text}")
        data = text.encode("utf-8", "replace")
        chunks = [data[i : i + STATUSTEXT_LENGTH] for i in range(0, len(data), STATUSTEXT_LENGTH)]
        if len(chunks) > 1 and len(chunks[-1]) == STATUSTEXT_LENGTH:
            chunks.append(b"")
        chunk_id = (int(time.monotonic() * 1000) % 65535) + 1 if len(chunks) > 1 else 0
        for seq, chunk in enumerate(chunks or [b""]):
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
            r.get("replayed", 0),
            self.motors.counters["rejected"],
        )

    # --- the loop's hooks -------------------------------------------------------------
    def receive(self, link: Link, received_at: float | None = None) -> None:
        for message, _peer in link.receive():
            if self.tlog is not None and link.name != MOTOR_LINK:
                self.tlog.record(bytes(message.get_msgbuf()), received_at)
            self.dispatch(message, link)

    def dispatch(self, message: Any, link: Link) -> None:
        target = getattr(message, "target_system", 0)
        if target not in (0, self.system_id):
            self.counters["ignored"] += 1
            return
        if self.signing is not None and self.signing.verdict(message) is not None:
            self._report_signing()
            return
        handler = self.handlers.get(message.get_type())
        if handler is None:
            return
        try:
            handler(message, link)
        except (ValueError, TypeError, OverflowError) as error:
            # Out-of-range fields must never stop the vehicle: report and carry on.
            self.counters["bad_values"] += 1
            self.statustext(Severity.WARNING, f"rejected {message.get_type()}: {error}")

    def tick(self, wall_now: float) -> None:
        """After the physics: events, heartbeat (wall clock), telemetry (sim clock; in
        lockstep also never faster than its rate on the wall clock)."""
        v = self.vehicle
        while v.events:
            severity, text = v.events.popleft()
            self.statustext(severity, text)
        while v.items_reached:
            self.send(self.encoder.mission_item_reached_encode(v.items_reached.popleft()))
        state = (v.armed, v.mode, v.crashed, v.motor_control)
        if wall_now - self.last_heartbeat >= T.HEARTBEAT_PERIOD or state != self.last_state:
            self.last_heartbeat, self.last_state = wall_now, state  # at once on a change
            self.send(T.build_heartbeat(v, self.identity.autopilot))
        self._watch_ground_station(wall_now)
        progress = (v.mission_current, len(v.mission), T.mission_state(v))
        if progress != self.last_mission_progress:  # at once, as PX4 does: MAVSDK's
            self.last_mission_progress = progress  # is_mission_finished reads it
            self.send(T.build_mission_current(self._snapshot()))
        self.missions.tick(wall_now)
        if self.signing is not None and wall_now - self._signing_reported[0] > 1.0:
            self._report_signing(wall_now)
        wall_cap = wall_now if self.motors.lockstep else None
        snapshot: T.Snapshot | None = None
        for link in self.links:
            due = self.schedules[id(link)].due(v.time, wall_cap)
            if not due:
                continue
            if snapshot is None:
                snapshot = self._snapshot()
            for message_id in due:
                self.send(T.BUILDERS[message_id](snapshot), link)

    def _snapshot(self) -> T.Snapshot:
        return T.Snapshot(self.vehicle, self.comm_errors, self.error_counts, self.identity)

    # --- the ground station's heartbeat: link-loss failsafe (PX4's NAV_DLL_ACT) --------
    def handle_heartbeat(self, msg: Any, link: Link) -> None:
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

    def _report_signing(self, wall_now: float | None = None) -> None:
        """STATUSTEXT at the first rejection, then a summary at most every 10 s."""
        assert self.signing is not None
        total = sum(self.signing.rejected.values())
        last_time, last_total = self._signing_reported
        now = time.monotonic() if wall_now is None else wall_now
        first = last_total == 0 and total > 0
        if total != last_total and (first or now - last_time >= SIGNING_REPORT_PERIOD):
            self._signing_reported = (now, total)
            self.statustext(Severity.WARNING, self.signing.summary())

    # --- motor path ---------------------------------------------------------------------
    def handle_hil_actuator_controls(self, msg: Any, link: Link) -> None:
        problem = self.motors.command(msg)
        if problem is not None:
            self.statustext(Severity.WARNING, problem)
        self.send_together(self.motors.state_messages(self._hil_state(link)), link)

    def handle_setup_signing(self, msg: Any, link: Link) -> None:
        """A new key from a ground station (MAVProxy's ``signing setup``). Once signing is
        on, only a message signed with the current key gets here; all zeros: off."""
        key = bytes(msg.secret_key)
        if getattr(msg, "target_component", 0) not in (0, self.component_id):
            return
        self.set_signing_key(None if not any(key) else key)
        self.statustext(Severity.NOTICE, "signing " + ("off" if not any(key) else "key set"))

    def _hil_state(self, link: Link) -> bool:
        return id(link) not in self.without_hil_state

    def _cmd_reset_state(self, c: Command, link: Link) -> Result:
        result = self.motors.reset(c.params)
        if result.ok:
            self._after_ack.extend(self.motors.state_messages(self._hil_state(link)))
        return result

    # --- heartbeat, ping, time --------------------------------------------------------
    def handle_ping(self, msg: Any, link: Link) -> None:
        if msg.target_system == 0:  # a request, not an answer to one of ours
            self.send(
                self.encoder.ping_encode(
                    msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent()
                ),
                link,
            )

    def handle_timesync(self, msg: Any, link: Link) -> None:
        if msg.tc1 == 0:
            self.send(self.encoder.timesync_encode(time.monotonic_ns(), msg.ts1), link)

    # --- parameters (param_protocol.py) ------------------------------------------------
    def handle_param_request_list(self, msg: Any, link: Link) -> None:
        self.params.on_request_list(msg, self._reply(link))

    def handle_param_request_read(self, msg: Any, link: Link) -> None:
        self.params.on_request_read(msg, self._reply(link))

    def handle_param_set(self, msg: Any, link: Link) -> None:
        if getattr(msg, "target_component", 0) not in (0, self.component_id):
            return
        self.params.on_set(msg, self._reply(link), self.send)

    # --- commands ---------------------------------------------------------------------
    def handle_command_long(self, msg: Any, link: Link) -> None:
        self._command(msg, link)

    def handle_command_int(self, msg: Any, link: Link) -> None:
        self._command(msg, link)

    def _command(self, msg: Any, link: Link) -> None:
        if getattr(msg, "target_component", 0) not in (0, self.component_id):
            self.counters["ignored"] += 1
            return
        cmd = Command(msg)
        runner = self.commands.get(cmd.id)
        if runner is None:
            result = Result(Outcome.UNSUPPORTED)
        else:
            try:
                result = runner(cmd, link)
            except ValueError as error:
                result = Result(Outcome.DENIED, str(error))
        if result.reason:
            self.statustext(Severity.WARNING if not result.ok else Severity.INFO, result.reason)
        self.send(
            self.encoder.command_ack_encode(
                cmd.id, RESULTS[result.outcome], 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            ),
            link,
        )
        if self._after_ack:  # requested messages follow their ACK (MAVLink spec)
            self.send_together(self._after_ack, link)
            self._after_ack = []

    def _commands(self) -> dict[int, Callable[[Command, Link], Result]]:
        return {
            mav.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm_disarm,
            mav.MAV_CMD_NAV_TAKEOFF: self._cmd_takeoff,
            mav.MAV_CMD_NAV_LAND: lambda c, link: self.vehicle.land(),
            mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda c, link: self.vehicle.return_to_launch(),
            mav.MAV_CMD_DO_SET_MODE: self._cmd_set_mode,
            mav.MAV_CMD_DO_REPOSITION: self._cmd_reposition,
            mav.MAV_CMD_SET_MESSAGE_INTERVAL: self._cmd_message_interval,
            mav.MAV_CMD_REQUEST_MESSAGE: self._cmd_request_message,
            mav.MAV_CMD_GET_HOME_POSITION: lambda c, link: self._send_once(
                mav.MAVLINK_MSG_ID_HOME_POSITION, link
            ),
            mav.MAV_CMD_GET_MESSAGE_INTERVAL: self._cmd_get_message_interval,
            mav.MAV_CMD_DO_SET_HOME: self._cmd_set_home,
            mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: lambda c, link: self._send_once(
                mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION, link
            ),
            mav.MAV_CMD_MISSION_START: self._cmd_mission_start,
            mav.MAV_CMD_DO_SET_MISSION_CURRENT: lambda c, link: self.vehicle.set_mission_current(
                _int(c.params[0], "item")
            ),
            mav.MAV_CMD_DO_CHANGE_SPEED: self._cmd_change_speed,
            mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: self._cmd_reboot,
            RESET_STATE: self._cmd_reset_state,
            STAGE_MOTION: lambda c, link: self.motors.stage_motion(c.params),
        }

    def _cmd_arm_disarm(self, c: Command, link: Link) -> Result:
        force = math.isfinite(c.params[1]) and round(c.params[1]) in FORCE_MAGIC
        if c.params[0] == 1:
            return self.vehicle.arm(force)
        if c.params[0] == 0:
            return self.vehicle.disarm(force)
        return Result(Outcome.DENIED, f"arm/disarm: param1 must be 0 or 1, got {c.params[0]}")

    def _cmd_takeoff(self, c: Command, link: Link) -> Result:
        """Param7: AMSL for the PX4 identity (NaN: MIS_TAKEOFF_ALT), relative to home for
        the generic one; COMMAND_INT says which by its frame. An AMSL altitude below the
        ground is what MAVProxy and other ArduPilot-style clients send as a height above
        home: it is read so, with a message."""
        v = self.vehicle
        altitude = c.params[6]
        if math.isnan(altitude):
            return v.takeoff(None)
        if c.is_int:
            amsl = c.frame in (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT)
        else:
            amsl = self.identity.takeoff_param7_amsl
        if amsl and altitude < v.origin.altitude:
            self.statustext(
                Severity.INFO,
                f"take-off altitude {altitude:g} m is below the "
                "ground as AMSL: taken as metres above home",
            )
            amsl = False
        return v.takeoff(altitude - v.home_altitude if amsl else altitude)

    def _cmd_set_home(self, c: Command, link: Link) -> Result:
        """DO_SET_HOME: param1 = 1 the current position, else params 5-7 (AMSL)."""
        v = self.vehicle
        if c.params[0] == 1:
            east, north, _ = v.position
            up = v.altitude
        else:
            lat, lon, alt = c.params[4], c.params[5], c.params[6]
            if not all(math.isfinite(x) for x in (lat, lon, alt)):
                return Result(
                    Outcome.DENIED,
                    "set home denied: latitude, longitude and altitude must be numbers",
                )
            east, north, up = v.origin.to_local(lat, lon, alt)
        result = v.set_home(float(east), float(north), float(up))
        if result.ok:  # ground stations learn the new home at once
            self._after_ack.append(T.build_home_position(self._snapshot()))
        return result

    def _cmd_set_mode(self, c: Command, link: Link) -> Result:
        base, main, sub = c.params[0], c.params[1], c.params[2]
        if not int(base) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return Result(Outcome.DENIED, "set mode: only custom (PX4-layout) modes are supported")
        sub = 0 if math.isnan(sub) else sub
        return self.vehicle.set_mode(
            Mode.from_custom(_int(main, "main mode"), _int(sub, "sub mode"))
        )

    def handle_set_mode(self, msg: Any, link: Link) -> None:
        """SET_MODE (QGroundControl's PX4 plugin and MAVProxy send it); no ACK exists for
        it: the heartbeat shows the new mode, a STATUSTEXT the refusal."""
        try:
            mode = Mode.from_custom_mode(msg.custom_mode)
        except ValueError as error:
            self.statustext(Severity.WARNING, str(error))
            return
        result = self.vehicle.set_mode(mode)
        if result.reason:
            self.statustext(Severity.WARNING, result.reason)

    def handle_manual_control(self, msg: Any, link: Link) -> None:
        """Joystick (QGroundControl's): x forward, y right, r yaw in ±1000, z thrust
        0..1000 with 500 = hold altitude. Flown in POSCTL/ALTCTL; COM_RC_IN_MODE = 4
        turns stick input off."""
        if self.vehicle.params["COM_RC_IN_MODE"] == 4:
            return
        centre = (0, 0, 500, 0)  # an axis out of range (INT16_MAX: not in use) is centred
        x, y, z, r = (
            a if -1000 <= a <= 1000 else c
            for a, c in zip((msg.x, msg.y, msg.z, msg.r), centre, strict=True)
        )
        self.vehicle.stick_input(x / 1000, y / 1000, (z - 500) / 500, r / 1000)

    def _cmd_reposition(self, c: Command, link: Link) -> Result:
        speed, yaw_deg, lat, lon, alt = (
            c.params[0],
            c.params[3],
            c.params[4],
            c.params[5],
            c.params[6],
        )
        v = self.vehicle
        relative = c.frame in (
            mav.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        )
        east = north = math.nan
        if math.isfinite(lat) and math.isfinite(lon):
            east, north, _ = v.origin.to_local(lat, lon, v.origin.altitude)
        if math.isnan(alt):
            up = math.nan
        else:  # m above the ground
            up = alt + float(v.home_position[2]) if relative else alt - v.origin.altitude
        yaw = None if math.isnan(yaw_deg) else float(frames.yaw_ned_to_enu(math.radians(yaw_deg)))
        speed_ok = math.isfinite(speed) and speed > 0
        return self.vehicle.reposition(east, north, up, speed if speed_ok else None, yaw)

    def _cmd_message_interval(self, c: Command, link: Link) -> Result:
        message_id, interval_us = _int(c.params[0], "message id"), c.params[1]
        if message_id == mav.MAVLINK_MSG_ID_HEARTBEAT:
            return ACCEPTED  # always 1 Hz
        if message_id == mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION:  # in motor answers only
            if interval_us < 0:
                self.without_hil_state.add(id(link))
            else:
                self.without_hil_state.discard(id(link))
            return ACCEPTED
        if message_id not in T.BUILDERS:
            return Result(Outcome.UNSUPPORTED, f"message {message_id} is not streamed")
        schedule = self.schedules[id(link)]
        if interval_us == 0 or math.isnan(interval_us):
            schedule.set_rate(message_id, None)
        elif interval_us < 0:
            schedule.set_rate(message_id, 0.0)
        else:
            schedule.set_rate(message_id, min(1e6 / max(interval_us, 1000.0), 1000.0))
        return ACCEPTED

    def _cmd_request_message(self, c: Command, link: Link) -> Result:
        message_id = _int(c.params[0], "message id")
        if message_id == mav.MAVLINK_MSG_ID_HEARTBEAT:
            self._after_ack.append(T.build_heartbeat(self.vehicle, self.identity.autopilot))
            return ACCEPTED
        if message_id == mav.MAVLINK_MSG_ID_AVAILABLE_MODES:
            return self._available_modes(c.params[1])
        if message_id == mav.MAVLINK_MSG_ID_MESSAGE_INTERVAL:
            return self._message_interval(_int(c.params[1], "param2 (message id)"), link)
        return self._send_once(message_id, link)

    def _available_modes(self, index_param: float) -> Result:
        """Param2: the mode's index, 1..N; 0 (or NaN) for all of them."""
        index = 0 if math.isnan(index_param) else _int(index_param, "mode index")
        if not 0 <= index <= len(AVAILABLE_MODES):
            return Result(Outcome.DENIED, f"no mode with index {index}")
        indices = range(1, len(AVAILABLE_MODES) + 1) if index == 0 else [index]
        self._after_ack.extend(available_modes_message(self.encoder, i) for i in indices)
        return ACCEPTED

    def _cmd_get_message_interval(self, c: Command, link: Link) -> Result:
        return self._message_interval(_int(c.params[0], "message id"), link)

    def _message_interval(self, message_id: int, link: Link) -> Result:
        """MESSAGE_INTERVAL: µs between sends on this link; -1 not sent, 0 unknown id."""
        if message_id == mav.MAVLINK_MSG_ID_HEARTBEAT:
            interval_us = round(T.HEARTBEAT_PERIOD * 1e6)
        elif message_id in T.BUILDERS or message_id in T.DEFAULT_RATES:
            seconds = self.schedules[id(link)].intervals.get(message_id)
            interval_us = -1 if seconds is None else round(seconds * 1e6)
        else:
            interval_us = 0
        self._after_ack.append(self.encoder.message_interval_encode(message_id, interval_us))
        return ACCEPTED

    def _send_once(self, message_id: int, link: Link) -> Result:
        builder = T.BUILDERS.get(message_id)
        if builder is None:
            return Result(Outcome.UNSUPPORTED)
        self._after_ack.append(builder(self._snapshot()))
        return ACCEPTED

    def handle_request_data_stream(self, msg: Any, link: Link) -> None:
        ids = T.DATA_STREAMS.get(msg.req_stream_id, ())
        rate = float(msg.req_message_rate) if msg.start_stop else 0.0
        for message_id in ids:
            self.schedules[id(link)].set_rate(message_id, rate)

    def _cmd_mission_start(self, c: Command, link: Link) -> Result:
        first = c.params[0]
        if math.isfinite(first) and first > 0:
            result = self.vehicle.set_mission_current(int(first))
            if not result.ok:
                return result
        return self.vehicle.set_mode(Mode.MISSION)

    def _cmd_change_speed(self, c: Command, link: Link) -> Result:
        speed = c.params[1]
        if not (math.isfinite(speed) and speed > 0):
            return Result(Outcome.DENIED, f"change speed: {speed} m/s is not a speed")
        self.vehicle.mission_speed = speed
        return ACCEPTED

    def _cmd_reboot(self, c: Command, link: Link) -> Result:
        if c.params[0] != 1:
            return Result(Outcome.UNSUPPORTED)
        if self.vehicle.armed:
            return Result(Outcome.DENIED, "reboot denied: disarm first")
        self.vehicle.reboot()
        return ACCEPTED

    # --- missions ---------------------------------------------------------------------
    def _reply(self, link: Link) -> Callable[[Any], None]:
        return lambda message: self.send(message, link)

    def handle_mission_count(self, msg: Any, link: Link) -> None:
        self.missions.on_count(msg, self._reply(link), time.monotonic())

    def handle_mission_item_int(self, msg: Any, link: Link) -> None:
        self.missions.on_item(msg, self._reply(link), time.monotonic())

    def handle_mission_item(self, msg: Any, link: Link) -> None:
        self.missions.on_item(msg, self._reply(link), time.monotonic())

    def handle_mission_request_list(self, msg: Any, link: Link) -> None:
        self.missions.on_request_list(msg, self._reply(link))

    def handle_mission_request_int(self, msg: Any, link: Link) -> None:
        self.missions.on_request(msg, self._reply(link))

    def handle_mission_request(self, msg: Any, link: Link) -> None:
        self.missions.on_request(msg, self._reply(link))

    def handle_mission_clear_all(self, msg: Any, link: Link) -> None:
        self.missions.on_clear_all(msg, self._reply(link))

    def handle_mission_set_current(self, msg: Any, link: Link) -> None:
        result = self.vehicle.set_mission_current(msg.seq)
        if result.reason:
            self.statustext(Severity.WARNING, result.reason)
        self.send(T.build_mission_current(self._snapshot()), link)

    # --- offboard (offboard.py) ---------------------------------------------------------
    def handle_set_position_target_local_ned(self, msg: Any, link: Link) -> None:
        v = self.vehicle
        yaw_now = float(frames.euler_from_quat(v.fleet.quaternion[0])[2])
        setpoint = offboard.position_target(msg, v.position, yaw_now, v.airframe.gear_height)
        if isinstance(setpoint, str):
            self._bad_value(setpoint)
        else:
            v.offboard_setpoint(setpoint)

    def handle_set_attitude_target(self, msg: Any, link: Link) -> None:
        setpoint = offboard.attitude_target(msg)
        if isinstance(setpoint, str):
            self._bad_value(setpoint)
        else:
            self.vehicle.offboard_setpoint(setpoint)

    def _bad_value(self, text: str) -> None:
        self.counters["bad_values"] += 1
        if self.counters["bad_values"] % 100 == 1:  # do not flood the links
            self.statustext(Severity.WARNING, text)


def _int(value: float, what: str) -> int:
    if not math.isfinite(value):
        raise ValueError(f"{what} must be a number, got {value}")
    return round(value)
