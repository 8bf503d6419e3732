"""What a flight looks like: MAVLink messages of one vehicle -> samples for the Rerun scene.

Used row by row by the live viewer and column by column by the replay. Works with
whatever a log holds: position from LOCAL_POSITION_NED (or ODOMETRY, or
GLOBAL_POSITION_INT until a local one appears), attitude from ATTITUDE_QUATERNION (or
ODOMETRY, HIL_STATE_QUATERNION, ATTITUDE), rotors from ACTUATOR_OUTPUT_STATUS or
SERVO_OUTPUT_RAW, battery from BATTERY_STATUS or SYS_STATUS, setpoints from
POSITION_TARGET_LOCAL_NED / SET_POSITION_TARGET_LOCAL_NED and ATTITUDE_TARGET, GPS from
GPS_RAW_INT and GLOBAL_POSITION_INT (``map/track``), the wind from WIND_COV, the flight
state from HEARTBEAT and MISSION_CURRENT, the simulator's truth beside an estimate from
SIM_STATE (``altitude_truth``, ``roll_truth`` …, the true track); messages it does not
know are ignored. Angles
are in degrees, unwrapped (continuous through ±180°). Frames: see
:mod:`quadsitl.viz.scene` (ENU on screen).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.geo import Home
from quadsitl.viz.scene import WIND_ARROW_SCALE, pose_from_ned, quat_xyzw
from quadsitl.wire.dialect import mavlink as M
from quadsitl.wire.modes import Mode, mode_string
from quadsitl.wire.units import STANDARD_GRAVITY

# M is the project's dialect, not mavutil.mavlink: that one is MAVLink 1's (no ODOMETRY)
# unless MAVLINK20 was set in the environment before pymavlink was imported.

GCS_TYPE = 6  # MAV_TYPE_GCS
SEVERITY = ["CRITICAL"] * 3 + ["ERROR", "WARN", "INFO", "INFO", "DEBUG"]  # MAV_SEVERITY 0..7


@dataclass
class Sample:
    """``kind``: translation (3,), rotation (xyzw), scalar, point (3,), arrow (origin and
    vector, (6,)), geo (lat, lon in degrees), text, or truth (3,): where the vehicle
    really was (ENU, m, the local frame), a point of its true track."""

    entity: str
    kind: str
    value: Any
    level: str = "INFO"


@dataclass
class FlightView:
    vehicle: tuple[int, int] | None = None  # (system, component) of the vehicle
    home: Home | None = None
    home_local_enu: np.ndarray = field(default_factory=lambda: np.zeros(3))
    mission: dict[int, np.ndarray] = field(default_factory=dict)  # seq -> ENU point
    mission_changed: bool = False
    seen: set[str] = field(default_factory=set)
    last_mode: tuple[bool, str] | None = None
    hover_rotor: float = 1.0  # rotor value at hover (rad/s for quadsitl); 1: raw values
    last_angle: dict[str, float] = field(default_factory=dict)  # entity -> last degrees
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))  # m, ENU: the latest
    windy: bool = False  # a WIND_COV with moving air has been seen
    handlers: dict[int, Callable[[Any], list[Sample]]] = field(
        init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        self.handlers = {  # message id: the samples of a message from the vehicle
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self._local_position_ned,
            M.MAVLINK_MSG_ID_ODOMETRY: self._odometry,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self._global_position_int,
            M.MAVLINK_MSG_ID_HOME_POSITION: self._home_position,
            M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self._attitude_quaternion,
            M.MAVLINK_MSG_ID_HIL_STATE_QUATERNION: self._hil_state_quaternion,
            M.MAVLINK_MSG_ID_SIM_STATE: self._sim_state,
            M.MAVLINK_MSG_ID_ATTITUDE: self._attitude,
            M.MAVLINK_MSG_ID_ATTITUDE_TARGET: self._attitude_target,
            M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: self._position_target_local_ned,
            M.MAVLINK_MSG_ID_MISSION_CURRENT: self._mission_current,
            M.MAVLINK_MSG_ID_GPS_RAW_INT: self._gps_raw_int,
            M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: self._actuator_output_status,
            M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: self._servo_output_raw,
            M.MAVLINK_MSG_ID_BATTERY_STATUS: self._battery_status,
            M.MAVLINK_MSG_ID_SYS_STATUS: self._sys_status,
            M.MAVLINK_MSG_ID_WIND_COV: self._wind_cov,
            M.MAVLINK_MSG_ID_HIGHRES_IMU: self._highres_imu,
            M.MAVLINK_MSG_ID_SCALED_IMU: self._scaled_imu,
            M.MAVLINK_MSG_ID_SCALED_PRESSURE: self._scaled_pressure,
            M.MAVLINK_MSG_ID_STATUSTEXT: self._statustext,
        }

    def samples(self, msg: Any, own: bool = False) -> list[Sample]:
        """Samples of one message; ``own``: built by the simulator itself (no header)."""
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            return self._heartbeat(msg, own)
        if kind in ("SET_POSITION_TARGET_LOCAL_NED", "MISSION_ITEM_INT", "MISSION_ITEM"):
            return self._from_anyone(kind, msg)  # either direction: GCS or vehicle
        if not own and not self._from_vehicle(msg):
            return []
        handler = self.handlers.get(msg.get_msgId())
        if handler is None:
            return []
        self.seen.add(kind)
        out = list(handler(msg))
        for sample in out:
            if sample.kind == "translation":
                self.position = sample.value
        return out

    # --- whose message ----------------------------------------------------------------
    def _from_vehicle(self, msg: Any) -> bool:
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if self.vehicle is None:
            return source[0] != 255  # before its heartbeat: anything but a ground station
        return source == self.vehicle

    def _heartbeat(self, msg: Any, own: bool = False) -> list[Sample]:
        """The flight-state band at every heartbeat (armed 0/1, 2 on the current mode's
        series, NaN ending the previous mode's), and an event when it changes."""
        if not own:
            source = (msg.get_srcSystem(), msg.get_srcComponent())
            if self.vehicle is None and msg.type != GCS_TYPE and msg.autopilot != 8:
                self.vehicle = source
            if source != self.vehicle:
                return []
        armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        state = (armed, _mode_name(msg))
        out = state_samples(self.last_mode, state)
        self.last_mode = state
        return out

    def _angle(self, entity: str, radians: float) -> Sample:
        """Degrees, continuous with the entity's previous sample (unwrapped)."""
        value = math.degrees(radians)
        last = self.last_angle.get(entity)
        if last is not None and math.isfinite(value):
            value += 360.0 * round((last - value) / 360.0)
        if math.isfinite(value):
            self.last_angle[entity] = value
        return Sample(entity, "scalar", value)

    def _from_anyone(self, kind: str, msg: Any) -> list[Sample]:
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            if msg.coordinate_frame != M.MAV_FRAME_LOCAL_NED:
                return []
            return self._position_target(msg)
        if getattr(msg, "mission_type", 0) != 0 or self.home is None:
            return []
        scale = 1e-7 if kind == "MISSION_ITEM_INT" else 1.0
        if msg.x == 0 and msg.y == 0:  # e.g. take-off, land here, RTL
            return []
        relative = msg.frame in (3, 6)  # GLOBAL_RELATIVE_ALT(_INT)
        up = msg.z if relative else msg.z - self.home.altitude
        east, north, _ = self.home.to_local(msg.x * scale, msg.y * scale, self.home.altitude)
        self.mission[msg.seq] = np.array([east, north, up])
        self.mission_changed = True
        return []

    # --- the vehicle's telemetry (one method per message) -----------------------------
    def _local_position_ned(self, msg: Any) -> list[Sample]:
        position = frames.ned_to_enu([msg.x, msg.y, msg.z])
        velocity = frames.ned_to_enu([msg.vx, msg.vy, msg.vz])
        return [
            Sample("world/vehicle", "translation", position),
            *_altitude_velocity(position, velocity),
        ]

    def _odometry(self, msg: Any) -> list[Sample]:
        out = []
        if "LOCAL_POSITION_NED" not in self.seen:
            translation, _ = pose_from_ned([msg.x, msg.y, msg.z], msg.q)
            out.append(Sample("world/vehicle", "translation", translation))
        if "ATTITUDE_QUATERNION" not in self.seen:
            out.append(Sample("world/vehicle", "rotation", pose_from_ned([0, 0, 0], msg.q)[1]))
        return out

    def _global_position_int(self, msg: Any) -> list[Sample]:
        if msg.lat == 0 and msg.lon == 0:
            return []  # no position yet (ArduPilot's before its GPS and EKF have one)
        if self.home is None:
            self.home = Home(msg.lat * 1e-7, msg.lon * 1e-7, (msg.alt - msg.relative_alt) * 1e-3)
        geo = Sample("map/track", "geo", (msg.lat * 1e-7, msg.lon * 1e-7))
        if "LOCAL_POSITION_NED" in self.seen or "ODOMETRY" in self.seen:
            return [geo]
        east, north, _ = self.home.to_local(msg.lat * 1e-7, msg.lon * 1e-7, self.home.altitude)
        position = np.array([east, north, msg.relative_alt * 1e-3])
        velocity = frames.ned_to_enu([msg.vx * 0.01, msg.vy * 0.01, msg.vz * 0.01])
        return [
            geo,
            Sample("world/vehicle", "translation", position),
            *_altitude_velocity(position, velocity),
        ]

    def _home_position(self, msg: Any) -> list[Sample]:
        self.home = Home(msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3)
        self.home_local_enu = frames.ned_to_enu([msg.x, msg.y, msg.z])
        return []

    def _attitude_quaternion(self, msg: Any) -> list[Sample]:
        q = [msg.q1, msg.q2, msg.q3, msg.q4]
        return [Sample("world/vehicle", "rotation", pose_from_ned([0, 0, 0], q)[1])]

    def _hil_state_quaternion(self, msg: Any) -> list[Sample]:
        if {"ATTITUDE_QUATERNION", "ODOMETRY"} & self.seen:
            return []
        q = msg.attitude_quaternion
        return [Sample("world/vehicle", "rotation", pose_from_ned([0, 0, 0], q)[1])]

    def _sim_state(self, msg: Any) -> list[Sample]:
        """The simulator's truth: attitude and body rates, velocity and, once the home is
        known (the local frame's place on the globe), the true position."""
        out = [
            self._angle(f"plots/attitude/{name}_truth", value)
            for name, value in (("roll", msg.roll), ("pitch", msg.pitch), ("yaw", msg.yaw))
        ]
        for name, value in (("roll", msg.xgyro), ("pitch", msg.ygyro), ("yaw", msg.zgyro)):
            out.append(Sample(f"plots/rates/{name}_truth", "scalar", math.degrees(value)))
        velocity = frames.ned_to_enu([msg.vn, msg.ve, msg.vd])
        out.append(Sample("plots/climb_rate/climb_truth", "scalar", float(velocity[2])))
        out.append(Sample("plots/velocity/east_truth", "scalar", float(velocity[0])))
        out.append(Sample("plots/velocity/north_truth", "scalar", float(velocity[1])))
        lat, lon = (msg.lat_int * 1e-7, msg.lon_int * 1e-7) if msg.lat_int else (msg.lat, msg.lon)
        if self.home is not None and math.isfinite(msg.alt):
            east, north, up = self.home.to_local(lat, lon, msg.alt)
            position = np.array([east, north, up]) + self.home_local_enu
            out.append(Sample("plots/altitude/altitude_truth", "scalar", float(position[2])))
            out.append(Sample("world/trajectory_truth", "truth", position))
        return out

    def _attitude(self, msg: Any) -> list[Sample]:
        out = [
            self._angle(f"plots/attitude/{name}", value)
            for name, value in (("roll", msg.roll), ("pitch", msg.pitch), ("yaw", msg.yaw))
        ]
        out += [
            Sample(f"plots/rates/{name}", "scalar", math.degrees(value))
            for name, value in (
                ("roll", msg.rollspeed),
                ("pitch", msg.pitchspeed),
                ("yaw", msg.yawspeed),
            )
        ]
        if not {"ATTITUDE_QUATERNION", "ODOMETRY", "HIL_STATE_QUATERNION"} & self.seen:
            q_ned = frames.quat_from_euler(msg.roll, msg.pitch, msg.yaw)
            out.append(
                Sample(
                    "world/vehicle", "rotation", quat_xyzw(frames.quat_ned_frd_to_enu_flu(q_ned))
                )
            )
        return out

    def _attitude_target(self, msg: Any) -> list[Sample]:
        if msg.type_mask & 128:  # ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
            return []
        roll, pitch, yaw = frames.euler_from_quat(np.asarray(msg.q, dtype=np.float64)).tolist()
        return [
            self._angle(f"plots/attitude/{name}_setpoint", value)
            for name, value in (("roll", roll), ("pitch", pitch), ("yaw", yaw))
        ]

    def _position_target_local_ned(self, msg: Any) -> list[Sample]:
        if msg.coordinate_frame != M.MAV_FRAME_LOCAL_NED:
            return []
        return self._position_target(msg)

    def _position_target(self, msg: Any) -> list[Sample]:
        """Altitude, climb-rate and velocity setpoints (and the commanded point) of a local
        target."""
        out = []
        if not msg.type_mask & 7:  # position given
            point = frames.ned_to_enu([msg.x, msg.y, msg.z])
            out.append(Sample("world/setpoint", "point", point))
            out.append(Sample("plots/altitude/setpoint", "scalar", float(point[2])))
        if not msg.type_mask & 0x20 and math.isfinite(msg.vz):  # vz given
            out.append(Sample("plots/climb_rate/setpoint", "scalar", -float(msg.vz)))
        if not msg.type_mask & 0x18 and math.isfinite(msg.vx) and math.isfinite(msg.vy):
            out.append(Sample("plots/velocity/east_setpoint", "scalar", float(msg.vy)))
            out.append(Sample("plots/velocity/north_setpoint", "scalar", float(msg.vx)))
        return out

    def _mission_current(self, msg: Any) -> list[Sample]:
        return [Sample("plots/mission_item/seq", "scalar", float(msg.seq))]

    def _gps_raw_int(self, msg: Any) -> list[Sample]:
        out = [Sample("plots/gps/fix_type", "scalar", float(msg.fix_type))]
        if msg.satellites_visible != 255:
            out.append(Sample("plots/gps/satellites", "scalar", float(msg.satellites_visible)))
        if "GLOBAL_POSITION_INT" not in self.seen and msg.fix_type >= 2:
            out.append(Sample("map/track", "geo", (msg.lat * 1e-7, msg.lon * 1e-7)))
        return out

    def _actuator_output_status(self, msg: Any) -> list[Sample]:
        count = bin(msg.active).count("1") or 4
        return [
            Sample(f"plots/rotors/rotor_{i + 1}", "scalar", msg.actuator[i] / self.hover_rotor)
            for i in range(min(count, 8))
        ]

    def _servo_output_raw(self, msg: Any) -> list[Sample]:
        return [
            Sample(f"plots/servo_pwm/{i}", "scalar", getattr(msg, f"servo{i}_raw"))
            for i in range(1, 5)
        ]

    def _battery_status(self, msg: Any) -> list[Sample]:
        cells = [v for v in msg.voltages if v not in (0, 65535)]
        out = []
        if msg.battery_remaining >= 0:
            out.append(Sample("plots/battery_remaining/percent", "scalar", msg.battery_remaining))
        if cells:
            out.append(Sample("plots/battery_voltage/voltage", "scalar", sum(cells) / 1000))
        return out

    def _sys_status(self, msg: Any) -> list[Sample]:
        if "BATTERY_STATUS" in self.seen or msg.voltage_battery in (0, 65535):
            return []
        return [Sample("plots/battery_voltage/voltage", "scalar", msg.voltage_battery / 1000)]

    def _wind_cov(self, msg: Any) -> list[Sample]:
        """The air's velocity at the vehicle: its speed and parts (ENU) in the wind panel,
        and an arrow at the vehicle, WIND_ARROW_SCALE m per m/s, the way the air blows.
        Nothing until the air moves (PX4 and quadsitl send WIND_COV in still air too)."""
        east, north, up = frames.ned_to_enu([msg.wind_x, msg.wind_y, msg.wind_z])
        if not self.windy and east == north == up == 0.0:
            return []
        self.windy = True
        air = np.array([east, north, up], dtype=np.float64)
        return [
            Sample("plots/wind/speed", "scalar", float(np.linalg.norm(air))),
            Sample("plots/wind/east", "scalar", float(east)),
            Sample("plots/wind/north", "scalar", float(north)),
            Sample("plots/wind/up", "scalar", float(up)),
            Sample("world/wind", "arrow", np.concatenate([self.position, air * WIND_ARROW_SCALE])),
        ]

    def _highres_imu(self, msg: Any) -> list[Sample]:
        """What the sensors read (body FRD): specific force m/s², rates in deg/s, and
        the barometer's pressure in hPa."""
        accel, rates = (msg.xacc, msg.yacc, msg.zacc), (msg.xgyro, msg.ygyro, msg.zgyro)
        pressure = Sample("plots/barometer/pressure", "scalar", float(msg.abs_pressure))
        return [*_imu_samples(accel, rates), pressure]

    def _scaled_imu(self, msg: Any) -> list[Sample]:
        """The same in mG and mrad/s (ArduPilot's and older logs), unless HIGHRES_IMU
        says it already."""
        if "HIGHRES_IMU" in self.seen:
            return []
        g = STANDARD_GRAVITY / 1000.0
        accel = (msg.xacc * g, msg.yacc * g, msg.zacc * g)
        return _imu_samples(accel, (msg.xgyro / 1e3, msg.ygyro / 1e3, msg.zgyro / 1e3))

    def _scaled_pressure(self, msg: Any) -> list[Sample]:
        if "HIGHRES_IMU" in self.seen:
            return []
        return [Sample("plots/barometer/pressure", "scalar", float(msg.press_abs))]

    def _statustext(self, msg: Any) -> list[Sample]:
        level = SEVERITY[min(max(msg.severity, 0), 7)]
        return [Sample("events", "text", str(msg.text).rstrip("\x00"), level)]


def state_samples(last: tuple[bool, str] | None, state: tuple[bool, str]) -> list[Sample]:
    """The flight-state band's samples at a report of ``state`` = (armed, mode name)
    after ``last`` (None: the first): armed 0/1, 2 on the current mode's series (NaN
    ending the previous mode's), and an event when the state changes. The same for
    every source: heartbeats, a ULog's vehicle_status, a DataFlash log's MODE and ARM."""
    armed, mode = state
    out = []
    if last is not None and state != last:
        was_armed, was_mode = last
        out.append(Sample("plots/state/armed", "scalar", float(was_armed)))
        if was_mode != mode:
            old_band = f"plots/state/mode/{was_mode}"
            out += [Sample(old_band, "scalar", 2.0), Sample(old_band, "scalar", math.nan)]
    out += [
        Sample("plots/state/armed", "scalar", float(armed)),
        Sample(f"plots/state/mode/{mode}", "scalar", 2.0),
    ]
    if state != last:
        out.append(Sample("events", "text", f"{'ARMED' if armed else 'disarmed'}, mode {mode}"))
    return out


def _imu_samples(accel: tuple, rates: tuple) -> list[Sample]:
    """Accelerometer (m/s²) and gyroscope (rad/s in, deg/s out) series, body FRD."""
    out = [
        Sample(f"plots/accelerometer/{axis}", "scalar", float(value))
        for axis, value in zip("xyz", accel, strict=True)
    ]
    out += [
        Sample(f"plots/gyroscope/{axis}", "scalar", math.degrees(value))
        for axis, value in zip("xyz", rates, strict=True)
    ]
    return out


def _altitude_velocity(position: np.ndarray, velocity: np.ndarray) -> list[Sample]:
    return [
        Sample("plots/altitude/altitude", "scalar", float(position[2])),
        Sample("plots/climb_rate/climb", "scalar", float(velocity[2])),
        Sample("plots/velocity/east", "scalar", float(velocity[0])),
        Sample("plots/velocity/north", "scalar", float(velocity[1])),
    ]


def _mode_name(msg: Any) -> str:
    """PX4-layout custom modes (PX4 and quadsitl), else pymavlink's names (ArduPilot...)."""
    if msg.autopilot in (M.MAV_AUTOPILOT_PX4, M.MAV_AUTOPILOT_GENERIC):
        try:
            return Mode.from_custom_mode(msg.custom_mode).name
        except ValueError:
            pass
    return mode_string(msg)
