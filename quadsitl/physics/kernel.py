"""The compiled physics kernel: :mod:`quadsitl.physics.reference`, loop by loop, in numba.

Same model, same order of operations, written with scalars. Vehicles are copied in
blocks of ``BLOCK`` into structure-of-arrays scratch (``s[column, vehicle]``) so that the
compiler vectorises each RK4 stage across vehicles (about 2× the speed of a loop over
rows). ``tests/test_kernel.py`` holds it to the numpy
reference within 1e-12. Read the reference to understand the physics; read this only
to change its speed.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from quadsitl.physics import layout as L

BLOCK = 32  # vehicles per vectorised block (measured best of 16..256)
# FMA contraction and reciprocal division only: no fast-math NaN/inf assumptions, so
# the finiteness check stays exact.
_jit = numba.njit(nogil=True, cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz"})


@_jit
def _derivative(s, p, cmd, out, m):  # pragma: no cover - compiled
    """ṡ of the first m vehicles of a block: s (17, B), p (N_PARAMS, B), cmd (4, B)."""
    for j in range(m):
        vx, vy, vz = s[L.I_VX, j], s[L.I_VY, j], s[L.I_VZ, j]
        qw, qx, qy, qz = s[L.I_QW, j], s[L.I_QX, j], s[L.I_QY, j], s[L.I_QZ, j]
        wx, wy, wz = s[L.I_WX, j], s[L.I_WY, j], s[L.I_WZ, j]
        kt = p[L.P_KT, j]
        omega_max = p[L.P_OMEGA_MAX, j]
        motor_rate = p[L.P_MOTOR_RATE, j]

        total_thrust = 0.0
        mx = 0.0
        my = 0.0
        yaw_sum = 0.0
        for i in range(L.N_ROTORS):
            rotor = s[L.I_ROTOR0 + i, j]
            rotor_sq = rotor * rotor
            thrust = kt * rotor_sq
            total_thrust += thrust
            mx += p[L.P_ROTOR_Y0 + i, j] * thrust
            my += p[L.P_ROTOR_X0 + i, j] * thrust
            yaw_sum += p[L.P_ROTOR_YAW_SIGN0 + i, j] * rotor_sq
            c = min(max(cmd[i, j], 0.0), omega_max)
            out[L.I_ROTOR0 + i, j] = motor_rate * (c - rotor)

        mass = p[L.P_MASS, j]
        drag = p[L.P_KD, j] * math.sqrt(vx * vx + vy * vy + vz * vz)
        out[L.I_PX, j] = vx
        out[L.I_PY, j] = vy
        out[L.I_PZ, j] = vz
        out[L.I_VX, j] = (total_thrust * (2 * (qx * qz + qw * qy)) - drag * vx) / mass
        out[L.I_VY, j] = (total_thrust * (2 * (qy * qz - qw * qx)) - drag * vy) / mass
        out[L.I_VZ, j] = (total_thrust * (1 - 2 * (qx * qx + qy * qy)) - drag * vz) / mass - p[
            L.P_GRAVITY, j
        ]

        out[L.I_QW, j] = 0.5 * (-qx * wx - qy * wy - qz * wz)
        out[L.I_QX, j] = 0.5 * (qw * wx + qy * wz - qz * wy)
        out[L.I_QY, j] = 0.5 * (qw * wy - qx * wz + qz * wx)
        out[L.I_QZ, j] = 0.5 * (qw * wz + qx * wy - qy * wx)

        jxx, jyy, jzz = p[L.P_JXX, j], p[L.P_JYY, j], p[L.P_JZZ, j]
        km_rate = p[L.P_KM, j] * math.sqrt(wx * wx + wy * wy + wz * wz)
        mx = mx - km_rate * wx - (wy * (jzz * wz) - wz * (jyy * wy))
        my = -my - km_rate * wy - (wz * (jxx * wx) - wx * (jzz * wz))
        mz = p[L.P_KQ, j] * yaw_sum - km_rate * wz - (wx * (jyy * wy) - wy * (jxx * wx))
        out[L.I_WX, j] = mx / jxx
        out[L.I_WY, j] = my / jyy
        out[L.I_WZ, j] = mz / jzz


@_jit
def _ground_contact(prev, s, p, j, contact, touchdown_speed, n):  # pragma: no cover - compiled
    """Contact resolution of block column j (vehicle n), as reference.ground_contact."""
    if contact[n] == L.CRASHED:
        for k in range(L.I_ROTOR0):
            s[k, j] = prev[k, j]
        return
    qw, qx, qy, qz = s[L.I_QW, j], s[L.I_QX, j], s[L.I_QY, j], s[L.I_QZ, j]
    pz = s[L.I_PZ, j]
    ground_z = p[L.P_GROUND_Z, j]
    cos_tilt = 1 - 2 * (qx * qx + qy * qy)
    sin_tilt = math.sqrt(max(0.0, 1.0 - cos_tilt * cos_tilt))
    r_zx = 2 * (qx * qz - qw * qy)
    r_zy = 2 * (qy * qz + qw * qx)
    strike = False
    for i in range(L.N_ROTORS):
        hub_z = pz + r_zx * p[L.P_ROTOR_X0 + i, j] + r_zy * p[L.P_ROTOR_Y0 + i, j]
        if hub_z - p[L.P_ROTOR_RADIUS, j] * sin_tilt < ground_z:
            strike = True
    rest_z = ground_z + p[L.P_GEAR_HEIGHT, j]
    below = pz < rest_z and not strike
    if not (strike or below):
        contact[n] = L.AIRBORNE
        return
    touching = below and contact[n] != L.ON_GROUND
    speed = -s[L.I_VZ, j]
    too_hard = touching and (
        speed > p[L.P_MAX_TOUCHDOWN_SPEED, j] or cos_tilt < p[L.P_COS_MAX_TILT, j]
    )
    if touching:
        touchdown_speed[n] = max(speed, 0.0)
    resting = below and not too_hard
    s[L.I_PZ, j] = max(pz, rest_z)
    for k in range(3):
        s[L.I_VX + k, j] = 0.0
        s[L.I_WX + k, j] = 0.0
    if resting:
        yaw = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
        s[L.I_QW, j] = math.cos(0.5 * yaw)
        s[L.I_QX, j] = 0.0
        s[L.I_QY, j] = 0.0
        s[L.I_QZ, j] = math.sin(0.5 * yaw)
        contact[n] = L.ON_GROUND
    else:
        contact[n] = L.CRASHED


@_jit
def first_invalid_command(rotor_cmd):  # pragma: no cover - compiled
    """Index of the first vehicle whose (4,) command holds NaN or inf, or -1."""
    for n in range(rotor_cmd.shape[0]):
        for i in range(rotor_cmd.shape[1]):
            if not math.isfinite(rotor_cmd[n, i]):
                return n
    return -1


@_jit
def _axpy(out, x, a, y, m):  # pragma: no cover - compiled
    """out = x + a·y over the first m columns."""
    for k in range(out.shape[0]):
        for j in range(m):
            out[k, j] = x[k, j] + a * y[k, j]


@_jit
def step(state, params, rotor_cmd, contact, touchdown_speed, dt, n_substeps):  # pragma: no cover
    """Advance every vehicle ``n_substeps`` physics steps of ``dt`` in place.

    Returns -1, or the index of the first vehicle with a non-finite command, in which
    case nothing was changed.
    """
    bad = first_invalid_command(rotor_cmd)
    if bad >= 0:
        return bad
    size = L.STATE_SIZE
    s = np.empty((size, BLOCK))
    p = np.empty((L.N_PARAMS, BLOCK))
    cmd = np.empty((L.N_ROTORS, BLOCK))
    prev = np.empty((size, BLOCK))
    tmp = np.empty((size, BLOCK))
    k1 = np.empty((size, BLOCK))
    k2 = np.empty((size, BLOCK))
    k3 = np.empty((size, BLOCK))
    k4 = np.empty((size, BLOCK))
    sixth = dt / 6.0
    for first in range(0, state.shape[0], BLOCK):
        m = min(BLOCK, state.shape[0] - first)
        for j in range(m):
            for k in range(size):
                s[k, j] = state[first + j, k]
            for k in range(L.N_PARAMS):
                p[k, j] = params[first + j, k]
            for k in range(L.N_ROTORS):
                cmd[k, j] = rotor_cmd[first + j, k]
        for _ in range(n_substeps):
            prev[:, :m] = s[:, :m]
            _derivative(s, p, cmd, k1, m)
            _axpy(tmp, s, 0.5 * dt, k1, m)
            _derivative(tmp, p, cmd, k2, m)
            _axpy(tmp, s, 0.5 * dt, k2, m)
            _derivative(tmp, p, cmd, k3, m)
            _axpy(tmp, s, dt, k3, m)
            _derivative(tmp, p, cmd, k4, m)
            for k in range(size):
                for j in range(m):
                    s[k, j] = s[k, j] + sixth * (
                        k1[k, j] + 2.0 * k2[k, j] + 2.0 * k3[k, j] + k4[k, j]
                    )
            for j in range(m):
                norm = math.sqrt(
                    s[L.I_QW, j] ** 2 + s[L.I_QX, j] ** 2 + s[L.I_QY, j] ** 2 + s[L.I_QZ, j] ** 2
                )
                for k in range(L.I_QW, L.I_QZ + 1):
                    s[k, j] /= norm
                omega_max = p[L.P_OMEGA_MAX, j]
                for k in range(L.I_ROTOR0, size):
                    s[k, j] = min(max(s[k, j], 0.0), omega_max)
            for j in range(m):
                _ground_contact(prev, s, p, j, contact, touchdown_speed, first + j)
        for j in range(m):
            for k in range(size):
                state[first + j, k] = s[k, j]
    return -1
