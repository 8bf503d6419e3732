"""The arithmetic of the cascaded flight controller, compiled (one vehicle per call).

:class:`quadsitl.flight_software.controller.CascadedController` packs its setpoint, gains and
model into the rows below and calls :func:`rotor_command`; read that class for what the
loops do and why. Here they are written with scalars (numba), because a fleet runs one
controller per vehicle 250 times a second and the numpy version spent ~200 µs a call
in array overhead.

Frames and units as everywhere: world ENU, body FLU, SI.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from quadsitl.physics import layout as L

# --- the setpoint row ------------------------------------------------------------------
SP_POS = 0  # 3 values, m; NaN in the first: no position (velocity control)
SP_VEL = 3  # 3, m/s (feed-forward)
SP_ACC = 6  # 3, m/s²
SP_YAW = 9  # rad, NaN: keep the current heading
SP_YAW_RATE = 10  # rad/s
SP_ATT = 11  # 4, quaternion; NaN in the first: no attitude setpoint
SP_RATES = 15  # 3, rad/s; NaN in the first: no body-rate setpoint
SP_THRUST = 18  # fraction of the maximum collective thrust (NaN: none)
SP_IDLE = 19  # 1: idle on the ground
SP_MAX_XY = 20  # m/s, this leg's horizontal speed limit (NaN: the parameter's)
SP_SIZE = 21

# --- the gains row: ControllerGains' fields in this order --------------------------------
GAIN_FIELDS = (
    "pos_xy",
    "pos_z",
    "vel_xy",
    "vel_xy_i",
    "vel_z",
    "vel_z_i",
    "att_rp",
    "att_yaw",
    "rate_rp",
    "rate_yaw",
    "motor_boost",
    "max_speed_xy",
    "max_speed_up",
    "max_speed_down",
    "max_accel_xy",
    "max_tilt_deg",
    "max_rate_rp_deg",
    "max_rate_yaw_deg",
    "idle_fraction",
)
(
    G_POS_XY,
    G_POS_Z,
    G_VEL_XY,
    G_VEL_XY_I,
    G_VEL_Z,
    G_VEL_Z_I,
    G_ATT_RP,
    G_ATT_YAW,
    G_RATE_RP,
    G_RATE_YAW,
    G_MOTOR_BOOST,
    G_MAX_SPEED_XY,
    G_MAX_SPEED_UP,
    G_MAX_SPEED_DOWN,
    G_MAX_ACCEL_XY,
    G_MAX_TILT_DEG,
    G_MAX_RATE_RP_DEG,
    G_MAX_RATE_YAW_DEG,
    G_IDLE_FRACTION,
) = range(len(GAIN_FIELDS))

# --- the model row -----------------------------------------------------------------------
M_MASS, M_GRAVITY, M_JXX, M_JYY, M_JZZ, M_OMEGA_MAX, M_MAX_THRUST, M_DRAG = range(8)
M_MIXER = 8  # 16 values: the inverse allocation matrix, row-major
M_SIZE = 24

INTEGRAL_LIMIT = 3.0  # m/s², bound of each velocity-integral term
BRAKE_FRACTION = 0.5  # of MPC_ACC_HOR: the deceleration that ends the approach to a
# position setpoint (the rest is the velocity loop's margin; legs plan the same)

_jit = numba.njit(cache=True, error_model="numpy")
# Parts of rotor_command, inlined into it (numba IR): one machine code, as fast as when
# it was written in one piece.
_inline = numba.njit(cache=True, error_model="numpy", inline="always")


@_jit
def _clamp(x, low, high):  # pragma: no cover - compiled
    return min(max(x, low), high)


@_jit
def approach_speed(distance, gain, decel):  # pragma: no cover - compiled
    """Speed (m/s) at which the position loop closes ``distance`` (m): ``gain`` × distance
    near the target, and far from it the speed from which ``decel`` (m/s²) stops the
    vehicle exactly there (the square-root law), joined where both have the same value
    and slope. A plain P loop at speed limits that its acceleration limit cannot brake
    from overshoots a large step; this does not."""
    if gain <= 0.0 or decel <= 0.0:
        return gain * distance
    linear = decel / (gain * gain)  # m: below it, the P loop already brakes within decel
    if distance <= linear:
        return gain * distance
    return math.sqrt(2.0 * decel * (distance - 0.5 * linear))


@_jit
def _quat_from_axes(x0, x1, x2, y0, y1, y2, z0, z1, z2):  # pragma: no cover - compiled
    """Unit quaternion (w, x, y, z) of the rotation whose matrix has the columns x, y, z
    (Shepperd's method)."""
    r00, r01, r02 = x0, y0, z0
    r10, r11, r12 = x1, y1, z1
    r20, r21, r22 = x2, y2, z2
    trace = r00 + r11 + r22
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        w, x, y, z = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        w, x, y, z = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
        w, x, y, z = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    return w / norm, x / norm, y / norm, z / norm


@_jit
def _attitude_loop(q, dw, dx, dy, dz, g, rate):  # pragma: no cover - compiled
    """Body-rate setpoint (rad/s, FLU) into ``rate`` from the error between the attitude
    ``q`` and the wanted one (dw, dx, dy, dz): q_err = q* ⊗ q_des, shortest way round."""
    qw, qx, qy, qz = q[0], -q[1], -q[2], -q[3]  # the conjugate of q (w, x, y, z)
    ew = qw * dw - qx * dx - qy * dy - qz * dz
    ex = qw * dx + qx * dw + qy * dz - qz * dy
    ey = qw * dy - qx * dz + qy * dw + qz * dx
    ez = qw * dz + qx * dy - qy * dx + qz * dw
    if ew < 0:
        ex, ey, ez = -ex, -ey, -ez
    max_rp = math.radians(g[G_MAX_RATE_RP_DEG])
    max_yaw = math.radians(g[G_MAX_RATE_YAW_DEG])
    rate[0] = _clamp(2.0 * ex * g[G_ATT_RP], -max_rp, max_rp)
    rate[1] = _clamp(2.0 * ey * g[G_ATT_RP], -max_rp, max_rp)
    rate[2] = _clamp(2.0 * ez * g[G_ATT_YAW], -max_yaw, max_yaw)


@_jit
def _mix_and_drive(thrust, tx, ty, tz, rotors, g, m, out):  # pragma: no cover - compiled
    """Rotor speeds for thrust and torque (yaw gives way first when they cannot all be
    had), then the motor loop that drives the slow motors there faster."""
    omega_max = m[M_OMEGA_MAX]
    omega_sq_max = omega_max * omega_max
    wanted = np.empty(4)
    low, high = math.inf, -math.inf
    for i in range(4):
        row = M_MIXER + 4 * i
        wanted[i] = m[row] * thrust + m[row + 1] * tx + m[row + 2] * ty + m[row + 3] * tz
        low, high = min(low, wanted[i]), max(high, wanted[i])
    if low < 0 or high > omega_sq_max:
        for i in range(4):
            row = M_MIXER + 4 * i
            wanted[i] = m[row] * thrust + m[row + 1] * tx + m[row + 2] * ty
    for i in range(4):
        target = math.sqrt(_clamp(wanted[i], 0.0, omega_sq_max))
        _drive(target, rotors[i], g, omega_max, out, i)


@_jit
def _drive(target, omega, g, omega_max, out, i):  # pragma: no cover - compiled
    """The motor loop: command that drives a (slow) motor to ``target`` faster."""
    out[i] = _clamp(target + g[G_MOTOR_BOOST] * (target - omega), 0.0, omega_max)


@_inline
def _offboard_thrust(q, sp, g, m, rate_sp):  # pragma: no cover - compiled
    """An offboard attitude and/or body-rate setpoint: the body rates it asks into
    ``rate_sp``; the collective thrust (N) it asks."""
    thrust_sp = 0.0 if math.isnan(sp[SP_THRUST]) else sp[SP_THRUST]
    thrust = m[M_MAX_THRUST] * _clamp(thrust_sp, 0.0, 1.0)
    if not math.isnan(sp[SP_ATT]):
        a = SP_ATT
        _attitude_loop(q, sp[a], sp[a + 1], sp[a + 2], sp[a + 3], g, rate_sp)
        if not math.isnan(sp[SP_RATES]):
            for k in range(3):
                rate_sp[k] += sp[SP_RATES + k]
    else:
        for k in range(3):
            rate_sp[k] = sp[SP_RATES + k]
    return thrust


@_inline
def _velocity_setpoint(state, sp, g, v, accel_ff):  # pragma: no cover - compiled
    """Position loop: velocity setpoint (m/s) into ``v`` and the acceleration fed forward
    into ``accel_ff``, limited to the speed limits; the horizontal part on the
    square-root law (approach_speed), so a far setpoint is reached at rest, braking
    within the acceleration limit."""
    for k in range(3):
        v[k] = sp[SP_VEL + k]
        accel_ff[k] = sp[SP_ACC + k]
    if not math.isnan(sp[SP_POS]):
        ex, ey = sp[SP_POS] - state[L.I_PX], sp[SP_POS + 1] - state[L.I_PY]
        distance = math.hypot(ex, ey)
        if distance > 0.0:
            decel = BRAKE_FRACTION * g[G_MAX_ACCEL_XY]
            speed = approach_speed(distance, g[G_POS_XY], decel)
            ux, uy = ex / distance, ey / distance
            v[0] += speed * ux
            v[1] += speed * uy
            closing = state[L.I_VX] * ux + state[L.I_VY] * uy
            if speed < g[G_POS_XY] * distance and closing > 0.0:
                # On the square-root curve: feed forward the deceleration that
                # following it takes (d speed/dt at the current closing speed).
                accel_ff[0] -= decel * closing / speed * ux
                accel_ff[1] -= decel * closing / speed * uy
        v[2] += g[G_POS_Z] * (sp[SP_POS + 2] - state[L.I_PZ])
    max_xy = g[G_MAX_SPEED_XY]
    if not math.isnan(sp[SP_MAX_XY]):
        max_xy = min(sp[SP_MAX_XY], max_xy)
    speed_xy = math.hypot(v[0], v[1])
    if speed_xy > max_xy:
        v[0] *= max_xy / speed_xy
        v[1] *= max_xy / speed_xy
    v[2] = _clamp(v[2], -g[G_MAX_SPEED_DOWN], g[G_MAX_SPEED_UP])


@_inline
def _acceleration(state, g, v, accel_ff, integral, dt, accel):  # pragma: no cover - compiled
    """Velocity loop: acceleration setpoint (m/s²) into ``accel`` from a PI loop on the
    velocity error; updates ``integral`` (anti-windup: not while saturated)."""
    vel = state[L.VEL]
    error = np.empty(3)
    for k in range(3):
        error[k] = v[k] - vel[k]
        gain = g[G_VEL_XY] if k < 2 else g[G_VEL_Z]
        accel[k] = accel_ff[k] + gain * error[k] + integral[k]
    accel_xy = math.hypot(accel[0], accel[1])
    if accel_xy > g[G_MAX_ACCEL_XY]:
        accel[0] *= g[G_MAX_ACCEL_XY] / accel_xy
        accel[1] *= g[G_MAX_ACCEL_XY] / accel_xy
    for k in range(3):
        if accel_xy <= g[G_MAX_ACCEL_XY]:  # anti-windup: not while saturated
            gain_i = g[G_VEL_XY_I] if k < 2 else g[G_VEL_Z_I]
            integral[k] += gain_i * error[k] * dt
        integral[k] = _clamp(integral[k], -INTEGRAL_LIMIT, INTEGRAL_LIMIT)


@_inline
def _thrust_and_attitude(state, sp, g, m, accel, rate_sp):  # pragma: no cover - compiled
    """The collective thrust (N) and the attitude that produce ``accel``, drag
    compensated; the body rates the attitude loop asks into ``rate_sp``."""
    q, vel = state[L.QUAT], state[L.VEL]
    qw, qx, qy, qz = q[0], q[1], q[2], q[3]
    mass, gravity = m[M_MASS], m[M_GRAVITY]
    speed = math.sqrt(vel[0] ** 2 + vel[1] ** 2 + vel[2] ** 2)
    f0 = mass * accel[0] + m[M_DRAG] * speed * vel[0]
    f1 = mass * accel[1] + m[M_DRAG] * speed * vel[1]
    f2 = mass * (accel[2] + gravity) + m[M_DRAG] * speed * vel[2]
    f2 = max(f2, 0.1 * mass * gravity)
    max_horizontal = f2 * math.tan(math.radians(g[G_MAX_TILT_DEG]))
    horizontal = math.hypot(f0, f1)
    if horizontal > max_horizontal:
        f0 *= max_horizontal / horizontal
        f1 *= max_horizontal / horizontal
    norm = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    z0, z1, z2 = f0 / norm, f1 / norm, f2 / norm
    yaw = sp[SP_YAW]
    if math.isnan(yaw):
        yaw = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    h0, h1 = math.cos(yaw), math.sin(yaw)
    y0, y1, y2 = -z2 * h1, z2 * h0, z0 * h1 - z1 * h0  # z_body × heading
    norm = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    y0, y1, y2 = y0 / norm, y1 / norm, y2 / norm
    x0, x1, x2 = y1 * z2 - y2 * z1, y2 * z0 - y0 * z2, y0 * z1 - y1 * z0
    dw, dx, dy, dz = _quat_from_axes(x0, x1, x2, y0, y1, y2, z0, z1, z2)
    # Thrust along the current body z: a tilted vehicle gets what it can use.
    up0 = 2 * (qw * qy + qx * qz)
    up1 = 2 * (qy * qz - qw * qx)
    up2 = 1 - 2 * (qx * qx + qy * qy)
    thrust = _clamp(f0 * up0 + f1 * up1 + f2 * up2, 0.0, m[M_MAX_THRUST])
    _attitude_loop(q, dw, dx, dy, dz, g, rate_sp)
    rate_sp[2] += sp[SP_YAW_RATE]
    return thrust


@_jit
def rotor_command(state, sp, g, m, integral, dt):  # pragma: no cover - compiled
    """(4,) rotor-speed commands (rad/s) for the vehicle ``state`` (one row of the
    physics layout), the setpoint row ``sp``, gains ``g`` and model ``m``; updates the
    velocity ``integral`` (3,) in place."""
    out = np.empty(4)
    rotors = state[L.ROTORS]
    if sp[SP_IDLE] != 0.0:
        integral[:] = 0.0
        idle = g[G_IDLE_FRACTION] * m[M_OMEGA_MAX]
        for i in range(4):
            _drive(idle, rotors[i], g, m[M_OMEGA_MAX], out, i)
        return out
    rate_sp = np.empty(3)
    if not (math.isnan(sp[SP_ATT]) and math.isnan(sp[SP_RATES])):  # offboard attitude
        thrust = _offboard_thrust(state[L.QUAT], sp, g, m, rate_sp)
        integral[:] = 0.0
    else:
        v, accel_ff, accel = np.empty(3), np.empty(3), np.empty(3)
        _velocity_setpoint(state, sp, g, v, accel_ff)
        _acceleration(state, g, v, accel_ff, integral, dt, accel)
        thrust = _thrust_and_attitude(state, sp, g, m, accel, rate_sp)
    # Rate loop: body torque (N·m), P on the rate error plus the gyroscopic term.
    w = state[L.RATES]
    j0, j1, j2 = m[M_JXX], m[M_JYY], m[M_JZZ]
    tx = j0 * g[G_RATE_RP] * (rate_sp[0] - w[0]) + (w[1] * j2 * w[2] - w[2] * j1 * w[1])
    ty = j1 * g[G_RATE_RP] * (rate_sp[1] - w[1]) + (w[2] * j0 * w[0] - w[0] * j2 * w[2])
    tz = j2 * g[G_RATE_YAW] * (rate_sp[2] - w[2]) + (w[0] * j1 * w[1] - w[1] * j0 * w[0])
    _mix_and_drive(thrust, tx, ty, tz, rotors, g, m, out)
    return out
