"""The right-hand side and the ground contact of one block of vehicles, scalar by scalar:
:func:`quadsitl.physics.reference.derivative` and ``ground_contact``, loop by loop.

The physics kernel (:mod:`quadsitl.physics.kernel`) inlines both into its RK4 step,
where the block's row length B is a compile-time constant; here they read and write its
structure-of-arrays scratch (value k of vehicle j at ``s[k * B + j]``), each loop over
vehicles innermost, so that the compiler vectorises it. Read the reference to
understand the physics; read this only to change its speed.
"""

from __future__ import annotations

import math
from typing import Any

import numba

from quadsitl.physics import ground_effect as GE
from quadsitl.physics import layout as L

# Rows of the block's ``sums`` scratch (each B values). The world build keeps there too
# what it holds over a physics step: the air (written by the weather's step) and each
# rotor's thrust and yaw factors (rotor_factors, once per step rather than per stage).
THRUST, ROLL_MOMENT, PITCH_MOMENT, YAW_SUM = 0, 1, 2, 3  # the rotor sums
AIR0 = 4  # 6 rows: the air's velocity (world ENU), then its angular velocity (body FLU)
THRUST_FACTOR0 = AIR0 + 6  # 4 rows: k_T η_i G_i, rotor i's thrust per Ω² (N s²)
YAW_FACTOR0 = THRUST_FACTOR0 + L.N_ROTORS  # 4 rows: ±η_i, rotor i's reaction-torque sign
SUMS_ROWS = YAW_FACTOR0 + L.N_ROTORS
# FMA contraction and reciprocal division only: no fast-math NaN/inf assumptions, so
# the finiteness check stays exact.
_OPTIONS: dict[str, Any] = dict(
    cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz"}
)
# Inlined into the kernel's ``step`` (numba IR), where B is a compile-time constant.
_inline = numba.njit(inline="always", **_OPTIONS)


@_inline
def _rotor(rotor, cmd, thrust_factor, yaw_factor, rate, omega_max):  # pragma: no cover
    """One rotor's thrust, reaction-torque term and motor lag dΩ/dt, from scalars only.

    The rotors are written out one by one in :func:`derivative`, not looped over: an
    inner loop over them added into the rotor sums in memory (read-modify-write rows of
    ``sums`` next to the rows the world reads), which the compiler could not prove
    apart, and the world build's derivative ran unvectorised (+20 ns a vehicle step,
    measured). Scalars only: an inlined call that takes arrays costs reference counts
    per vehicle, and the loop around it is not vectorised either."""
    rotor_sq = rotor * rotor
    command = min(max(cmd, 0.0), omega_max)
    return thrust_factor * rotor_sq, yaw_factor * rotor_sq, rate * (command - rotor)


@_inline
def derivative(s, p, cmd, out, m, sums, B, WIND):  # pragma: no cover - compiled
    """ṡ of the first m vehicles of a block (rows of B values; ``sums``: scratch for the
    rotor sums). WIND builds the world from what ``sums`` holds over the step (the air,
    each rotor's factors of :func:`rotor_factors`); without it, the paper's still air."""
    for j in range(m):  # the four rotors, written out: see _rotor
        rate, omega_max = p[L.P_MOTOR_RATE * B + j], p[L.P_OMEGA_MAX * B + j]
        r0, r1 = s[L.I_ROTOR0 * B + j], s[(L.I_ROTOR0 + 1) * B + j]
        r2, r3 = s[(L.I_ROTOR0 + 2) * B + j], s[(L.I_ROTOR0 + 3) * B + j]
        if WIND:  # the world: k_T η_i G_i and ±η_i of the step (rotor_factors)
            k0, k1 = sums[THRUST_FACTOR0 * B + j], sums[(THRUST_FACTOR0 + 1) * B + j]
            k2, k3 = sums[(THRUST_FACTOR0 + 2) * B + j], sums[(THRUST_FACTOR0 + 3) * B + j]
            e0, e1 = sums[YAW_FACTOR0 * B + j], sums[(YAW_FACTOR0 + 1) * B + j]
            e2, e3 = sums[(YAW_FACTOR0 + 2) * B + j], sums[(YAW_FACTOR0 + 3) * B + j]
        else:
            k0 = k1 = k2 = k3 = p[L.P_KT * B + j]
            e0, e1 = p[L.P_ROTOR_YAW_SIGN0 * B + j], p[(L.P_ROTOR_YAW_SIGN0 + 1) * B + j]
            e2, e3 = p[(L.P_ROTOR_YAW_SIGN0 + 2) * B + j], p[(L.P_ROTOR_YAW_SIGN0 + 3) * B + j]
        t0, y0, lag0 = _rotor(r0, cmd[j], k0, e0, rate, omega_max)
        t1, y1, lag1 = _rotor(r1, cmd[B + j], k1, e1, rate, omega_max)
        t2, y2, lag2 = _rotor(r2, cmd[2 * B + j], k2, e2, rate, omega_max)
        t3, y3, lag3 = _rotor(r3, cmd[3 * B + j], k3, e3, rate, omega_max)
        out[L.I_ROTOR0 * B + j], out[(L.I_ROTOR0 + 1) * B + j] = lag0, lag1
        out[(L.I_ROTOR0 + 2) * B + j], out[(L.I_ROTOR0 + 3) * B + j] = lag2, lag3
        sums[THRUST * B + j] = t0 + t1 + t2 + t3
        y, x = L.P_ROTOR_Y0 * B + j, L.P_ROTOR_X0 * B + j  # rotor i's arm: + i·B
        sums[ROLL_MOMENT * B + j] = (
            p[y] * t0 + p[y + B] * t1 + p[y + 2 * B] * t2 + p[y + 3 * B] * t3
        )
        sums[PITCH_MOMENT * B + j] = (
            p[x] * t0 + p[x + B] * t1 + p[x + 2 * B] * t2 + p[x + 3 * B] * t3
        )
        sums[YAW_SUM * B + j] = y0 + y1 + y2 + y3
    for j in range(m):
        vx, vy, vz = s[L.I_VX * B + j], s[L.I_VY * B + j], s[L.I_VZ * B + j]
        qw, qx = s[L.I_QW * B + j], s[L.I_QX * B + j]
        qy, qz = s[L.I_QY * B + j], s[L.I_QZ * B + j]
        wx, wy, wz = s[L.I_WX * B + j], s[L.I_WY * B + j], s[L.I_WZ * B + j]
        total_thrust = sums[THRUST * B + j]
        mx = sums[ROLL_MOMENT * B + j]
        my = sums[PITCH_MOMENT * B + j]
        yaw_sum = sums[YAW_SUM * B + j]

        mass = p[L.P_MASS * B + j]
        out[L.I_PX * B + j] = vx
        out[L.I_PY * B + j] = vy
        out[L.I_PZ * B + j] = vz
        if WIND:  # velocity and rates through the air
            ax = vx - sums[AIR0 * B + j]
            ay = vy - sums[(AIR0 + 1) * B + j]
            az = vz - sums[(AIR0 + 2) * B + j]
            ox = wx - sums[(AIR0 + 3) * B + j]
            oy = wy - sums[(AIR0 + 4) * B + j]
            oz = wz - sums[(AIR0 + 5) * B + j]
        else:
            ax, ay, az = vx, vy, vz
            ox, oy, oz = wx, wy, wz
        drag = p[L.P_KD * B + j] * math.sqrt(ax * ax + ay * ay + az * az)
        out[L.I_VX * B + j] = (total_thrust * (2 * (qx * qz + qw * qy)) - drag * ax) / mass
        out[L.I_VY * B + j] = (total_thrust * (2 * (qy * qz - qw * qx)) - drag * ay) / mass
        gravity = p[L.P_GRAVITY * B + j]
        out[L.I_VZ * B + j] = (
            total_thrust * (1 - 2 * (qx * qx + qy * qy)) - drag * az
        ) / mass - gravity

        out[L.I_QW * B + j] = 0.5 * (-qx * wx - qy * wy - qz * wz)
        out[L.I_QX * B + j] = 0.5 * (qw * wx + qy * wz - qz * wy)
        out[L.I_QY * B + j] = 0.5 * (qw * wy - qx * wz + qz * wx)
        out[L.I_QZ * B + j] = 0.5 * (qw * wz + qx * wy - qy * wx)

        jxx, jyy, jzz = p[L.P_JXX * B + j], p[L.P_JYY * B + j], p[L.P_JZZ * B + j]
        km_rate = p[L.P_KM * B + j] * math.sqrt(ox * ox + oy * oy + oz * oz)
        mx = mx - km_rate * ox - (wy * (jzz * wz) - wz * (jyy * wy))
        my = -my - km_rate * oy - (wz * (jxx * wx) - wx * (jzz * wz))
        mz = p[L.P_KQ * B + j] * yaw_sum - km_rate * oz - (wx * (jyy * wy) - wy * (jxx * wx))
        out[L.I_WX * B + j] = mx / jxx
        out[L.I_WY * B + j] = my / jyy
        out[L.I_WZ * B + j] = mz / jzz


@_inline
def rotor_factors(s, p, sums, m, B):  # pragma: no cover - compiled
    """Each rotor's thrust factor k_T η_i G_i and yaw factor ±η_i into ``sums`` rows
    THRUST_FACTOR0.. and YAW_FACTOR0..: its efficiency η_i and its ground-effect gain
    G_i (1 where ground effect is off) at the state s, the step's start (held over the
    step, as the air is)."""
    for i in range(L.N_ROTORS):
        for j in range(m):
            qw, qx = s[L.I_QW * B + j], s[L.I_QX * B + j]
            qy, qz = s[L.I_QY * B + j], s[L.I_QZ * B + j]
            hub_z = (
                s[L.I_PZ * B + j]
                + 2 * (qx * qz - qw * qy) * p[(L.P_ROTOR_X0 + i) * B + j]
                + 2 * (qy * qz + qw * qx) * p[(L.P_ROTOR_Y0 + i) * B + j]
            )
            radius = p[L.P_ROTOR_RADIUS * B + j]
            height = max(hub_z - p[L.P_GROUND_Z * B + j], GE.MIN_HEIGHT_RADII * radius)
            k = radius / (4.0 * height)
            ratio = 1.0 / (1.0 - k * k)  # Cheeseman–Bennett (+inf height: 1)
            gain = 1.0 + (ratio - 1.0) * p[L.P_GROUND_EFFECT * B + j]  # switch: 1 or 0
            efficiency = p[(L.P_ROTOR_EFFICIENCY0 + i) * B + j]
            sums[(THRUST_FACTOR0 + i) * B + j] = p[L.P_KT * B + j] * (efficiency * gain)
            sums[(YAW_FACTOR0 + i) * B + j] = p[(L.P_ROTOR_YAW_SIGN0 + i) * B + j] * efficiency


@_inline
def ground_contact(prev, s, p, contact, touchdown_speed, first, m, B):  # pragma: no cover
    """Contact resolution of the block's first m columns (vehicles first..first+m−1), as
    reference.ground_contact. The loop over the block is here, not at the call: numba
    could not prune the reference counts of an inlined call per vehicle, and their
    atomic updates (four pairs per vehicle and step) took 20-40 % of a step (measured
    with perf: still air 51 -> 32 ns per vehicle step)."""
    for j in range(m):
        n = first + j
        if contact[n] == L.CRASHED:
            for k in range(L.I_ROTOR0):
                s[k * B + j] = prev[k * B + j]
            continue
        ground_z = p[L.P_GROUND_Z * B + j]
        if ground_z == -math.inf:  # no ground: nothing to touch
            contact[n] = L.AIRBORNE
            continue
        qw, qx = s[L.I_QW * B + j], s[L.I_QX * B + j]
        qy, qz = s[L.I_QY * B + j], s[L.I_QZ * B + j]
        pz = s[L.I_PZ * B + j]
        cos_tilt = 1 - 2 * (qx * qx + qy * qy)
        sin_tilt = math.sqrt(max(0.0, 1.0 - cos_tilt * cos_tilt))
        r_zx = 2 * (qx * qz - qw * qy)
        r_zy = 2 * (qy * qz + qw * qx)
        strike = False
        for i in range(L.N_ROTORS):
            hub_z = pz + r_zx * p[(L.P_ROTOR_X0 + i) * B + j] + r_zy * p[(L.P_ROTOR_Y0 + i) * B + j]
            if hub_z - p[L.P_ROTOR_RADIUS * B + j] * sin_tilt < ground_z:
                strike = True
        rest_z = ground_z + p[L.P_GEAR_HEIGHT * B + j]
        below = pz < rest_z and not strike
        if not (strike or below):
            contact[n] = L.AIRBORNE
            continue
        touching = below and contact[n] != L.ON_GROUND
        speed = -s[L.I_VZ * B + j]
        too_hard = touching and (
            speed > p[L.P_MAX_TOUCHDOWN_SPEED * B + j] or cos_tilt < p[L.P_COS_MAX_TILT * B + j]
        )
        if touching:
            touchdown_speed[n] = max(speed, 0.0)
        resting = below and not too_hard
        s[L.I_PZ * B + j] = max(pz, rest_z)
        for k in range(3):
            s[(L.I_VX + k) * B + j] = 0.0
            s[(L.I_WX + k) * B + j] = 0.0
        if resting:
            yaw = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
            s[L.I_QW * B + j] = math.cos(0.5 * yaw)
            s[L.I_QX * B + j] = 0.0
            s[L.I_QY * B + j] = 0.0
            s[L.I_QZ * B + j] = math.sin(0.5 * yaw)
            contact[n] = L.ON_GROUND
        else:
            contact[n] = L.CRASHED
