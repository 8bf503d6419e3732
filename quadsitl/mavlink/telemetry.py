"""Telemetry: what the vehicle reports, converted to MAVLink's frames and units here.

One ``build_*`` function per message. World ENU -> local NED, body FLU -> FRD, through
:mod:`quadsitl.frames` only. The sensor messages (HIGHRES_IMU, SCALED_IMU, RAW_IMU,
SCALED_PRESSURE) and ODOMETRY are streamed on request only; the sensor messages and
GPS_RAW_INT carry the vehicle's sensor models (:mod:`quadsitl.physics.sensors`: noise,
bias, GPS latency); the pose and velocity messages (ATTITUDE, ATTITUDE_QUATERNION,
LOCAL_POSITION_NED, GLOBAL_POSITION_INT, VFR_HUD, ODOMETRY) what the flight software
knows: the truth, or with EKF2_EN = 1 the onboard estimate (ODOMETRY then with its
covariance, :mod:`.estimate`).
Rates are per link and per message (SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM), paced
by simulated time; the heartbeat is paced by the wall
clock so that ground stations keep the link even when simulated time stands still.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from functools import cached_property
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.mavlink import mavlink as mav
from quadsitl.mavlink.degrade import SLOWEST_RATE
from quadsitl.mavlink.estimate import build_estimate_odometry
from quadsitl.mavlink.identity import (
    AVAILABLE_MODES,
    CUSTOM_VERSION,
    IDENTITIES,
    MIDDLEWARE_VERSION,
    Identity,
)
from quadsitl.mavlink.motor_path import STANDARD_GRAVITY
from quadsitl.physics import dryden as D
from quadsitl.physics import layout as L
from quadsitl.physics.sensors import environment as E
from quadsitl.physics.sensors.gps import FIX_3D
from quadsitl.vehicle.modes import MAIN_AUTO, MAIN_OFFBOARD, MAIN_POSCTL, Mode
from quadsitl.vehicle.vehicle import Vehicle
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.answer import UNUSED_OUTPUTS, odometry_values
from quadsitl.wire.state import WireState
from quadsitl.wire.units import to_time_usec

_encoder = mav.MAVLink(None)

# SYS_STATUS sensor bits reported present, enabled and healthy.
SENSORS = (
    mav.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mav.MAV_SYS_STATUS_SENSOR_GPS
    | mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mav.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mav.MAV_SYS_STATUS_SENSOR_BATTERY
    | mav.MAV_SYS_STATUS_PREARM_CHECK
)
CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
# The SYS_STATUS health bit of each sensor that can fail (failures.SENSORS).
SENSOR_HEALTH = {
    "gyro": mav.MAV_SYS_STATUS_SENSOR_3D_GYRO,
    "accel": mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
    "mag": mav.MAV_SYS_STATUS_SENSOR_3D_MAG,
    "baro": mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
    "gps": mav.MAV_SYS_STATUS_SENSOR_GPS,
}
HEARTBEAT_PERIOD = 1.0  # s, wall clock
# HIGHRES_IMU fields_updated bits (HIGHRES_IMU_UPDATED_FLAGS).
HIGHRES_ACCEL, HIGHRES_GYRO, HIGHRES_MAG = 0x007, 0x038, 0x1C0
HIGHRES_BARO = 0x200 | 0x800 | 0x1000  # absolute pressure, pressure altitude, temperature
HIGHRES_DIFF_PRESSURE = 0x400


class Snapshot:
    """The vehicle's state in wire frames and units, computed once per telemetry tick."""

    def __init__(
        self,
        vehicle: Vehicle,
        comm_errors: int = 0,
        error_counts: tuple[int, ...] = (0,) * 4,
        identity: Identity = IDENTITIES["px4"],
        resets: int = 0,
    ) -> None:
        self.vehicle = vehicle
        self.identity = identity
        self.resets = resets  # state resets through the motor path (ODOMETRY reset_counter)
        self.comm_errors = min(comm_errors, 65535)  # malformed frames received
        self.error_counts = [min(n, 65535) for n in error_counts]  # signing, motor commands
        s = vehicle.nav_state  # the truth itself unless EKF2_EN selects the estimate
        self.time_boot_ms = int(vehicle.time * 1000) & 0xFFFFFFFF
        self.time_usec = to_time_usec(vehicle.time)
        # Local origin: the start position on the ground (the resting centre of mass is
        # gear height up); the conversion is WireState's, shared with the motor path.
        wire = WireState.from_physics(s, vehicle.airframe.gear_height, self.time_usec, 0, 0.0)
        self.position_ned = wire.position_ned  # m
        self.velocity_ned = frames.enu_to_ned(s[L.VEL])  # m/s
        self.velocity_frd = wire.velocity_frd  # m/s, body
        self.q_ned_frd = wire.q_ned_frd  # (w, x, y, z)
        self.roll, self.pitch, self.yaw = frames.euler_from_quat(self.q_ned_frd).tolist()
        self.rates_frd = wire.rates_frd  # rad/s
        self.rotor_speeds = wire.rotor_speeds  # rad/s
        self.lat, self.lon, self.alt_amsl = wire.global_position(vehicle.origin)
        up = -float(self.position_ned[2])
        self.relative_alt = up - float(vehicle.home_position[2])  # m above home
        self.heading_deg = math.degrees(self.yaw) % 360.0
        self.ground_speed = math.hypot(self.velocity_ned[0], self.velocity_ned[1])

    # --- the sensors (read only when a sensor message is built) -------------------------
    @cached_property
    def specific_force_frd(self) -> np.ndarray:
        """The accelerometer, m/s², body FRD: specific force, (0, 0, −g) at rest."""
        return frames.flu_to_frd(self.vehicle.sensors.accel)

    @cached_property
    def gyro_frd(self) -> np.ndarray:
        """The gyroscope, rad/s, body FRD."""
        return frames.flu_to_frd(self.vehicle.sensors.gyro)

    @cached_property
    def magnetic_field_frd(self) -> np.ndarray:
        """The magnetometer, gauss, body FRD: the Earth's field at home (WMM)."""
        return frames.flu_to_frd(self.vehicle.sensors.magnetic_field)

    @cached_property
    def wind_ned(self) -> np.ndarray:
        """The air's velocity at the vehicle, m/s, local NED (mean wind, turbulence and
        gust; 0 in still air)."""
        return frames.enu_to_ned(self.vehicle.fleet.air_velocity[0])

    @cached_property
    def airspeed(self) -> float:
        """Speed through the air, m/s (the ground speed in still air)."""
        return float(np.linalg.norm(self.velocity_ned - self.wind_ned))

    @cached_property
    def air(self) -> tuple[float, float, float]:
        """(static pressure hPa, differential pressure hPa, temperature °C): the
        barometer's, and the dynamic pressure ½ρv² of the speed through the air."""
        sensors = self.vehicle.sensors
        density = sensors.pressure / (E.AIR_GAS_CONSTANT * sensors.temperature)  # kg/m³
        dynamic = 0.5 * density * self.airspeed**2 / 100
        return sensors.pressure / 100, dynamic, sensors.temperature - 273.15

    @cached_property
    def highres_fields(self) -> int:
        """HIGHRES_IMU fields_updated: the sensors that sampled since the last one built
        for this vehicle (once per snapshot: every link sending it in this tick agrees)."""
        imu, mag, baro, _ = self.vehicle.sensors.fresh()
        bits = HIGHRES_DIFF_PRESSURE  # computed from the state at each message
        bits |= (HIGHRES_ACCEL | HIGHRES_GYRO) if imu else 0
        bits |= HIGHRES_MAG if mag else 0
        bits |= HIGHRES_BARO if baro else 0
        return bits

    @cached_property
    def gps(self) -> dict[str, Any]:
        """The GPS receiver's latest fix, with its position on the globe (lat, lon deg,
        alt m AMSL of the ground-level point, as GLOBAL_POSITION_INT) and NED velocity."""
        fix = self.vehicle.sensors.gps()
        east, north, up = fix["position"]
        gear = self.vehicle.airframe.gear_height
        fix["lat"], fix["lon"], fix["alt"] = self.vehicle.origin.to_global(
            float(east), float(north), float(up) - gear
        )
        fix["velocity_ned"] = frames.enu_to_ned(fix["velocity"])
        return fix


def build_heartbeat(v: Vehicle, autopilot: int = mav.MAV_AUTOPILOT_PX4) -> Any:
    main = v.mode.value[0]
    base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_STABILIZE_ENABLED
    if main in (MAIN_AUTO,):
        base |= mav.MAV_MODE_FLAG_AUTO_ENABLED | mav.MAV_MODE_FLAG_GUIDED_ENABLED
    if main in (MAIN_POSCTL, MAIN_OFFBOARD):
        base |= mav.MAV_MODE_FLAG_GUIDED_ENABLED
    if v.armed:
        base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
    if v.motor_control:
        base |= mav.MAV_MODE_FLAG_HIL_ENABLED
    if v.crashed:
        status = mav.MAV_STATE_CRITICAL
    else:
        status = mav.MAV_STATE_ACTIVE if v.armed else mav.MAV_STATE_STANDBY
    return _encoder.heartbeat_encode(
        mav.MAV_TYPE_QUADROTOR, autopilot, base, v.mode.custom_mode, status
    )


def build_sys_status(s: Snapshot) -> Any:
    """Sensors present, enabled and healthy (MAVSDK's health checks read them). The
    geofence bit is present and enabled when a fence is set, and unhealthy while it is
    breached (MAVProxy announces "fence breach" whenever the health bit is clear)."""
    v = s.vehicle
    fence = mav.MAV_SYS_STATUS_GEOFENCE
    fenced = v.params["GF_MAX_HOR_DIST"] > 0 or v.params["GF_MAX_VER_DIST"] > 0
    present = SENSORS | (fence if fenced else 0)
    health = SENSORS | fence
    for sensor, bit in SENSOR_HEALTH.items():  # a sensor that failed off is unhealthy
        if v.sensors.off(sensor):
            health &= ~bit
    if v.crashed:
        health &= ~mav.MAV_SYS_STATUS_PREARM_CHECK
    if v.failsafes.fence_breached:
        health &= ~fence
    return _encoder.sys_status_encode(
        present,
        present,
        health,
        100,
        int(v.battery.voltage * 1000),
        int(v.battery.current * 100),
        int(v.battery.remaining * 100),
        0,
        s.comm_errors,
        *s.error_counts,
    )


def build_extended_sys_state(s: Snapshot) -> Any:
    return _encoder.extended_sys_state_encode(mav.MAV_VTOL_STATE_UNDEFINED, s.vehicle.landed_state)


def build_attitude(s: Snapshot) -> Any:
    r = s.rates_frd
    return _encoder.attitude_encode(s.time_boot_ms, s.roll, s.pitch, s.yaw, r[0], r[1], r[2])


def build_attitude_quaternion(s: Snapshot) -> Any:
    q, r = s.q_ned_frd, s.rates_frd
    return _encoder.attitude_quaternion_encode(
        s.time_boot_ms, q[0], q[1], q[2], q[3], r[0], r[1], r[2], [0.0] * 4
    )


def build_local_position_ned(s: Snapshot) -> Any:
    p, v = s.position_ned, s.velocity_ned
    return _encoder.local_position_ned_encode(s.time_boot_ms, p[0], p[1], p[2], v[0], v[1], v[2])


def build_global_position_int(s: Snapshot) -> Any:
    v = s.velocity_ned * 100.0  # cm/s
    return _encoder.global_position_int_encode(
        s.time_boot_ms,
        round(s.lat * 1e7),
        round(s.lon * 1e7),
        round(s.alt_amsl * 1000),
        round(s.relative_alt * 1000),
        round(v[0]),
        round(v[1]),
        round(v[2]),
        round(s.heading_deg * 100) % 36000,
    )


def build_gps_raw_int(s: Snapshot) -> Any:
    """The GPS receiver's fix, as PX4 fills GPS_RAW_INT: eph/epv are the dilutions of
    precision × 100, h_acc/v_acc/vel_acc the 1-σ accuracies (mm, mm/s)."""
    g = s.gps
    vn, ve = (float(x) for x in g["velocity_ned"][:2])
    speed = math.hypot(vn, ve)
    course = round(math.degrees(math.atan2(ve, vn)) % 360 * 100)
    fixed = g["fix_type"] == FIX_3D
    return _encoder.gps_raw_int_encode(
        s.time_usec,
        g["fix_type"],
        round(g["lat"] * 1e7) if fixed else 0,
        round(g["lon"] * 1e7) if fixed else 0,
        round(g["alt"] * 1000) if fixed else 0,
        min(round(g["hdop"] * 100), 65534) if fixed else 65535,
        min(round(g["vdop"] * 100), 65534) if fixed else 65535,
        round(speed * 100) if fixed else 65535,
        course if fixed and speed > 0.2 else 65535,
        g["satellites"],
        h_acc=min(round(g["eph"] * 1000), 2**32 - 1),
        v_acc=min(round(g["epv"] * 1000), 2**32 - 1),
        vel_acc=min(round(g["speed_accuracy"] * 1000), 2**32 - 1),
    )


def build_home_position(s: Snapshot) -> Any:
    v = s.vehicle
    lat, lon, alt = v.origin.to_global(*v.home_position)
    north, east, down = frames.enu_to_ned(v.home_position)  # local NED, m
    return _encoder.home_position_encode(
        latitude=round(lat * 1e7),
        longitude=round(lon * 1e7),
        altitude=round(alt * 1000),
        x=float(north),
        y=float(east),
        z=float(down),
        q=[1.0, 0.0, 0.0, 0.0],
        approach_x=0.0,
        approach_y=0.0,
        approach_z=0.0,
        time_usec=s.time_usec,
    )


def build_vfr_hud(s: Snapshot) -> Any:
    v = s.vehicle
    throttle = round(100 * float(np.mean(v.rotor_cmd)) / v.airframe.max_rotor_speed)
    return _encoder.vfr_hud_encode(
        s.airspeed,
        s.ground_speed,
        round(s.heading_deg) % 360,
        throttle,
        s.alt_amsl,
        -float(s.velocity_ned[2]),
    )


def build_battery_status(s: Snapshot) -> Any:
    b = s.vehicle.battery
    cells = [round(b.voltage / b.cells * 1000)] * b.cells + [65535] * (10 - b.cells)
    return _encoder.battery_status_encode(
        0,
        mav.MAV_BATTERY_FUNCTION_ALL,
        mav.MAV_BATTERY_TYPE_LIPO,
        32767,
        cells,
        round(b.current * 100),
        round(b.used_mah),
        -1,
        round(b.remaining * 100),
    )


def build_servo_output_raw(s: Snapshot) -> Any:
    v = s.vehicle
    pwm = [
        round(1000 + 1000 * c / v.airframe.max_rotor_speed) if v.armed else 1000
        for c in v.rotor_cmd
    ]
    return _encoder.servo_output_raw_encode(s.time_usec & 0xFFFFFFFF, 0, *pwm, 0, 0, 0, 0)


def build_actuator_output_status(s: Snapshot) -> Any:
    speeds = [float(w) for w in s.rotor_speeds] + list(UNUSED_OUTPUTS)  # rad/s, measured
    return _encoder.actuator_output_status_encode(s.time_usec, 0b1111, speeds)


def build_system_time(s: Snapshot) -> Any:
    return _encoder.system_time_encode(int(time.time() * 1e6), s.time_boot_ms)


def mission_state(v: Vehicle) -> int:
    """MISSION_CURRENT's mission_state (MAVSDK's is_mission_finished waits for COMPLETE)."""
    runner = v.missions
    if not runner.items:
        return mav.MISSION_STATE_NO_MISSION
    if runner.finished:
        return mav.MISSION_STATE_COMPLETE
    if v.mode is Mode.MISSION:
        return mav.MISSION_STATE_ACTIVE
    return mav.MISSION_STATE_PAUSED if runner.started else mav.MISSION_STATE_NOT_STARTED


def build_mission_current(s: Snapshot) -> Any:
    v = s.vehicle
    in_mission = int(v.mode is Mode.MISSION)
    return _encoder.mission_current_encode(
        v.mission_current, len(v.mission), mission_state(v), in_mission
    )


def build_autopilot_version(s: Snapshot) -> Any:
    return _encoder.autopilot_version_encode(
        capabilities=CAPABILITIES,
        flight_sw_version=s.identity.flight_sw_version,
        middleware_sw_version=MIDDLEWARE_VERSION,
        os_sw_version=0,
        board_version=0,
        flight_custom_version=list(CUSTOM_VERSION),
        middleware_custom_version=[0] * 8,
        os_custom_version=[0] * 8,
        vendor_id=0,
        product_id=0,
        uid=0x5153_4954_4C00_0001,
    )


def build_odometry(s: Snapshot) -> Any:
    """The motor path's ODOMETRY (local NED pose, body FRD velocity and rates); with
    EKF2_EN = 1 the estimate's, with its covariance."""
    if s.vehicle.estimator.enabled:
        return build_estimate_odometry(s)
    values = odometry_values(
        s.time_usec,
        s.position_ned.tolist(),
        s.q_ned_frd.tolist(),
        s.velocity_frd.tolist(),
        s.rates_frd.tolist(),
        s.resets,
    )
    return FC.message(mav.MAVLink_odometry_message, values)


def build_highres_imu(s: Snapshot) -> Any:
    """SI units: m/s², rad/s, gauss, hPa, m, °C; body FRD."""
    f, w, m = s.specific_force_frd, s.gyro_frd, s.magnetic_field_frd
    pressure, differential, temperature = s.air
    return _encoder.highres_imu_encode(
        s.time_usec,
        *(float(x) for x in f),
        *(float(x) for x in w),
        *(float(x) for x in m),
        pressure,
        differential,
        s.vehicle.sensors.pressure_altitude,
        temperature,
        s.highres_fields,
    )


def _imu_integers(s: Snapshot) -> list[int]:
    """Accelerometer mG, gyroscope mrad/s, magnetometer mgauss (body FRD), int16."""
    mg = s.specific_force_frd / STANDARD_GRAVITY * 1000
    values = [*mg, *(s.gyro_frd * 1000), *(s.magnetic_field_frd * 1000)]
    return [int(max(-32767, min(32767, round(float(x))))) for x in values]


def build_scaled_imu(s: Snapshot) -> Any:
    return _encoder.scaled_imu_encode(s.time_boot_ms, *_imu_integers(s), round(s.air[2] * 100))


def build_raw_imu(s: Snapshot) -> Any:
    """There are no sensor counts: the values of SCALED_IMU (mG, mrad/s, mgauss), as
    ArduPilot fills RAW_IMU."""
    return _encoder.raw_imu_encode(s.time_usec, *_imu_integers(s), 0, round(s.air[2] * 100))


def build_wind_cov(s: Snapshot) -> Any:
    """The wind at the vehicle, as PX4 sends its estimate (QGroundControl shows its speed
    and the direction it blows from). Here it is the truth: the air's velocity (NED, m/s)
    and the turbulence's variance about the mean wind (m²/s²) at the vehicle's height."""
    weather = s.vehicle.fleet.winds[0]
    height = max(-float(s.position_ned[2]), 0.0)
    sigma_u, sigma_v, sigma_w = (float(x) for x in D.intensities(height, weather.sigma_w))
    north, east, down = (float(x) for x in s.wind_ned)
    return _encoder.wind_cov_encode(
        s.time_usec,
        north,
        east,
        down,
        sigma_u**2 + sigma_v**2,
        sigma_w**2,
        s.alt_amsl,
        0.0,
        0.0,
    )


def build_scaled_pressure(s: Snapshot) -> Any:
    """The barometer: hPa, the differential pressure hPa, cdegC."""
    pressure, differential, temperature = s.air
    return _encoder.scaled_pressure_encode(
        s.time_boot_ms, pressure, differential, round(temperature * 100)
    )


def build_current_mode(s: Snapshot) -> Any:
    v = s.vehicle
    standard = next((e.standard_mode for e in AVAILABLE_MODES if e.mode is v.mode), 0)
    return _encoder.current_mode_encode(standard, v.mode.custom_mode, v.mode.custom_mode)


BUILDERS: dict[int, Callable[[Snapshot], Any]] = {
    mav.MAVLINK_MSG_ID_SYS_STATUS: build_sys_status,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: build_extended_sys_state,
    mav.MAVLINK_MSG_ID_ATTITUDE: build_attitude,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: build_attitude_quaternion,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: build_local_position_ned,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: build_global_position_int,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: build_gps_raw_int,
    mav.MAVLINK_MSG_ID_HOME_POSITION: build_home_position,
    mav.MAVLINK_MSG_ID_VFR_HUD: build_vfr_hud,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: build_battery_status,
    mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: build_servo_output_raw,
    mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: build_actuator_output_status,
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: build_system_time,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: build_mission_current,
    mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION: build_autopilot_version,
    mav.MAVLINK_MSG_ID_CURRENT_MODE: build_current_mode,
    mav.MAVLINK_MSG_ID_WIND_COV: build_wind_cov,
    # On request only (SET_MESSAGE_INTERVAL, REQUEST_MESSAGE): not in DEFAULT_RATES.
    mav.MAVLINK_MSG_ID_ODOMETRY: build_odometry,
    mav.MAVLINK_MSG_ID_HIGHRES_IMU: build_highres_imu,
    mav.MAVLINK_MSG_ID_SCALED_IMU: build_scaled_imu,
    mav.MAVLINK_MSG_ID_RAW_IMU: build_raw_imu,
    mav.MAVLINK_MSG_ID_SCALED_PRESSURE: build_scaled_pressure,
}

# Default rates, Hz (the spec's typical rates; position and attitude at 50 Hz).
DEFAULT_RATES: dict[int, float] = {
    mav.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    mav.MAVLINK_MSG_ID_ATTITUDE: 50.0,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 50.0,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: 5.0,
    mav.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    mav.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 10.0,
    mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: 10.0,
    mav.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    mav.MAVLINK_MSG_ID_WIND_COV: 1.0,
}

FASTEST_INTERVAL = 1.0 / max(DEFAULT_RATES.values())  # s, of the fastest default stream

# REQUEST_DATA_STREAM groups (ArduPilot/MAVProxy convention) -> message ids.
DATA_STREAMS: dict[int, tuple[int, ...]] = {
    mav.MAV_DATA_STREAM_EXTENDED_STATUS: (
        mav.MAVLINK_MSG_ID_SYS_STATUS,
        mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
        mav.MAVLINK_MSG_ID_GPS_RAW_INT,
        mav.MAVLINK_MSG_ID_MISSION_CURRENT,
    ),
    mav.MAV_DATA_STREAM_RC_CHANNELS: (mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,),
    mav.MAV_DATA_STREAM_RAW_CONTROLLER: (mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS,),
    mav.MAV_DATA_STREAM_POSITION: (
        mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
        mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    ),
    mav.MAV_DATA_STREAM_EXTRA1: (
        mav.MAVLINK_MSG_ID_ATTITUDE,
        mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
    ),
    mav.MAV_DATA_STREAM_EXTRA2: (mav.MAVLINK_MSG_ID_VFR_HUD,),
    mav.MAV_DATA_STREAM_EXTRA3: (
        mav.MAVLINK_MSG_ID_SYSTEM_TIME,
        mav.MAVLINK_MSG_ID_BATTERY_STATUS,
        mav.MAVLINK_MSG_ID_HOME_POSITION,
    ),
}
DATA_STREAMS[mav.MAV_DATA_STREAM_ALL] = tuple(m for ids in DATA_STREAMS.values() for m in ids)


class Schedule:
    """Per-link message intervals (s of simulated time) and when each is next due.

    ``streams=False`` starts with every stream off (the motor-command link). ``offset``
    (s) delays each message's first time: a fleet spreads its vehicles' messages over
    the fastest stream's interval instead of sending them all at once. ``slowdown``
    (set with :meth:`slow_down`) stretches every interval while the real-time loop is
    short of time (:mod:`.degrade`); ``intervals`` keep the rates asked for."""

    def __init__(self, streams: bool = True, offset: float = 0.0) -> None:
        rates = DEFAULT_RATES if streams else {}
        self.offset = offset
        self.slowdown = 1.0
        self.intervals: dict[int, float] = {m: 1.0 / hz for m, hz in rates.items()}
        self.next_due: dict[int, float] = {}
        self.last_wall: dict[int, float] = {}
        self._earliest = -math.inf  # simulated s: nothing is due before it
        self._last_now = math.inf  # simulated s of the last look

    def set_rate(self, message_id: int, hz: float | None) -> None:
        """Rate in Hz; 0 or negative stops the message; None restores the default."""
        if hz is None:
            if message_id in DEFAULT_RATES:
                self.intervals[message_id] = 1.0 / DEFAULT_RATES[message_id]
            else:
                self.intervals.pop(message_id, None)
        elif hz <= 0:
            self.intervals.pop(message_id, None)
        else:
            self.intervals[message_id] = 1.0 / hz
        self.next_due.pop(message_id, None)
        self._earliest = -math.inf

    def slow_down(self, factor: float) -> None:
        """Send every stream ``factor`` times less often, but none below SLOWEST_RATE
        (nor below its own rate); 1 restores the rates asked for."""
        if factor != self.slowdown:
            self.slowdown = factor
            self._earliest = -math.inf

    def _interval(self, interval: float) -> float:
        """``interval`` as slowed down now."""
        if self.slowdown == 1.0:
            return interval
        return max(interval, min(interval * self.slowdown, 1.0 / SLOWEST_RATE))

    def due(self, now: float, wall_now: float | None = None) -> list[int]:
        """Message ids due at simulated time ``now``; advances their next due time.

        With ``wall_now`` (lockstep, possibly far faster than real time) a message is
        also held back until its interval has passed on the wall clock."""
        if self._last_now <= now < self._earliest:
            return []  # nothing due yet (most calls): no need to look at each message
        self._last_now = now
        out = []
        for message_id, asked in self.intervals.items():
            interval = self._interval(asked)
            due = self.next_due.get(message_id)
            if due is None:
                due = self.next_due[message_id] = now + self.offset
            if due - now > interval:  # simulated time went back (reboot, reset)
                due = now
            if now >= due and wall_now is not None:
                if wall_now - self.last_wall.get(message_id, -math.inf) < interval:
                    continue
                self.last_wall[message_id] = wall_now
            if now >= due:
                out.append(message_id)
                # Keep the phase, but never queue a backlog after a pause.
                self.next_due[message_id] = max(due + interval, now + 0.5 * interval)
        self._earliest = min(
            (self.next_due.get(m, -math.inf) for m in self.intervals), default=math.inf
        )
        return out
