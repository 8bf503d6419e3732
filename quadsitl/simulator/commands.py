"""COMMAND_LONG and COMMAND_INT: one ``_cmd_<name>`` per MAV_CMD, each returning a Result.

The server (:mod:`.server`) decodes the message into a :class:`Command`, runs it here and
answers with COMMAND_ACK (and, after it, any message the command asked for: see
``server.after_ack``). What the commands need of the server is :class:`CommandHost`, so
this module does not import the server. Frames and units are converted here, at the
wire: AMSL and relative altitudes to local metres, NED yaw in degrees to ENU radians.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Protocol

from quadsitl import frames
from quadsitl.flight_software.results import ACCEPTED, Outcome, Result, Severity
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.physics.sensors.failures import FAILURE_NAMES, OFF, STUCK
from quadsitl.physics.sensors.failures import OK as SENSOR_OK
from quadsitl.simulator import telemetry as T
from quadsitl.simulator import telemetry_pose as pose
from quadsitl.simulator import telemetry_status as status
from quadsitl.simulator.identity import AVAILABLE_MODES, Identity, available_modes_message
from quadsitl.simulator.links import Link
from quadsitl.simulator.motor_slot import MotorSlot
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import FORCE_MAGIC, RESET_STATE, STAGE_AIRFRAME, STAGE_MOTION
from quadsitl.wire.modes import Mode

# COMPONENT_ARM_DISARM param2 that forces the action: PX4's and ArduPilot's 21196 (what
# this project's clients send), and 2989, which QGroundControl's "force arm" sends
# (src/Vehicle/Vehicle.cc).

# MAV_CMD_INJECT_FAILURE's sensor units and failure types the sensor models simulate.
SENSOR_UNITS = {
    mav.FAILURE_UNIT_SENSOR_GYRO: "gyro",
    mav.FAILURE_UNIT_SENSOR_ACCEL: "accel",
    mav.FAILURE_UNIT_SENSOR_MAG: "mag",
    mav.FAILURE_UNIT_SENSOR_BARO: "baro",
    mav.FAILURE_UNIT_SENSOR_GPS: "gps",
}
SENSOR_FAILURES = {
    mav.FAILURE_TYPE_OK: SENSOR_OK,
    mav.FAILURE_TYPE_OFF: OFF,
    mav.FAILURE_TYPE_STUCK: STUCK,
}
FORCE_VALUES = (FORCE_MAGIC, 2989)


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


class CommandHost(Protocol):
    """What the commands act on and answer through: the server of one vehicle
    (:class:`~.server.MavlinkServer`, which runs them)."""

    vehicle: Vehicle
    identity: Identity
    encoder: Any  # pymavlink's MAVLink, for the messages sent after the ACK
    motors: MotorSlot  # the vehicle's part of the motor path
    schedules: dict[int, T.Schedule]  # link id -> its telemetry schedule
    without_hil_state: set[int]  # link ids whose motor answers leave HIL_STATE out
    after_ack: list[Any]  # messages to send after the COMMAND_ACK

    def statustext(self, severity: int, text: str, echo: bool = True) -> None: ...

    def snapshot(self) -> Snapshot: ...

    def hil_state(self, link: Link) -> bool: ...


class Commands:
    """The MAV_CMDs the vehicle runs; anything else is UNSUPPORTED."""

    def __init__(self, server: CommandHost) -> None:
        self.server = server
        self.table = self._table()

    def run(self, cmd: Command, link: Link) -> Result:
        runner = self.table.get(cmd.id)
        if runner is None:
            return Result(Outcome.UNSUPPORTED)
        try:
            return runner(cmd, link)
        except ValueError as error:
            return Result(Outcome.DENIED, str(error))

    def _table(self) -> dict[int, Callable[[Command, Link], Result]]:
        return {
            mav.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm_disarm,
            mav.MAV_CMD_NAV_TAKEOFF: self._cmd_takeoff,
            mav.MAV_CMD_NAV_LAND: lambda c, link: self.server.vehicle.land(),
            mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: lambda c, link: (
                self.server.vehicle.return_to_launch()
            ),
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
            mav.MAV_CMD_DO_SET_MISSION_CURRENT: lambda c, link: (
                self.server.vehicle.set_mission_current(_int(c.params[0], "item"))
            ),
            mav.MAV_CMD_DO_CHANGE_SPEED: self._cmd_change_speed,
            mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: self._cmd_reboot,
            mav.MAV_CMD_INJECT_FAILURE: self._cmd_inject_failure,
            RESET_STATE: self._cmd_reset_state,
            STAGE_MOTION: lambda c, link: self.server.motors.stage_motion(c.params),
            STAGE_AIRFRAME: lambda c, link: self.server.motors.stage_airframe(c.params),
        }

    def _cmd_arm_disarm(self, c: Command, link: Link) -> Result:
        force = math.isfinite(c.params[1]) and round(c.params[1]) in FORCE_VALUES
        if c.params[0] == 1:
            return self.server.vehicle.arm(force)
        if c.params[0] == 0:
            return self.server.vehicle.disarm(force)
        return Result(Outcome.DENIED, f"arm/disarm: param1 must be 0 or 1, got {c.params[0]}")

    def _cmd_takeoff(self, c: Command, link: Link) -> Result:
        """Param7: AMSL for the PX4 identity (NaN: MIS_TAKEOFF_ALT), relative to home for
        the generic one; COMMAND_INT says which by its frame. An AMSL altitude below the
        ground is what MAVProxy and other ArduPilot-style clients send as a height above
        home: it is read so, with a message."""
        v = self.server.vehicle
        altitude = c.params[6]
        if math.isnan(altitude):
            return v.takeoff(None)
        if c.is_int:
            amsl = c.frame in (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT)
        else:
            amsl = self.server.identity.takeoff_param7_amsl
        if amsl and altitude < v.origin.altitude:
            self.server.statustext(
                Severity.INFO,
                f"take-off altitude {altitude:g} m is below the "
                "ground as AMSL: taken as metres above home",
            )
            amsl = False
        return v.takeoff(altitude - v.home_altitude if amsl else altitude)

    def _cmd_set_home(self, c: Command, link: Link) -> Result:
        """DO_SET_HOME: param1 = 1 the current position, else params 5-7 (AMSL)."""
        v = self.server.vehicle
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
            self.server.after_ack.append(pose.build_home_position(self.server.snapshot()))
        return result

    def _cmd_set_mode(self, c: Command, link: Link) -> Result:
        base, main, sub = c.params[0], c.params[1], c.params[2]
        if not int(base) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return Result(Outcome.DENIED, "set mode: only custom (PX4-layout) modes are supported")
        sub = 0 if math.isnan(sub) else sub
        return self.server.vehicle.set_mode(
            Mode.from_custom(_int(main, "main mode"), _int(sub, "sub mode"))
        )

    def _cmd_reposition(self, c: Command, link: Link) -> Result:
        speed, yaw_deg, lat, lon, alt = (
            c.params[0],
            c.params[3],
            c.params[4],
            c.params[5],
            c.params[6],
        )
        v = self.server.vehicle
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
        return self.server.vehicle.reposition(east, north, up, speed if speed_ok else None, yaw)

    def _cmd_message_interval(self, c: Command, link: Link) -> Result:
        message_id, interval_us = _int(c.params[0], "message id"), c.params[1]
        if message_id == mav.MAVLINK_MSG_ID_HEARTBEAT:
            return ACCEPTED  # always 1 Hz
        if message_id == mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION:  # in motor answers only
            if interval_us < 0:
                self.server.without_hil_state.add(id(link))
            else:
                self.server.without_hil_state.discard(id(link))
            return ACCEPTED
        if message_id not in T.BUILDERS:
            return Result(Outcome.UNSUPPORTED, f"message {message_id} is not streamed")
        schedule = self.server.schedules[id(link)]
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
            self.server.after_ack.append(
                status.build_heartbeat(self.server.vehicle, self.server.identity.autopilot)
            )
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
        self.server.after_ack.extend(
            available_modes_message(self.server.encoder, i) for i in indices
        )
        return ACCEPTED

    def _cmd_get_message_interval(self, c: Command, link: Link) -> Result:
        return self._message_interval(_int(c.params[0], "message id"), link)

    def _message_interval(self, message_id: int, link: Link) -> Result:
        """MESSAGE_INTERVAL: µs between sends on this link; -1 not sent, 0 unknown id."""
        if message_id == mav.MAVLINK_MSG_ID_HEARTBEAT:
            interval_us = round(T.HEARTBEAT_PERIOD * 1e6)
        elif message_id in T.BUILDERS or message_id in T.DEFAULT_RATES:
            seconds = self.server.schedules[id(link)].intervals.get(message_id)
            interval_us = -1 if seconds is None else round(seconds * 1e6)
        else:
            interval_us = 0
        self.server.after_ack.append(
            self.server.encoder.message_interval_encode(message_id, interval_us)
        )
        return ACCEPTED

    def _send_once(self, message_id: int, link: Link) -> Result:
        builder = T.BUILDERS.get(message_id)
        if builder is None:
            return Result(Outcome.UNSUPPORTED)
        self.server.after_ack.append(builder(self.server.snapshot()))
        return ACCEPTED

    def _cmd_mission_start(self, c: Command, link: Link) -> Result:
        first = c.params[0]
        if math.isfinite(first) and first > 0:
            result = self.server.vehicle.set_mission_current(int(first))
            if not result.ok:
                return result
        return self.server.vehicle.set_mode(Mode.MISSION)

    def _cmd_change_speed(self, c: Command, link: Link) -> Result:
        speed = c.params[1]
        if not (math.isfinite(speed) and speed > 0):
            return Result(Outcome.DENIED, f"change speed: {speed} m/s is not a speed")
        self.server.vehicle.flight.change_speed(speed)
        return ACCEPTED

    def _cmd_reboot(self, c: Command, link: Link) -> Result:
        if c.params[0] != 1:
            return Result(Outcome.UNSUPPORTED)
        if self.server.vehicle.armed:
            return Result(Outcome.DENIED, "reboot denied: disarm first")
        self.server.vehicle.reboot()
        return ACCEPTED

    def _sensor_failure(self, sensor: str, kind: int, instance: int) -> Result:
        """A sensor (there is one of each: instance 0 or 1) stuck, off, or back to OK."""
        failure = SENSOR_FAILURES.get(kind)
        if failure is None:
            name = _enum_name("FAILURE_TYPE", kind)
            return Result(Outcome.UNSUPPORTED, f"{sensor} {name} not simulated: OK, OFF, STUCK")
        if instance not in (0, 1):
            return Result(Outcome.DENIED, f"{sensor} {instance} does not exist: there is one")
        v = self.server.vehicle
        v.sensors.fail(sensor, failure)
        state = FAILURE_NAMES[failure]
        severity = Severity.NOTICE if failure == SENSOR_OK else Severity.CRITICAL
        v.event(severity, f"{sensor} {state} (failure injection)")
        return ACCEPTED

    def _cmd_inject_failure(self, c: Command, link: Link) -> Result:
        """PX4's failure injection, guarded by SYS_FAILURE_EN: param1 the unit, param2 the
        type, param3 the instance (the motor, 1-based; 0 every one). Motors: OK
        restores, OFF stops, WRONG leaves it param4 (0 < η < 1) of its thrust. The
        gyroscope, accelerometer, magnetometer, barometer and GPS: OK, OFF, STUCK."""
        v = self.server.vehicle
        if not v.params["SYS_FAILURE_EN"]:
            return Result(Outcome.DENIED, "failure injection off (SYS_FAILURE_EN 0)")
        unit, kind = _int(c.params[0], "failure unit"), _int(c.params[1], "failure type")
        if unit in SENSOR_UNITS:
            return self._sensor_failure(SENSOR_UNITS[unit], kind, _int(c.params[2], "instance"))
        if unit != mav.FAILURE_UNIT_SYSTEM_MOTOR:
            name = _enum_name("FAILURE_UNIT", unit)
            return Result(Outcome.UNSUPPORTED, f"{name} failure not simulated")
        if kind not in (mav.FAILURE_TYPE_OK, mav.FAILURE_TYPE_OFF, mav.FAILURE_TYPE_WRONG):
            name = _enum_name("FAILURE_TYPE", kind)
            return Result(Outcome.UNSUPPORTED, f"motor {name} not simulated: OK, OFF, WRONG")
        motor = _int(c.params[2], "motor instance")
        which = "every motor" if motor == 0 else f"motor {motor}"
        if kind == mav.FAILURE_TYPE_OK:
            v.motors.restore(motor)
            v.event(Severity.NOTICE, f"{which} restored (failure injection)")
            return ACCEPTED
        efficiency = 0.0
        if kind == mav.FAILURE_TYPE_WRONG:
            efficiency = c.params[3]
            if not (math.isfinite(efficiency) and 0.0 < efficiency < 1.0):
                raise ValueError(f"motor WRONG: param4 (thrust left) not in (0, 1): {efficiency:g}")
        v.motors.inject(motor, efficiency)
        state = "off" if efficiency == 0.0 else f"at {efficiency:.0%} thrust"
        v.event(Severity.CRITICAL, f"{which} {state} (failure injection)")
        return ACCEPTED

    def _cmd_reset_state(self, c: Command, link: Link) -> Result:
        result = self.server.motors.reset(c.params)
        if result.ok:
            self.server.after_ack.extend(
                self.server.motors.state_messages(self.server.hil_state(link))
            )
        return result


def _enum_name(enum: str, value: int) -> str:
    """The MAVLink name of ``value`` in ``enum`` (its number if it has none)."""
    entry = mav.enums[enum].get(value)
    return entry.name if entry is not None else f"{enum} {value}"


def _int(value: float, what: str) -> int:
    if not math.isfinite(value):
        raise ValueError(f"{what} must be a number, got {value}")
    return round(value)
