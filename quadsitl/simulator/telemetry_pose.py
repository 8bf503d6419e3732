"""Telemetry of where the vehicle is and how it moves, as the flight software knows it
(the truth, or with EKF2_EN = 1 the onboard estimate): ATTITUDE, ATTITUDE_QUATERNION,
LOCAL_POSITION_NED, GLOBAL_POSITION_INT, HOME_POSITION, VFR_HUD and ODOMETRY (the
estimate's, with its covariance: :mod:`.estimate`); and SIM_STATE, the simulator's truth
beside an estimate (as ArduPilot's SITL sends it). One ``build_*`` function per message;
when each is sent is :mod:`.telemetry`'s. Integers are rounded with
:func:`~quadsitl.wire.fit.wire_int` (saturated at their field's limits when packed).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.physics import layout as L
from quadsitl.simulator.estimate import build_estimate_odometry
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.answer import odometry_values
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.fit import finite, wire_int
from quadsitl.wire.state import WireState

_encoder = mav.MAVLink(None)


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


def build_sim_state(s: Snapshot) -> Any:
    """SIM_STATE: the true attitude (quaternion and Euler angles, NED/FRD), body rates,
    position (lat, lon in degrees and 1e-7 degrees, alt m AMSL) and velocity (NED)
    whatever the flight software flies on; accelerations unknown (NaN)."""
    vehicle = s.vehicle
    state = finite(vehicle.state, 1e15)
    wire = WireState.from_physics(state, vehicle.airframe.gear_height, s.time_usec, 0, 0.0)
    q, r = wire.q_ned_frd, wire.rates_frd
    roll, pitch, yaw = frames.euler_from_quat(q).tolist()
    lat, lon, alt = wire.global_position(vehicle.origin)
    v = frames.enu_to_ned(state[L.VEL])
    nan = float("nan")
    return _encoder.sim_state_encode(
        q[0], q[1], q[2], q[3], roll, pitch, yaw, nan, nan, nan, r[0], r[1], r[2],
        lat, lon, alt, 0.0, 0.0, v[0], v[1], v[2], wire_int(lat * 1e7), wire_int(lon * 1e7),
    )  # fmt: skip


def build_global_position_int(s: Snapshot) -> Any:
    v = s.velocity_ned * 100.0  # cm/s
    return _encoder.global_position_int_encode(
        s.time_boot_ms,
        wire_int(s.lat * 1e7),
        wire_int(s.lon * 1e7),
        wire_int(s.alt_amsl * 1000),
        wire_int(s.relative_alt * 1000),
        wire_int(v[0]),
        wire_int(v[1]),
        wire_int(v[2]),
        wire_int(s.heading_deg * 100) % 36000,
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
    throttle = wire_int(100 * float(np.mean(v.rotor_cmd)) / v.airframe.max_rotor_speed)
    return _encoder.vfr_hud_encode(
        s.airspeed,
        s.ground_speed,
        wire_int(s.heading_deg) % 360,
        throttle,
        s.alt_amsl,
        -float(s.velocity_ned[2]),
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
