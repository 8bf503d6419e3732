"""Offboard setpoints off the wire: SET_POSITION_TARGET_LOCAL_NED and SET_ATTITUDE_TARGET
decoded into the controller's :class:`~quadsitl.flight_software.controller.Setpoint`.

The wire is NED/FRD, the vehicle ENU/FLU; the conversions go through :mod:`quadsitl.frames`.
Each decoder returns a Setpoint, or a string saying why the message is ignored (NaN or
inf in a field that is used, an unsupported frame, a zero quaternion).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.flight_software.controller import Setpoint
from quadsitl.wire.dialect import mavlink as mav

POSITION = (
    mav.POSITION_TARGET_TYPEMASK_X_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_Z_IGNORE
)
VELOCITY = (
    mav.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_VZ_IGNORE
)
ACCELERATION = (
    mav.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mav.POSITION_TARGET_TYPEMASK_AZ_IGNORE
)
YAW = mav.POSITION_TARGET_TYPEMASK_YAW_IGNORE
YAW_RATE = mav.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
# The per-axis ignore bits, in the order of the fields they cover.
AXIS_BITS = (
    mav.POSITION_TARGET_TYPEMASK_X_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_Y_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_Z_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_VX_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_VY_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_VZ_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_AX_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_AY_IGNORE,
    mav.POSITION_TARGET_TYPEMASK_AZ_IGNORE,
)
BODY_FRAMES = (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
LOCAL_FRAMES = (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_OFFSET_NED)
OFFSET_FRAMES = (mav.MAV_FRAME_LOCAL_OFFSET_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
RATE_BITS = (
    mav.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE,
    mav.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE,
    mav.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE,
)


def position_target(
    msg: Any, position: np.ndarray, yaw_now: float, gear_height: float
) -> Setpoint | str:
    """SET_POSITION_TARGET_LOCAL_NED. ``position``: the vehicle's (3,) ENU position (for
    offset frames); ``yaw_now``: its heading, ENU rad (for body frames)."""
    mask = msg.type_mask
    values = (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, msg.afx, msg.afy, msg.afz)
    used = [v for bit, v in zip(AXIS_BITS, values, strict=True) if not mask & bit]
    used += [v for bit, v in ((YAW, msg.yaw), (YAW_RATE, msg.yaw_rate)) if not mask & bit]
    if not all(math.isfinite(v) for v in used):
        return "offboard setpoint with NaN or inf ignored"
    frame = msg.coordinate_frame
    body = frame in BODY_FRAMES
    if not body and frame not in LOCAL_FRAMES:
        return f"offboard frame {frame} unsupported: use LOCAL_NED or BODY_NED"
    heading = frames.quat_from_axis_angle([0.0, 0.0, 1.0], yaw_now)

    def to_enu(ned: tuple[float, float, float]) -> np.ndarray:
        if body:  # x forward, y right, z down, turned with the vehicle's heading
            return frames.quat_rotate(heading, frames.frd_to_flu(np.array(ned)))
        return frames.ned_to_enu(np.array(ned))

    setpoint = Setpoint()
    if not mask & POSITION:
        target = to_enu((msg.x, msg.y, msg.z))
        if frame in OFFSET_FRAMES:
            target = target + position
        else:
            target[2] += gear_height  # NED z is the ground-level frame's
        setpoint.position = target
    if not mask & VELOCITY:
        setpoint.velocity = to_enu((msg.vx, msg.vy, msg.vz))
    if not mask & ACCELERATION:
        setpoint.acceleration = to_enu((msg.afx, msg.afy, msg.afz))
    if not mask & YAW:
        setpoint.yaw = float(frames.yaw_ned_to_enu(msg.yaw))
    if not mask & YAW_RATE:
        setpoint.yaw_rate = -msg.yaw_rate  # NED (about down) -> ENU (about up)
    return setpoint


def attitude_target(msg: Any) -> Setpoint | str:
    """SET_ATTITUDE_TARGET: quaternion NED/FRD and/or body rates FRD, thrust 0..1."""
    mask = msg.type_mask
    rates = (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate)
    if not all(math.isfinite(x) for x in (*msg.q, msg.thrust, *rates)):
        return "attitude setpoint with NaN or inf ignored"
    setpoint = Setpoint(thrust=float(np.clip(msg.thrust, 0.0, 1.0)))
    ignore_attitude = mask & mav.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
    if not ignore_attitude:
        q = np.array(msg.q, dtype=np.float64)
        if np.linalg.norm(q) < 1e-6:
            return "attitude setpoint with a zero quaternion ignored"
        setpoint.attitude = frames.quat_ned_frd_to_enu_flu(q / np.linalg.norm(q))
    if ignore_attitude or not any(mask & bit for bit in RATE_BITS):
        frd = np.array([0.0 if mask & bit else r for bit, r in zip(RATE_BITS, rates, strict=True)])
        setpoint.body_rates = frames.frd_to_flu(frd)
    return setpoint
