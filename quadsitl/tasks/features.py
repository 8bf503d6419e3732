"""The observation layout and the goal distances, for all tasks, over the batch.

Compiled with numba because the single env must step in tens of microseconds and the
vector env must handle millions of env steps per second; the formulas are short and
each is written once. The observation layout (34 values, all tasks; target following
appends 7) is OBS_LAYOUT (and TARGET_OBS_LAYOUT) below: columns, meaning, frame and unit.

Distances (the d_c of Eq. 18), one row per env: position ‖p − p_g‖, attitude
‖sin ζ − sin ζ_g‖ + ‖cos ζ − cos ζ_g‖, velocity ‖v − v_g‖ (world), rates ‖ω − ω_g‖.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from quadsitl.physics import layout as L

# First column of each block (the compiled code indexes with these) ...
OBS_X = 0
OBS_SIN_X = 3
OBS_COS_X = 6
OBS_BODY_VX = 9
OBS_RATE_X = 12
OBS_ROTOR0 = 15
OBS_GOAL_DX = 19
OBS_GOAL_SIN_X = 22
OBS_GOAL_COS_X = 25
OBS_GOAL_DVX = 28
OBS_GOAL_RATE_X = 31
# ... and the blocks as slices (for numpy code).
OBS_POS = slice(0, 3)
OBS_SIN = slice(3, 6)
OBS_COS = slice(6, 9)
OBS_BODY_VEL = slice(9, 12)
OBS_RATES = slice(12, 15)
OBS_ROTORS = slice(15, 19)
OBS_GOAL_POS = slice(19, 22)
OBS_GOAL_SIN = slice(22, 25)
OBS_GOAL_COS = slice(25, 28)
OBS_GOAL_VEL = slice(28, 31)
OBS_GOAL_RATES = slice(31, 34)
OBS_SIZE = 34
# Target following appends (the ``extra_obs`` of its task):
OBS_TARGET_VECTOR = slice(34, 37)  # target − position, ENU m
OBS_TARGET_DISTANCE = 37  # ‖target − position‖, m
OBS_TARGET_VELOCITY = slice(38, 41)  # target velocity, ENU m/s
OBS_TARGET_VECTOR_X = 34
OBS_TARGET_VELOCITY_X = 38
TARGET_EXTRA_OBS = 7
# The blocks as data, (columns, what, frame and unit): what an exported policy's
# contract (policies/export) says a flight controller must feed it.
OBS_LAYOUT = (
    (OBS_POS, "position relative to the task origin", "world ENU, m"),
    (OBS_SIN, "sin(roll, pitch, yaw)", "intrinsic Z-Y-X Euler angles of body FLU in world ENU"),
    (OBS_COS, "cos(roll, pitch, yaw)", "intrinsic Z-Y-X Euler angles of body FLU in world ENU"),
    (OBS_BODY_VEL, "linear velocity", "body FLU, m/s"),
    (OBS_RATES, "body rates", "body FLU, rad/s"),
    (OBS_ROTORS, "rotor speeds Ω / Ω_max, in motor order", "0..1"),
    (OBS_GOAL_POS, "goal position − position", "world ENU, m"),
    (OBS_GOAL_SIN, "sin ζ_goal − sin ζ (goal attitude: level, yaw 0)", "–"),
    (OBS_GOAL_COS, "cos ζ_goal − cos ζ", "–"),
    (OBS_GOAL_VEL, "goal velocity − velocity", "body FLU, m/s"),
    (OBS_GOAL_RATES, "goal rates − rates (goal rates: 0)", "body FLU, rad/s"),
)
TARGET_OBS_LAYOUT = (  # target following's extra_obs, after OBS_LAYOUT
    (OBS_TARGET_VECTOR, "target − position", "world ENU, m"),
    (slice(OBS_TARGET_DISTANCE, OBS_TARGET_DISTANCE + 1), "‖target − position‖", "m"),
    (OBS_TARGET_VELOCITY, "target velocity", "world ENU, m/s"),
)

D_POS, D_ATT, D_VEL, D_RATE = 0, 1, 2, 3
N_DIST = 4

# Goal arrays: (N, 6) = position (ENU, m) then velocity (ENU, m/s).
GOAL_POS = slice(0, 3)
GOAL_VEL = slice(3, 6)
GOAL_X, GOAL_VX = 0, 3

_jit = numba.njit(nogil=True, cache=True, error_model="numpy")


@_jit
def observe(state, params, goal, obs, dist, tilt):  # pragma: no cover - compiled
    """Fill obs (N, ≥34), dist (N, 4) and tilt (N,) = max(|roll|, |pitch|) in rad."""
    for n in range(state.shape[0]):
        s = state[n]
        qw, qx, qy, qz = s[L.I_QW], s[L.I_QX], s[L.I_QY], s[L.I_QZ]
        # Sines and cosines of roll, pitch and yaw straight from the quaternion (no
        # trigonometry: the angles' own atan2/asin are only needed for the tilt).
        roll_y, roll_x = 2 * (qw * qx + qy * qz), 1 - 2 * (qx * qx + qy * qy)
        sin_pitch = min(max(2 * (qw * qy - qz * qx), -1.0), 1.0)
        yaw_y, yaw_x = 2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz)
        roll = math.atan2(roll_y, roll_x)
        pitch = math.asin(sin_pitch)
        tilt[n] = max(abs(roll), abs(pitch))
        # Rotation matrix rows: body = Rᵀ world.
        r00 = 1 - 2 * (qy * qy + qz * qz)
        r01 = 2 * (qx * qy - qw * qz)
        r02 = 2 * (qx * qz + qw * qy)
        r10 = 2 * (qx * qy + qw * qz)
        r11 = 1 - 2 * (qx * qx + qz * qz)
        r12 = 2 * (qy * qz - qw * qx)
        r20 = 2 * (qx * qz - qw * qy)
        r21 = 2 * (qy * qz + qw * qx)
        r22 = 1 - 2 * (qx * qx + qy * qy)
        o = obs[n]
        pos_err = 0.0
        for k in range(3):
            o[OBS_X + k] = s[L.I_PX + k]
            delta = goal[n, GOAL_X + k] - s[L.I_PX + k]
            o[OBS_GOAL_DX + k] = delta
            pos_err += delta * delta
        sin_err = 0.0
        cos_err = 0.0
        roll_norm, yaw_norm = math.hypot(roll_y, roll_x), math.hypot(yaw_y, yaw_x)
        sines = (
            roll_y / roll_norm if roll_norm > 0 else 0.0,
            sin_pitch,
            yaw_y / yaw_norm if yaw_norm > 0 else 0.0,
        )
        cosines = (
            roll_x / roll_norm if roll_norm > 0 else 1.0,
            math.sqrt(1.0 - sin_pitch * sin_pitch),
            yaw_x / yaw_norm if yaw_norm > 0 else 1.0,
        )
        for k in range(3):
            sa = sines[k]
            ca = cosines[k]
            o[OBS_SIN_X + k] = sa
            o[OBS_COS_X + k] = ca
            o[OBS_GOAL_SIN_X + k] = -sa
            o[OBS_GOAL_COS_X + k] = 1.0 - ca
            sin_err += sa * sa
            cos_err += (1.0 - ca) * (1.0 - ca)
        vx, vy, vz = s[L.I_VX], s[L.I_VY], s[L.I_VZ]
        ex, ey, ez = goal[n, GOAL_VX] - vx, goal[n, GOAL_VX + 1] - vy, goal[n, GOAL_VX + 2] - vz
        o[OBS_BODY_VX] = r00 * vx + r10 * vy + r20 * vz
        o[OBS_BODY_VX + 1] = r01 * vx + r11 * vy + r21 * vz
        o[OBS_BODY_VX + 2] = r02 * vx + r12 * vy + r22 * vz
        o[OBS_GOAL_DVX] = r00 * ex + r10 * ey + r20 * ez
        o[OBS_GOAL_DVX + 1] = r01 * ex + r11 * ey + r21 * ez
        o[OBS_GOAL_DVX + 2] = r02 * ex + r12 * ey + r22 * ez
        rate_err = 0.0
        for k in range(3):
            w = s[L.I_WX + k]
            o[OBS_RATE_X + k] = w
            o[OBS_GOAL_RATE_X + k] = -w
            rate_err += w * w
        omega_max = params[n, L.P_OMEGA_MAX]
        for k in range(L.N_ROTORS):
            o[OBS_ROTOR0 + k] = s[L.I_ROTOR0 + k] / omega_max
        dist[n, D_POS] = math.sqrt(pos_err)
        dist[n, D_ATT] = math.sqrt(sin_err) + math.sqrt(cos_err)
        dist[n, D_VEL] = math.sqrt(ex * ex + ey * ey + ez * ez)
        dist[n, D_RATE] = math.sqrt(rate_err)


def hide_position(obs: np.ndarray, observe_position: bool) -> None:
    """The task option ``observe_position=False``: the position slots of every row of
    ``obs`` read 0 (the env's observations and the policy autopilot's alike)."""
    if not observe_position:
        obs[:, OBS_POS] = 0.0


def empty_buffers(n: int, obs_size: int = OBS_SIZE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Preallocated (obs, dist, tilt) arrays for ``n`` envs."""
    return np.zeros((n, obs_size), np.float32), np.zeros((n, N_DIST)), np.zeros(n)
