"""An offboard policy's action as the autopilot's own setpoint: the three action levels of
the flight-stack envs, each a message PX4 (OFFBOARD) and ArduPilot (GUIDED) accept.

Actions are normalised to [−1, 1] per component; this module scales them and writes the
MAVLink message in the wire's frames (NED/FRD). No IO here.

* ``velocity``: east, north, up velocity and yaw rate, as SET_POSITION_TARGET_LOCAL_NED
  (velocity and yaw rate; the rest ignored);
* ``attitude``: roll, pitch, yaw and collective thrust, as SET_ATTITUDE_TARGET
  (quaternion and thrust);
* ``rates``: body roll, pitch and yaw rates (FLU) and collective thrust, as
  SET_ATTITUDE_TARGET (body rates and thrust, the attitude ignored).

Thrust: action 0 is the airframe's hover thrust, −1 none, +1 full.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.wire.dialect import mavlink as mav

LEVELS = ("velocity", "attitude", "rates")
MAX_SPEED_XY = 2.0  # m/s at |action| 1
MAX_SPEED_Z = 1.0  # m/s
MAX_YAW_RATE = 1.0  # rad/s
MAX_TILT = 0.5  # rad, roll and pitch
MAX_RATE_RP = 3.0  # rad/s
MAX_RATE_YAW = 2.0  # rad/s

_IGNORE_ALL_BUT_VELOCITY_AND_YAW_RATE = (
    mav.POSITION_TARGET_TYPEMASK_X_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_Z_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_YAW_IGNORE
)
_POSITION_AND_YAW = (
    mav.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_VZ_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)


def check_level(level: str) -> str:
    if level not in LEVELS:
        raise ValueError(f"action level {level!r} is not one of {LEVELS}")
    return level


def thrust(a: float, hover: float) -> float:
    """Collective thrust (fraction of full) of action ``a``: 0 hovers, −1 none, +1 full."""
    a = min(1.0, max(-1.0, a))
    return hover * (1.0 + a) if a < 0 else hover + a * (1.0 - hover)


def message(
    link: Any, level: str, action: np.ndarray, time_ms: int, hover: float, system: int = 1
) -> Any:
    """The setpoint message of ``action`` (4,) at ``level``, encoded by ``link`` (a
    pymavlink MAVLink object), stamped ``time_ms`` (the autopilot's clock), for the
    autopilot of MAVLink system ``system``."""
    a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    if level == "velocity":
        east, north, up = a[0] * MAX_SPEED_XY, a[1] * MAX_SPEED_XY, a[2] * MAX_SPEED_Z
        yaw_rate_down = -a[3] * MAX_YAW_RATE  # ENU about up -> NED about down
        return link.set_position_target_local_ned_encode(
            time_ms, system, 1, mav.MAV_FRAME_LOCAL_NED, _IGNORE_ALL_BUT_VELOCITY_AND_YAW_RATE,
            0, 0, 0, north, east, -up, 0, 0, 0, 0, yaw_rate_down,
        )  # fmt: skip
    collective = thrust(float(a[3]), hover)
    if level == "attitude":
        q_enu = frames.quat_from_euler(a[0] * MAX_TILT, a[1] * MAX_TILT, a[2] * math.pi)
        return attitude_message(link, q_enu, collective, time_ms, system)
    check_level(level)
    rates = frames.flu_to_frd(
        np.array([a[0] * MAX_RATE_RP, a[1] * MAX_RATE_RP, a[2] * MAX_RATE_YAW])
    )
    ignore = mav.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
    return link.set_attitude_target_encode(
        time_ms, system, 1, ignore, [1.0, 0.0, 0.0, 0.0], *rates, collective
    )


def position_message(
    link: Any, east_north_up: np.ndarray, yaw_enu: float, time_ms: int, system: int = 1
) -> Any:
    """A position setpoint (local NED) holding heading ``yaw_enu``: how a reset flies the
    vehicle to an episode's start under the autopilot's own position control."""
    east, north, up = (float(v) for v in east_north_up)
    return link.set_position_target_local_ned_encode(
        time_ms, system, 1, mav.MAV_FRAME_LOCAL_NED, _POSITION_AND_YAW,
        north, east, -up, 0, 0, 0, 0, 0, 0, float(frames.yaw_enu_to_ned(yaw_enu)), 0,
    )  # fmt: skip


def attitude_message(
    link: Any, q_enu_flu: np.ndarray, collective: float, time_ms: int, system: int = 1
) -> Any:
    """An attitude setpoint (body FLU in world ENU, as quadsitl's state holds it) with
    collective thrust 0..1: the attitude level's message, and how a reset tilts the
    vehicle to an episode's drawn attitude."""
    q = frames.quat_enu_flu_to_ned_frd(np.asarray(q_enu_flu, dtype=np.float64))
    ignore = 0b111  # body rates
    return link.set_attitude_target_encode(time_ms, system, 1, ignore, q, 0, 0, 0, collective)
