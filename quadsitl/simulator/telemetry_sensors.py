"""Telemetry of the sensors: GPS_RAW_INT, HIGHRES_IMU, SCALED_IMU, RAW_IMU,
SCALED_PRESSURE (the vehicle's sensor models, :mod:`quadsitl.physics.sensors`: noise,
bias, GPS latency), and WIND_COV (the air at the vehicle). Body FRD, local NED. One
``build_*`` function per message; when each is sent is :mod:`.telemetry`'s (all but
GPS_RAW_INT and WIND_COV on request only). Integers are rounded with
:func:`~quadsitl.wire.fit.wire_int` (saturated at their field's limits when packed).
"""

from __future__ import annotations

import math
from typing import Any

from quadsitl.physics import dryden as D
from quadsitl.physics.sensors.gps import FIX_3D
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.fit import wire_int
from quadsitl.wire.units import STANDARD_GRAVITY

_encoder = mav.MAVLink(None)


def build_gps_raw_int(s: Snapshot) -> Any:
    """The GPS receiver's fix, as PX4 fills GPS_RAW_INT: eph/epv are the dilutions of
    precision × 100, h_acc/v_acc/vel_acc the 1-σ accuracies (mm, mm/s)."""
    g = s.gps
    vn, ve = (float(x) for x in g["velocity_ned"][:2])
    speed = math.hypot(vn, ve)
    course = wire_int(math.degrees(math.atan2(ve, vn)) % 360 * 100)
    fixed = g["fix_type"] == FIX_3D
    return _encoder.gps_raw_int_encode(
        s.time_usec,
        g["fix_type"],
        wire_int(g["lat"] * 1e7) if fixed else 0,
        wire_int(g["lon"] * 1e7) if fixed else 0,
        wire_int(g["alt"] * 1000) if fixed else 0,
        min(wire_int(g["hdop"] * 100), 65534) if fixed else 65535,
        min(wire_int(g["vdop"] * 100), 65534) if fixed else 65535,
        min(wire_int(speed * 100), 65534) if fixed else 65535,
        course if fixed and speed > 0.2 else 65535,
        g["satellites"],
        h_acc=wire_int(g["eph"] * 1000),
        v_acc=wire_int(g["epv"] * 1000),
        vel_acc=wire_int(g["speed_accuracy"] * 1000),
    )


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
    return [max(-32767, min(32767, wire_int(float(x)))) for x in values]


def build_scaled_imu(s: Snapshot) -> Any:
    return _encoder.scaled_imu_encode(s.time_boot_ms, *_imu_integers(s), wire_int(s.air[2] * 100))


def build_raw_imu(s: Snapshot) -> Any:
    """There are no sensor counts: the values of SCALED_IMU (mG, mrad/s, mgauss), as
    ArduPilot fills RAW_IMU."""
    return _encoder.raw_imu_encode(s.time_usec, *_imu_integers(s), 0, wire_int(s.air[2] * 100))


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
        s.time_boot_ms, pressure, differential, wire_int(temperature * 100)
    )
