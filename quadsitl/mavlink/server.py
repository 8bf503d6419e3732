"""The MAVLink server: one ``handle_<message>`` per incoming message, telemetry out.

It owns no sockets and no clock: the loop in :mod:`.runner` passes messages in with the
link they came from, and calls :meth:`MavlinkServer.tick` after stepping the physics.
Every frame sent or received goes to the telemetry log, except on the motor-command
link (``hil``), whose thousands of round trips a second would swamp it. With a signing
key, messages other than HEARTBEAT and RADIO_STATUS must be signed (:mod:`.signing`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.mavlink import mavlink as mav
from quadsitl.mavlink import telemetry as T
from quadsitl.mavlink.links import Link
from quadsitl.mavlink.mission_protocol import MissionProtocol
from quadsitl.mavlink.motor_path import RESET_STATE, STAGE_MOTION, MotorPath
from quadsitl.mavlink.signing import SignatureCheck, sign_outgoing
from quadsitl.mavlink.tlog import TlogWriter
from quadsitl.vehicle.controller import Setpoint
from quadsitl.vehicle.modes import Mode
from quadsitl.vehicle.params import PARAMETERS
from quadsitl.vehicle.results import ACCEPTED, Outcome, Result
from quadsitl.vehicle.vehicle import Vehicle

FORCE_MAGIC = 21196  # COMPONENT_ARM_DISARM param2 that forces the action (PX4, ArduPilot)
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
    ) -> None:
        self.vehicle = vehicle
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
        self.last_heartbeat = -math.inf
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
        """STATUSTEXT on every link; long texts are split into chunks (MAVLink 2)."""
        if self.echo is not None:
            self.echo(f"[{self.vehicle.time:8.2f} s] {text}")
        data = text.encode("utf-8", "replace")
        chunks = [data[i : i + STATUSTEXT_LENGTH] for i in range(0, len(data), STATUSTEXT_LENGTH)]
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
            r.get("unsigned", 0), r.get("bad_signature", 0), r.get("replayed", 0),
            self.motors.counters["rejected"],
        )  # fmt: skip

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
            self.statustext(4, f"rejected {message.get_type()}: {error}")

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
            self.send(T.build_heartbeat(v))
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
                snapshot = T.Snapshot(v, self.comm_errors, self.error_counts)
            for message_id in due:
                self.send(T.BUILDERS[message_id](snapshot), link)

    def _report_signing(self, wall_now: float | None = None) -> None:
        """STATUSTEXT at the first rejection, then a summary at most every 10 s."""
        assert self.signing is not None
        total = sum(self.signing.rejected.values())
        last_time, last_total = self._signing_reported
        now = time.monotonic() if wall_now is None else wall_now
        first = last_total == 0 and total > 0
        if total != last_total and (first or now - last_time >= SIGNING_REPORT_PERIOD):
            self._signing_reported = (now, total)
            self.statustext(4, self.signing.summary())

    # --- motor path ---------------------------------------------------------------------
    def handle_hil_actuator_controls(self, msg: Any, link: Link) -> None:
        problem = self.motors.command(msg)
        if problem is not None:
            self.statustext(4, problem)
        self.send_together(self.motors.state_messages(self._hil_state(link)), link)

    def handle_setup_signing(self, msg: Any, link: Link) -> None:
        """A new key from a ground station (MAVProxy's ``signing setup``). Once signing is
        on, only a message signed with the current key gets here; all zeros: off."""
        key = bytes(msg.secret_key)
        if getattr(msg, "target_component", 0) not in (0, self.component_id):
            return
        self.set_signing_key(None if not any(key) else key)
        self.statustext(5, "signing " + ("off" if not any(key) else "key set"))

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

    # --- parameters -------------------------------------------------------------------
    def _param_value(self, name: str) -> Any:
        names = self.vehicle.params.names()
        return self.encoder.param_value_encode(
            name.encode(), self.vehicle.params[name], mav.MAV_PARAM_TYPE_REAL32,
            len(names), names.index(name),
        )  # fmt: skip

    def handle_param_request_list(self, msg: Any, link: Link) -> None:
        for spec in PARAMETERS:
            self.send(self._param_value(spec.name), link)

    def handle_param_request_read(self, msg: Any, link: Link) -> None:
        names = self.vehicle.params.names()
        if msg.param_index >= 0:
            if msg.param_index >= len(names):
                self.statustext(4, f"no parameter with index {msg.param_index}")
                return
            name = names[msg.param_index]
        else:
            name = _param_name(msg.param_id)
            if name not in names:
                self.statustext(4, f"unknown parameter {name!r}")
                return
        self.send(self._param_value(name), link)

    def handle_param_set(self, msg: Any, link: Link) -> None:
        name = _param_name(msg.param_id)
        try:
            self.vehicle.set_param(name, msg.param_value)
        except ValueError as error:
            self.statustext(4, f"param set refused: {error}")
            if name not in self.vehicle.params.names():
                return
        self.send(self._param_value(name))  # echo: the acknowledgement (or the old value)

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
            self.statustext(4, result.reason)
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
        force = round(c.params[1]) == FORCE_MAGIC if math.isfinite(c.params[1]) else False
        if c.params[0] == 1:
            return self.vehicle.arm(force)
        if c.params[0] == 0:
            return self.vehicle.disarm(force)
        return Result(Outcome.DENIED, f"arm/disarm: param1 must be 0 or 1, got {c.params[0]}")

    def _cmd_takeoff(self, c: Command, link: Link) -> Result:
        altitude = c.params[6]
        if math.isnan(altitude):
            return self.vehicle.takeoff(None)
        relative = c.is_int and c.frame in (
            mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        )  # fmt: skip
        return self.vehicle.takeoff(altitude if relative else altitude - self.vehicle.home.altitude)

    def _cmd_set_mode(self, c: Command, link: Link) -> Result:
        base, main, sub = c.params[0], c.params[1], c.params[2]
        if not int(base) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return Result(Outcome.DENIED, "set mode: only custom (PX4-layout) modes are supported")
        sub = 0 if math.isnan(sub) else sub
        return self.vehicle.set_mode(
            Mode.from_custom(_int(main, "main mode"), _int(sub, "sub mode"))
        )

    def handle_set_mode(self, msg: Any, link: Link) -> None:
        """Deprecated SET_MODE message (MAVProxy still sends it); no ACK exists for it."""
        try:
            mode = Mode.from_custom_mode(msg.custom_mode)
        except ValueError as error:
            self.statustext(4, str(error))
            return
        result = self.vehicle.set_mode(mode)
        if result.reason:
            self.statustext(4, result.reason)

    def _cmd_reposition(self, c: Command, link: Link) -> Result:
        speed, yaw_deg, lat, lon, alt = (
            c.params[0],
            c.params[3],
            c.params[4],
            c.params[5],
            c.params[6],
        )
        home = self.vehicle.home
        relative = c.frame in (
            mav.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        )
        east = north = math.nan
        if math.isfinite(lat) and math.isfinite(lon):
            east, north, _ = home.to_local(lat, lon, home.altitude)
        up = alt if relative or math.isnan(alt) else alt - home.altitude
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
            self._after_ack.append(T.build_heartbeat(self.vehicle))
            return ACCEPTED
        return self._send_once(message_id, link)

    def _send_once(self, message_id: int, link: Link) -> Result:
        builder = T.BUILDERS.get(message_id)
        if builder is None:
            return Result(Outcome.UNSUPPORTED)
        self._after_ack.append(
            builder(T.Snapshot(self.vehicle, self.comm_errors, self.error_counts))
        )
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
            self.statustext(4, result.reason)
        self.send(T.build_mission_current(T.Snapshot(self.vehicle)), link)

    # --- offboard ---------------------------------------------------------------------
    def handle_set_position_target_local_ned(self, msg: Any, link: Link) -> None:
        values = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, msg.afx, msg.afy, msg.afz)
        mask = msg.type_mask
        used = [v for i, v in enumerate(values) if not mask & (1 << i)]
        if not all(math.isfinite(v) for v in used) or not all(
            math.isfinite(v) for bit, v in ((1024, msg.yaw), (2048, msg.yaw_rate)) if not mask & bit
        ):
            self._bad_value("offboard setpoint with NaN or inf ignored")
            return
        v = self.vehicle
        yaw_now = float(frames.euler_from_quat(v.fleet.quaternion[0])[2])
        frame = msg.coordinate_frame
        body = frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
        if not body and frame not in (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED):
            self._bad_value(f"offboard frame {frame} unsupported: use LOCAL_NED or BODY_NED")
            return
        heading = frames.quat_from_axis_angle([0.0, 0.0, 1.0], yaw_now)

        def to_enu(ned: tuple[float, float, float]) -> np.ndarray:
            if body:  # x forward, y right, z down, turned with the vehicle's heading
                return frames.quat_rotate(heading, np.array([ned[0], -ned[1], -ned[2]]))
            return frames.ned_to_enu(np.array(ned))

        setpoint = Setpoint()
        if not mask & 0b111:
            position = to_enu((msg.x, msg.y, msg.z))
            if frame in (mav.MAV_FRAME_LOCAL_OFFSET_NED, mav.MAV_FRAME_BODY_OFFSET_NED):
                position = position + v.position
            else:
                position[2] += v.airframe.gear_height  # NED z is the ground-level frame's
            setpoint.position = position
        if not mask & 0b111000:
            setpoint.velocity = to_enu((msg.vx, msg.vy, msg.vz))
        if not mask & 0b111000000:
            setpoint.acceleration = to_enu((msg.afx, msg.afy, msg.afz))
        if not mask & 1024:
            setpoint.yaw = float(frames.yaw_ned_to_enu(msg.yaw))
        if not mask & 2048:
            setpoint.yaw_rate = -msg.yaw_rate  # NED (down) -> ENU (up)
        v.offboard_setpoint(setpoint)

    def handle_set_attitude_target(self, msg: Any, link: Link) -> None:
        mask = msg.type_mask
        rates = (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate)
        checked = [*list(msg.q), msg.thrust, *list(rates)]
        if not all(math.isfinite(x) for x in checked):
            self._bad_value("attitude setpoint with NaN or inf ignored")
            return
        setpoint = Setpoint(thrust=float(np.clip(msg.thrust, 0.0, 1.0)))
        if not mask & 128:
            q = np.array(msg.q, dtype=np.float64)
            if np.linalg.norm(q) < 1e-6:
                self._bad_value("attitude setpoint with a zero quaternion ignored")
                return
            setpoint.attitude = frames.quat_ned_frd_to_enu_flu(q / np.linalg.norm(q))
        if not mask & 0b111 or mask & 128:
            frd = np.array([0.0 if mask & (1 << i) else r for i, r in enumerate(rates)])
            setpoint.body_rates = frames.frd_to_flu(frd)
        self.vehicle.offboard_setpoint(setpoint)

    def _bad_value(self, text: str) -> None:
        self.counters["bad_values"] += 1
        if self.counters["bad_values"] % 100 == 1:  # do not flood the links
            self.statustext(4, text)


def _param_name(raw: Any) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return str(raw).split("\x00", 1)[0].strip()


def _int(value: float, what: str) -> int:
    if not math.isfinite(value):
        raise ValueError(f"{what} must be a number, got {value}")
    return round(value)
