"""ODOMETRY of the onboard estimate: the estimator's pose and velocity with their
covariances, converted to MAVLink's frames here (world ENU -> local NED, body FLU ->
FRD, the attitude error -> roll, pitch and yaw).

MAVLink's ODOMETRY carries the upper-right triangle of each 6×6 covariance, row by row:
``pose_covariance`` over (x, y, z, roll, pitch, yaw) in the local NED frame and
``velocity_covariance`` over (vx, vy, vz, roll rate, pitch rate, yaw rate) in the child
frame, body FRD, as the velocity itself.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.flight_software import estimator_params as E
from quadsitl.physics import layout as L
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.wire.dialect import mavlink as mav

_UPPER = np.triu_indices(6)  # row-major upper-right triangle: MAVLink's order
_FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])
_encoder = mav.MAVLink(None)


def _enu_to_ned_matrix() -> np.ndarray:
    """(3, 3) T with v_ned = T·v_enu (through :func:`quadsitl.frames.enu_to_ned`)."""
    return frames.enu_to_ned(np.eye(3)).T


def euler_from_rotation_error(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """(3, 3) J with (δroll, δpitch, δyaw) = J·δθ for a small rotation δθ of the world
    frame (R_true = (I + [δθ]×)·R) at Z-Y-X Euler angles (rad) of that frame: δθ =
    δψ·z + δθ_p·Rz·y + δφ·Rz·Ry·x, inverted (singular only at pitch ±90°)."""
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    columns = np.array([[cy * cp, sy * cp, -sp], [-sy, cy, 0.0], [0.0, 0.0, 1.0]]).T
    return np.linalg.pinv(columns)


def odometry_covariances(
    covariance: np.ndarray, state: np.ndarray, rate_variance: float
) -> tuple[list[float], list[float]]:
    """(pose_covariance, velocity_covariance), 21 values each, of an estimate: its
    error covariance ``covariance`` (16, 16) (:mod:`quadsitl.flight_software.estimator_params`), its
    physics row ``state`` (world ENU, body FLU) and the variance (rad/s)² of one gyro
    reading's white noise (the body rates are the gyroscope less its bias)."""
    enu_to_ned = _enu_to_ned_matrix()
    q_ned_frd = frames.quat_enu_flu_to_ned_frd(state[L.QUAT])
    roll, pitch, yaw = frames.euler_from_quat(q_ned_frd).tolist()
    # Pose: (δp, δθ) in world ENU -> (x, y, z) NED and (roll, pitch, yaw).
    pose = np.zeros((6, E.SIZE))
    pose[0:3, E.POS] = enu_to_ned
    pose[3:6, E.ATT] = euler_from_rotation_error(roll, pitch, yaw) @ enu_to_ned
    # Body velocity v_b = Rᵀ·v: δv_b = Rᵀ·δv + Rᵀ·[v]×·δθ; rates = gyro − b_g.
    to_body = _FLU_TO_FRD @ frames.quat_to_matrix(state[L.QUAT]).T
    vx, vy, vz = state[L.VEL].tolist()
    velocity_cross = np.array([[0.0, -vz, vy], [vz, 0.0, -vx], [-vy, vx, 0.0]])
    motion = np.zeros((6, E.SIZE))
    motion[0:3, E.VEL] = to_body
    motion[0:3, E.ATT] = to_body @ velocity_cross
    motion[3:6, E.GYRO_BIAS] = -_FLU_TO_FRD
    pose_cov = pose @ covariance @ pose.T
    motion_cov = motion @ covariance @ motion.T + np.diag([0.0] * 3 + [rate_variance] * 3)
    return pose_cov[_UPPER].tolist(), motion_cov[_UPPER].tolist()


def build_estimate_odometry(s: Snapshot) -> Any:
    """ODOMETRY with the estimate (the snapshot's pose and velocity, which are the
    estimate while EKF2_EN is 1) and its covariances; estimator type GPS_INS."""
    v = s.vehicle
    imu = v.sensors.suite.params.imu
    rate_variance = imu.gyro_noise_density**2 * imu.rate * v.sensors.noise_scale**2
    pose_cov, velocity_cov = odometry_covariances(
        v.estimator.covariance, v.nav_state, rate_variance
    )
    p, q, u, r = s.position_ned, s.q_ned_frd, s.velocity_frd, s.rates_frd
    return _encoder.odometry_encode(
        time_usec=s.time_usec,
        frame_id=mav.MAV_FRAME_LOCAL_NED,
        child_frame_id=mav.MAV_FRAME_BODY_FRD,
        x=float(p[0]),
        y=float(p[1]),
        z=float(p[2]),
        q=[float(x) for x in q],
        vx=float(u[0]),
        vy=float(u[1]),
        vz=float(u[2]),
        rollspeed=float(r[0]),
        pitchspeed=float(r[1]),
        yawspeed=float(r[2]),
        pose_covariance=pose_cov,
        velocity_covariance=velocity_cov,
        reset_counter=s.resets & 0xFF,
        estimator_type=mav.MAV_ESTIMATOR_TYPE_GPS_INS,
        quality=0,  # "unknown", as PX4's EKF2 leaves it
    )
