"""The flight dynamics of the paper in plain numpy: the readable reference.

Pure functions over batched arrays (layout in :mod:`quadsitl.physics.layout`):
``derivative(state, params, rotor_cmd) -> dstate``, a generic :func:`rk4`, and
:func:`ground_contact`; :func:`step_in_place` runs them, after the weather, under the
kernel's in-place contract (the ``"reference"`` backend of the Fleet). The compiled
kernel (:mod:`quadsitl.physics.kernel`) computes the same thing fast and is tested
against this module.

Model (world ENU, body FLU, paper Eqs. 1-9 with the moment signs of Σ r_i × F_i):

* thrust T_i = η_i G_i kt Ω_i² along body +z; m v̇ = R e_z ΣT_i − kd |v_a| v_a − m g e_z
* q̇ = ½ q ⊗ (0, ω)
* J ω̇ = Σ r_i × T_i e_z + Σ s_i η_i kq Ω_i² e_z − km |ω_a| ω_a − ω × J ω

η_i is rotor i's efficiency (1 healthy, 0 dead: a motor fault) and G_i its ground-effect
gain (:mod:`quadsitl.physics.ground_effect`; 1 where it is off); both 1 by default.

v_a = v − w and ω_a = ω − ω_w are the velocity and rates relative to the air (w, ω_w:
the air's velocity and angular velocity, :mod:`quadsitl.physics.wind`); in still air
they are v and ω. The world around a vehicle (the air, and G_i at its hub heights) is
evaluated at the start of each physics step and held over the step's RK4 stages.
* Ω̇ = k_Ω (Ω_c − Ω), Ω_c clipped to [0, Ω_max]; the rotor speeds are integrated
  inside RK4 together with the rigid body.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from quadsitl.frames import quat_to_matrix
from quadsitl.physics import layout as L
from quadsitl.physics import wind
from quadsitl.physics.ground_effect import thrust_ratio

Array = NDArray[np.float64]


def derivative(
    state: Array,
    params: Array,
    rotor_cmd: Array,
    air: Array | None = None,
    gain: Array | None = None,
) -> Array:
    """Time derivative of the (N, 17) state under commanded rotor speeds (N, 4) rad/s.

    ``air``: None (still air) or (N, 6): the air's velocity (m/s, world ENU) and angular
    velocity (rad/s, body FLU), held over the step. ``gain``: (N, 4) the rotors'
    ground-effect gains G_i held over the step (:func:`ground_effect_gains`), or None:
    those of ``state``.
    """
    vel = state[:, L.VEL]  # (N, 3) m/s, world
    qw, qx, qy, qz = state[:, L.QUAT].T  # body -> world
    rates = state[:, L.RATES]  # (N, 3) rad/s, body
    rotors = state[:, L.ROTORS]  # (N, 4) rad/s
    mass = params[:, L.P_MASS]
    inertia = params[:, L.P_INERTIA]  # (N, 3)

    rotor_sq = rotors * rotors * params[:, L.P_ROTOR_EFFICIENCY]  # (N, 4) η_i Ω_i², (rad/s)²
    if gain is None:
        gain = ground_effect_gains(state, params)
    thrust = params[:, [L.P_KT]] * rotor_sq * gain  # (N, 4) N per rotor
    total_thrust = thrust.sum(axis=1)
    body_z_in_world = np.stack(
        [2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx), 1 - 2 * (qx * qx + qy * qy)], axis=1
    )
    air_vel = vel if air is None else vel - air[:, 0:3]  # (N, 3) m/s, world: through the air
    speed = np.linalg.norm(air_vel, axis=1, keepdims=True)
    force = total_thrust[:, None] * body_z_in_world - params[:, [L.P_KD]] * speed * air_vel
    accel = force / mass[:, None]
    accel[:, 2] -= params[:, L.P_GRAVITY]

    wx, wy, wz = rates.T
    quat_dot = 0.5 * np.stack(
        [
            -qx * wx - qy * wy - qz * wz,
            qw * wx + qy * wz - qz * wy,
            qw * wy - qx * wz + qz * wx,
            qw * wz + qx * wy - qy * wx,
        ],
        axis=1,
    )

    rotor_x, rotor_y = params[:, L.P_ROTOR_X], params[:, L.P_ROTOR_Y]
    moment = np.stack(
        [
            (rotor_y * thrust).sum(axis=1),  # r × F with F = T e_z: (y T, −x T, 0)
            -(rotor_x * thrust).sum(axis=1),
            params[:, L.P_KQ] * (params[:, L.P_ROTOR_YAW_SIGN] * rotor_sq).sum(axis=1),
        ],
        axis=1,
    )
    air_rates = rates if air is None else rates - air[:, 3:6]  # (N, 3) rad/s, body
    rate_norm = np.linalg.norm(air_rates, axis=1, keepdims=True)
    moment -= params[:, [L.P_KM]] * rate_norm * air_rates
    moment -= np.cross(rates, inertia * rates)
    rates_dot = moment / inertia

    cmd = np.clip(rotor_cmd, 0.0, params[:, [L.P_OMEGA_MAX]])
    rotors_dot = params[:, [L.P_MOTOR_RATE]] * (cmd - rotors)

    return np.concatenate([vel, accel, quat_dot, rates_dot, rotors_dot], axis=1)


def ground_effect_gains(state: Array, params: Array) -> Array:
    """(N, 4) G_i: each rotor's ground-effect gain at its hub height (1 where it is off)."""
    height = hub_heights(state, params) - params[:, [L.P_GROUND_Z]]  # (N, 4) m, +inf: no ground
    ratio = thrust_ratio(height, params[:, [L.P_ROTOR_RADIUS]])
    return np.where(params[:, [L.P_GROUND_EFFECT]] > 0, ratio, 1.0)


def hub_heights(state: Array, params: Array) -> Array:
    """(N, 4) m: each rotor hub's height, world z."""
    qw, qx, qy, qz = state[:, L.QUAT].T
    hub_z = (
        state[:, [L.I_PZ]]
        + 2 * (qx * qz - qw * qy)[:, None] * params[:, L.P_ROTOR_X]
        + 2 * (qy * qz + qw * qx)[:, None] * params[:, L.P_ROTOR_Y]
    )
    return hub_z


def rk4(f: Callable[[Array], Array], y: Array, dt: float) -> Array:
    """One classical Runge-Kutta step of ``ẏ = f(y)``."""
    k1 = f(y)
    k2 = f(y + 0.5 * dt * k1)
    k3 = f(y + 0.5 * dt * k2)
    k4 = f(y + dt * k3)
    return y + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def ground_contact(
    previous: Array, state: Array, params: Array, contact: NDArray[np.int8], touchdown_speed: Array
) -> tuple[Array, NDArray[np.int8], Array]:
    """Resolve contact with the flat ground after an integration step.

    Args:
        previous: (N, 17) state before the step (crashed vehicles stay where they were).
        state: (N, 17) state after the free-flight step.
        params: (N, N_PARAMS).
        contact: (N,) contact state before the step (layout.AIRBORNE/ON_GROUND/CRASHED).
        touchdown_speed: (N,) m/s, vertical speed at the last touchdown.

    Returns:
        The corrected state, the new contact state and the touchdown speeds.
        A crash is sticky: the rigid body stays put until the vehicle is reset.
    """
    state = state.copy()
    contact = contact.copy()
    touchdown_speed = touchdown_speed.copy()
    crashed = contact == L.CRASHED
    state[crashed, : L.ROTORS.start] = previous[crashed, : L.ROTORS.start]

    qw, qx, qy, qz = state[:, L.QUAT].T
    pz, vz = state[:, L.I_PZ], state[:, L.I_VZ]
    ground_z = params[:, L.P_GROUND_Z]
    cos_tilt = 1 - 2 * (qx * qx + qy * qy)  # world z of the body z axis
    # Lowest point of each rotor disc: hub height minus radius × sin(tilt).
    hub_z = hub_heights(state, params)
    sin_tilt = np.sqrt(np.maximum(0.0, 1.0 - cos_tilt * cos_tilt))
    disc_low = hub_z - (params[:, L.P_ROTOR_RADIUS] * sin_tilt)[:, None]
    strike = (disc_low < ground_z[:, None]).any(axis=1) & ~crashed
    rest_z = ground_z + params[:, L.P_GEAR_HEIGHT]
    below = (pz < rest_z) & ~crashed & ~strike
    touching = below & (contact != L.ON_GROUND)
    speed = -vz
    too_hard = touching & (
        (speed > params[:, L.P_MAX_TOUCHDOWN_SPEED]) | (cos_tilt < params[:, L.P_COS_MAX_TILT])
    )
    touchdown_speed[touching] = np.maximum(speed[touching], 0.0)

    new_crash = strike | too_hard
    resting = below & ~too_hard
    stopped = new_crash | resting
    state[stopped, L.I_PZ] = np.maximum(state[stopped, L.I_PZ], rest_z[stopped])
    state[stopped, L.VEL] = 0.0
    state[stopped, L.RATES] = 0.0
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    level = np.zeros((int(resting.sum()), 4))
    level[:, 0] = np.cos(0.5 * yaw[resting])
    level[:, 3] = np.sin(0.5 * yaw[resting])
    state[resting, L.QUAT] = level

    contact[~crashed] = L.AIRBORNE
    contact[resting] = L.ON_GROUND
    contact[new_crash] = L.CRASHED
    return state, contact, touchdown_speed


def step(
    state: Array,
    params: Array,
    rotor_cmd: Array,
    contact: NDArray[np.int8],
    touchdown_speed: Array,
    dt: float,
    air: Array | None = None,
) -> tuple[Array, NDArray[np.int8], Array]:
    """One physics step of length ``dt`` (s): RK4, renormalised attitude, ground contact.

    ``air``: as in :func:`derivative`. The air and the ground-effect gains of the
    step's start are held over its stages."""
    gain = ground_effect_gains(state, params)
    new = rk4(lambda y: derivative(y, params, rotor_cmd, air, gain), state, dt)
    new[:, L.QUAT] /= np.linalg.norm(new[:, L.QUAT], axis=1, keepdims=True)
    new[:, L.ROTORS] = np.clip(new[:, L.ROTORS], 0.0, params[:, [L.P_OMEGA_MAX]])
    return ground_contact(state, new, params, contact, touchdown_speed)


def step_in_place(
    state,
    params,
    rotor_cmd,
    contact,
    touchdown_speed,
    dt,
    n_substeps,
    wind_params=None,
    wind_state=None,
    streams=None,
) -> int:
    """The kernel's ``step`` contract in numpy (the reference backend of
    :class:`~quadsitl.physics.fleet.Fleet`): ``n_substeps`` steps in place; returns -1,
    or the first vehicle with a non-finite command (and then changes nothing). The
    weather (:func:`quadsitl.physics.wind.advance`) steps before each physics step
    unless every vehicle is in still air (no weather arrays)."""
    cmd = rotor_cmd.reshape(len(state), L.N_ROTORS)
    bad_rows = ~np.isfinite(cmd).all(axis=1)
    if bad_rows.any():
        return int(np.argmax(bad_rows))
    for _ in range(n_substeps):
        air = None
        if wind_params is not None:
            wind.advance(wind_state, wind_params, state, params, streams, dt)
            rotation = quat_to_matrix(state[:, L.QUAT])  # (N, 3, 3) body -> world
            rates_body = np.einsum("nji,nj->ni", rotation, wind_state[:, L.WS_AIR_RATES])
            air = np.concatenate([wind_state[:, L.WS_AIR_VELOCITY], rates_body], axis=1)
        state[:], contact[:], touchdown_speed[:] = step(
            state, params, cmd, contact, touchdown_speed, dt, air
        )
    return -1
