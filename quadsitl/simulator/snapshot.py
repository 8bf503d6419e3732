"""The vehicle's state in the wire's frames and units, computed once per telemetry tick.

Every telemetry message of a tick is built from one :class:`Snapshot` (the
``telemetry_*`` modules, ODOMETRY's covariance in :mod:`.estimate`): world ENU -> local
NED, body FLU -> FRD, through :mod:`quadsitl.frames` and the conversion the motor path
shares (:class:`~quadsitl.wire.state.WireState`). The sensors are read only when a
sensor message asks for them. What it reports is finite: a state or a sensor reading
with NaN or beyond :data:`REPORT_BOUND` (a diverged physics) is reported with NaN as 0
and the rest clamped (:func:`~quadsitl.wire.fit.finite`).
"""

from __future__ import annotations

import math
from functools import cached_property
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.physics import layout as L
from quadsitl.physics.sensors import environment as E
from quadsitl.simulator.identity import IDENTITIES, Identity
from quadsitl.wire.fit import finite
from quadsitl.wire.state import WireState
from quadsitl.wire.units import to_time_usec

# HIGHRES_IMU fields_updated bits (HIGHRES_IMU_UPDATED_FLAGS).
HIGHRES_ACCEL, HIGHRES_GYRO, HIGHRES_MAG = 0x007, 0x038, 0x1C0
HIGHRES_BARO = 0x200 | 0x800 | 0x1000  # absolute pressure, pressure altitude, temperature
HIGHRES_DIFF_PRESSURE = 0x400
# The largest state or sensor value reported (m, m/s, rad/s, m/s², ...): no flight comes
# near it, and a square of it (dynamic pressure, variances) still fits a float32 field.
REPORT_BOUND = 1e15


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
        # The truth itself unless EKF2_EN selects the estimate.
        s = finite(vehicle.nav_state, REPORT_BOUND)
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
        return frames.flu_to_frd(finite(self.vehicle.sensors.accel, REPORT_BOUND))

    @cached_property
    def gyro_frd(self) -> np.ndarray:
        """The gyroscope, rad/s, body FRD."""
        return frames.flu_to_frd(finite(self.vehicle.sensors.gyro, REPORT_BOUND))

    @cached_property
    def magnetic_field_frd(self) -> np.ndarray:
        """The magnetometer, gauss, body FRD: the Earth's field at home (WMM)."""
        return frames.flu_to_frd(finite(self.vehicle.sensors.magnetic_field, REPORT_BOUND))

    @cached_property
    def wind_ned(self) -> np.ndarray:
        """The air's velocity at the vehicle, m/s, local NED (mean wind, turbulence and
        gust; 0 in still air)."""
        return frames.enu_to_ned(finite(self.vehicle.fleet.air_velocity[0], REPORT_BOUND))

    @cached_property
    def airspeed(self) -> float:
        """Speed through the air, m/s (the ground speed in still air)."""
        return float(np.linalg.norm(self.velocity_ned - self.wind_ned))

    @cached_property
    def air(self) -> tuple[float, float, float]:
        """(static pressure hPa, differential pressure hPa, temperature °C): the
        barometer's, and the dynamic pressure ½ρv² of the speed through the air."""
        sensors = self.vehicle.sensors
        pressure, temperature = np.float64(sensors.pressure), np.float64(sensors.temperature)
        with np.errstate(all="ignore"):  # a diverged state: made finite below
            density = pressure / (E.AIR_GAS_CONSTANT * temperature)  # kg/m³
            dynamic = 0.5 * density * self.airspeed**2 / 100
            values = np.array([pressure / 100, dynamic, temperature - 273.15])
        hpa, differential, celsius = finite(values, REPORT_BOUND).tolist()
        return hpa, differential, celsius

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
