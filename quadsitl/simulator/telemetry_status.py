"""Telemetry of the vehicle's condition: HEARTBEAT (armed, mode), SYS_STATUS (sensor
health, battery, errors), EXTENDED_SYS_STATE, BATTERY_STATUS, the motor outputs
(SERVO_OUTPUT_RAW, ACTUATOR_OUTPUT_STATUS), SYSTEM_TIME, MISSION_CURRENT,
AUTOPILOT_VERSION and CURRENT_MODE. One ``build_*`` function per message; when each is
sent is :mod:`.telemetry`'s. Integers from the physics (battery, motor outputs) are
rounded with :func:`~quadsitl.wire.fit.wire_int` (saturated when packed).
"""

from __future__ import annotations

import time
from typing import Any

from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.simulator.identity import AVAILABLE_MODES, CUSTOM_VERSION, MIDDLEWARE_VERSION
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.wire.answer import UNUSED_OUTPUTS
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.fit import wire_int
from quadsitl.wire.modes import MAIN_AUTO, MAIN_OFFBOARD, MAIN_POSCTL, Mode

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
        wire_int(v.battery.voltage * 1000),
        wire_int(v.battery.current * 100),
        wire_int(v.battery.remaining * 100),
        0,
        s.comm_errors,
        *s.error_counts,
    )


def build_extended_sys_state(s: Snapshot) -> Any:
    return _encoder.extended_sys_state_encode(mav.MAV_VTOL_STATE_UNDEFINED, s.vehicle.landed_state)


def build_battery_status(s: Snapshot) -> Any:
    b = s.vehicle.battery
    cells = [min(wire_int(b.voltage / b.cells * 1000), 65534)] * b.cells + [65535] * (10 - b.cells)
    return _encoder.battery_status_encode(
        0,
        mav.MAV_BATTERY_FUNCTION_ALL,
        mav.MAV_BATTERY_TYPE_LIPO,
        32767,
        cells,
        wire_int(b.current * 100),
        wire_int(b.used_mah),
        -1,
        wire_int(b.remaining * 100),
    )


def build_servo_output_raw(s: Snapshot) -> Any:
    v = s.vehicle
    pwm = [
        wire_int(1000 + 1000 * c / v.airframe.max_rotor_speed) if v.armed else 1000
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


def build_current_mode(s: Snapshot) -> Any:
    v = s.vehicle
    standard = next((e.standard_mode for e in AVAILABLE_MODES if e.mode is v.mode), 0)
    return _encoder.current_mode_encode(standard, v.mode.custom_mode, v.mode.custom_mode)
