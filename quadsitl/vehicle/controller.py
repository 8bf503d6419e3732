"""The onboard flight controller: position -> velocity -> attitude -> rate -> mixer.

A cascade of simple loops in the simulator's own frames (world ENU, body FLU), as PX4's
multicopter controllers are arranged. It maps a :class:`Setpoint` and the vehicle state
to four rotor-speed commands (rad/s); nothing here touches the network. Anything with
the same ``rotor_command`` method (for instance a trained policy) can replace it.

Gains live in :class:`ControllerGains`; the MAVLink parameters of :mod:`.params` write
them. The paper's motors are slow (time constant 1/k_Ω = 0.18 s), so the innermost loop
closes around the measured rotor speeds (ESC telemetry) to speed the motors up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from quadsitl import frames
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import Airframe
from quadsitl.vehicle.params import PARAMETERS

Vec = NDArray[np.float64]


@dataclass
class Setpoint:
    """What the vehicle should do now. World ENU, body FLU, SI units.

    Position, velocity and acceleration combine as in PX4: a position (if given) is
    tracked with a P loop whose output adds to ``velocity`` (feed-forward); a ``None``
    position means velocity control. ``attitude``/``body_rates`` with ``thrust``
    override the outer loops (offboard attitude control); ``idle`` spins the rotors at
    idle speed on the ground.
    """

    position: Vec | None = None  # (3,) m
    velocity: Vec = field(default_factory=lambda: np.zeros(3))  # (3,) m/s
    acceleration: Vec = field(default_factory=lambda: np.zeros(3))  # (3,) m/s²
    yaw: float | None = None  # rad, ENU (None: keep the current heading)
    yaw_rate: float = 0.0  # rad/s, about world up
    attitude: Vec | None = None  # (4,) quaternion body FLU -> world ENU
    body_rates: Vec | None = None  # (3,) rad/s, FLU
    thrust: float | None = None  # fraction of the maximum collective thrust, 0..1
    idle: bool = False
    max_speed_xy: float | None = None  # m/s, overrides the parameter for this leg
    destination: Vec | None = None  # (3,) m, where the current leg ends (for autopilots
    # that fly to a goal, e.g. a trained policy, rather than along the path)
    landing: bool = False  # descending to touch down (Land)


@dataclass
class ControllerGains:
    """Loop gains and limits. Their defaults are the parameters' (the MAVLink parameter
    named in brackets sets each, :mod:`.params` holds its default, range and unit)."""

    pos_xy: float  # 1/s [MPC_XY_P]
    pos_z: float  # 1/s [MPC_Z_P]
    vel_xy: float  # 1/s [MPC_XY_VEL_P]
    vel_xy_i: float  # 1/s² [MPC_XY_VEL_I]
    vel_z: float  # 1/s [MPC_Z_VEL_P]
    vel_z_i: float  # 1/s² [MPC_Z_VEL_I]
    att_rp: float  # 1/s [MC_ROLL_P, also pitch]
    att_yaw: float  # 1/s [MC_YAW_P]
    rate_rp: float  # 1/s [MC_ROLLRATE_P, also pitch]
    rate_yaw: float  # 1/s [MC_YAWRATE_P]
    motor_boost: float  # rotor-speed loop gain, multiples of k_Ω [SIM_MOTOR_BOOST]
    max_speed_xy: float  # m/s [MPC_XY_VEL_MAX]
    max_speed_up: float  # m/s [MPC_Z_VEL_MAX_UP]
    max_speed_down: float  # m/s [MPC_Z_VEL_MAX_DN]
    max_accel_xy: float  # m/s² [MPC_ACC_HOR]
    max_tilt_deg: float  # deg [MPC_TILTMAX_AIR]
    max_rate_rp_deg: float  # deg/s [MC_ROLLRATE_MAX]
    max_rate_yaw_deg: float  # deg/s [MC_YAWRATE_MAX]
    idle_fraction: float  # idle rotor speed / Ω_max when armed on ground [SIM_IDLE]

    @classmethod
    def defaults(cls) -> ControllerGains:
        """Every gain at its parameter's default."""
        return cls(**{spec.gain: spec.default for spec in PARAMETERS if spec.gain})


class Autopilot(Protocol):
    """The seam for replacing the cascade (e.g. by a trained policy)."""

    def rotor_command(self, state: Vec, setpoint: Setpoint, dt: float) -> Vec:
        """(4,) rotor-speed commands, rad/s, for ``state`` (one row of the layout)."""
        ...

    def reset(self) -> None:
        """Forget integrators and filters (on arming, mode change or reset)."""
        ...


def allocation_matrix(airframe: Airframe) -> Vec:
    """(4, 4) A with [T, Mx, My, Mz] = A · Ω², body FLU; the physics' own moment model.

    Thrust f_i = kt Ω_i² along +z at r_i gives r_i × f_i = (y_i f_i, −x_i f_i, 0); the
    rotor's reaction adds sign_i · kq Ω_i² about +z.
    """
    r = airframe.rotor_positions()
    kt, kq = airframe.thrust_coeff, airframe.torque_coeff
    return np.vstack(
        [
            np.full(L.N_ROTORS, kt),
            kt * r[:, 1],
            -kt * r[:, 0],
            kq * np.asarray(airframe.rotor_yaw_sign, dtype=np.float64),
        ]
    )


class CascadedController:
    """PX4-style cascade over one vehicle; see the module docstring."""

    def __init__(self, airframe: Airframe, gains: ControllerGains | None = None) -> None:
        self.gains = gains or ControllerGains.defaults()
        self.set_airframe(airframe)

    def set_airframe(self, airframe: Airframe) -> None:
        """Re-derive the model terms (mass, inertia, mixer) from ``airframe``."""
        self.airframe = airframe
        self.mass = airframe.mass
        self.gravity = airframe.gravity
        self.inertia = np.asarray(airframe.inertia, dtype=np.float64)
        self.omega_max = airframe.max_rotor_speed
        self.max_thrust = L.N_ROTORS * airframe.thrust_coeff * self.omega_max**2
        self.mixer = np.linalg.inv(allocation_matrix(airframe))
        self.reset()

    def reset(self) -> None:
        self.vel_integral = np.zeros(3)  # m/s² contribution of the velocity I terms

    # --- the cascade ------------------------------------------------------------------
    def rotor_command(self, state: Vec, setpoint: Setpoint, dt: float) -> Vec:
        position, velocity = state[L.POS], state[L.VEL]
        q, rates, rotors = state[L.QUAT], state[L.RATES], state[L.ROTORS]
        if setpoint.idle:
            self.reset()
            return self._motor_loop(
                np.full(L.N_ROTORS, self.gains.idle_fraction * self.omega_max), rotors
            )
        yaw_now = float(frames.euler_from_quat(q)[2])
        if setpoint.attitude is not None or setpoint.body_rates is not None:
            thrust = self.max_thrust * float(np.clip(setpoint.thrust or 0.0, 0.0, 1.0))
            if setpoint.attitude is not None:
                rate_sp = self._attitude_loop(q, np.asarray(setpoint.attitude, np.float64))
                if setpoint.body_rates is not None:
                    rate_sp = rate_sp + setpoint.body_rates
            else:
                rate_sp = np.asarray(setpoint.body_rates, dtype=np.float64)
            self.reset()
        else:
            accel = self._velocity_loop(
                self._position_loop(position, setpoint), velocity, setpoint, dt
            )
            yaw = yaw_now if setpoint.yaw is None else setpoint.yaw
            thrust, q_des = self._thrust_and_attitude(accel, velocity, q, yaw)
            rate_sp = self._attitude_loop(q, q_des)
            rate_sp[2] += setpoint.yaw_rate
        torque = self._rate_loop(rates, rate_sp)
        return self._motor_loop(self._mix(thrust, torque), rotors)

    def _position_loop(self, position: Vec, sp: Setpoint) -> Vec:
        """Velocity setpoint (m/s, ENU), limited to the speed limits."""
        g = self.gains
        v = np.array(sp.velocity, dtype=np.float64)
        if sp.position is not None:
            error = sp.position - position
            v[:2] += g.pos_xy * error[:2]
            v[2] += g.pos_z * error[2]
        max_xy = g.max_speed_xy if sp.max_speed_xy is None else min(sp.max_speed_xy, g.max_speed_xy)
        speed_xy = math.hypot(v[0], v[1])
        if speed_xy > max_xy:
            v[:2] *= max_xy / speed_xy
        v[2] = min(max(v[2], -g.max_speed_down), g.max_speed_up)
        return v

    def _velocity_loop(self, velocity_sp: Vec, velocity: Vec, sp: Setpoint, dt: float) -> Vec:
        """Acceleration setpoint (m/s², ENU) from a PI loop on velocity."""
        g = self.gains
        error = velocity_sp - velocity
        gains_p = np.array([g.vel_xy, g.vel_xy, g.vel_z])
        gains_i = np.array([g.vel_xy_i, g.vel_xy_i, g.vel_z_i])
        accel = sp.acceleration + gains_p * error + self.vel_integral
        accel_xy = math.hypot(accel[0], accel[1])
        if accel_xy > g.max_accel_xy:
            accel[:2] *= g.max_accel_xy / accel_xy
        # Integrate only while not saturated (anti-windup), and bound the integral.
        if accel_xy <= g.max_accel_xy:
            self.vel_integral += gains_i * error * dt
        np.clip(self.vel_integral, -3.0, 3.0, out=self.vel_integral)
        return accel

    def _thrust_and_attitude(
        self, accel: Vec, velocity: Vec, q: Vec, yaw: float
    ) -> tuple[float, Vec]:
        """Collective thrust (N) and attitude (quaternion) that produce ``accel``."""
        drag = self.airframe.drag_coeff * np.linalg.norm(velocity) * velocity
        force = self.mass * (accel + np.array([0.0, 0.0, self.gravity])) + drag
        force[2] = max(force[2], 0.1 * self.mass * self.gravity)
        max_horizontal = force[2] * math.tan(math.radians(self.gains.max_tilt_deg))
        horizontal = math.hypot(force[0], force[1])
        if horizontal > max_horizontal:
            force[:2] *= max_horizontal / horizontal
        z_body = force / np.linalg.norm(force)
        heading = np.array([math.cos(yaw), math.sin(yaw), 0.0])
        y_body = np.cross(z_body, heading)
        y_body /= np.linalg.norm(y_body)
        x_body = np.cross(y_body, z_body)
        q_des = _quat_from_matrix(np.column_stack([x_body, y_body, z_body]))
        # Thrust along the current body z: a tilted vehicle gets what it can use.
        z_now = frames.quat_rotate(q, np.array([0.0, 0.0, 1.0]))
        thrust = float(np.clip(force @ z_now, 0.0, self.max_thrust))
        return thrust, q_des

    def _attitude_loop(self, q: Vec, q_des: Vec) -> Vec:
        """Body-rate setpoint (rad/s, FLU) from the quaternion error."""
        g = self.gains
        q_err = frames.quat_multiply(frames.quat_conjugate(q), q_des)
        if q_err[0] < 0:
            q_err = -q_err
        rate = 2.0 * q_err[1:] * np.array([g.att_rp, g.att_rp, g.att_yaw])
        max_rp, max_yaw = math.radians(g.max_rate_rp_deg), math.radians(g.max_rate_yaw_deg)
        rate[:2] = np.clip(rate[:2], -max_rp, max_rp)
        rate[2] = min(max(rate[2], -max_yaw), max_yaw)
        return rate

    def _rate_loop(self, rates: Vec, rate_sp: Vec) -> Vec:
        """Body torque (N·m, FLU): P on the rate error plus the gyroscopic term."""
        g = self.gains
        gains = np.array([g.rate_rp, g.rate_rp, g.rate_yaw])
        return self.inertia * gains * (rate_sp - rates) + np.cross(rates, self.inertia * rates)

    def _mix(self, thrust: float, torque: Vec) -> Vec:
        """Rotor speeds (rad/s) for thrust and torque; yaw gives way first when saturated."""
        omega_sq_max = self.omega_max**2
        omega_sq = self.mixer @ np.array([thrust, *torque])
        if omega_sq.min() < 0 or omega_sq.max() > omega_sq_max:
            omega_sq = self.mixer @ np.array([thrust, torque[0], torque[1], 0.0])
        return np.sqrt(np.clip(omega_sq, 0.0, omega_sq_max))

    def _motor_loop(self, omega_target: Vec, omega: Vec) -> Vec:
        """Command that drives the (slow) motors to ``omega_target`` faster."""
        cmd = omega_target + self.gains.motor_boost * (omega_target - omega)
        return np.clip(cmd, 0.0, self.omega_max)


def _quat_from_matrix(r: Vec) -> Vec:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    out = np.array(q)
    return out / np.linalg.norm(out)
