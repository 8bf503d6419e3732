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

from quadsitl.flight_software import cascade as C
from quadsitl.flight_software.params import PARAMETERS
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import Airframe

Vec = NDArray[np.float64]


@dataclass
class Setpoint:
    """What the vehicle should do now. World ENU, body FLU, SI units.

    Position, velocity and acceleration combine as in PX4: a position (if given) is
    tracked with a P loop whose output adds to ``velocity`` (feed-forward); far from
    the position the horizontal speed follows a square-root law instead, so that the
    vehicle brakes to it within the acceleration limit (docs/mavlink.md, "How position
    setpoints are flown"); a ``None`` position means velocity control.
    ``attitude``/``body_rates`` with ``thrust`` override the outer loops (offboard
    attitude control); ``idle`` spins the rotors at idle speed on the ground.
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
    _row: Vec | None = field(default=None, init=False, repr=False, compare=False)

    @classmethod
    def defaults(cls) -> ControllerGains:
        """Every gain at its parameter's default."""
        return cls(**{spec.gain: spec.default for spec in PARAMETERS if spec.gain})

    def __setattr__(self, name: str, value: float) -> None:
        object.__setattr__(self, name, value)
        object.__setattr__(self, "_row", None)  # a gain changed: pack them again

    def row(self) -> Vec:
        """The gains in :data:`quadsitl.flight_software.cascade.GAIN_FIELDS` order (kept until a
        gain changes)."""
        row = self._row
        if row is None:
            row = np.array([getattr(self, f) for f in C.GAIN_FIELDS])
            object.__setattr__(self, "_row", row)
        return row


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
    """PX4-style cascade over one vehicle; see the module docstring. The arithmetic is
    compiled in :mod:`quadsitl.flight_software.cascade`; this class holds the gains, the model
    and the velocity integral, and packs each setpoint for it."""

    def __init__(self, airframe: Airframe, gains: ControllerGains | None = None) -> None:
        self.gains = gains or ControllerGains.defaults()
        self.setpoint_row = np.empty(C.SP_SIZE)
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
        self.model_row = np.array(
            [
                self.mass,
                self.gravity,
                *self.inertia,
                self.omega_max,
                self.max_thrust,
                airframe.drag_coeff,
                *self.mixer.ravel(),
            ]
        )
        if self.model_row.shape != (C.M_SIZE,):  # the compiled code reads it by position
            raise AssertionError(f"model row of {self.model_row.size} values, not {C.M_SIZE}")
        self.reset()

    def reset(self) -> None:
        self.vel_integral = np.zeros(3)  # m/s² contribution of the velocity I terms

    def rotor_command(self, state: Vec, setpoint: Setpoint, dt: float) -> Vec:
        return C.rotor_command(
            state, self._pack(setpoint), self.gains.row(), self.model_row, self.vel_integral, dt
        )

    def _pack(self, sp: Setpoint) -> Vec:
        """The setpoint as the row :func:`quadsitl.flight_software.cascade.rotor_command` reads
        (NaN where a part is absent)."""
        row = self.setpoint_row
        row.fill(math.nan)
        if sp.position is not None:
            row[C.SP_POS : C.SP_POS + 3] = sp.position
        row[C.SP_VEL : C.SP_VEL + 3] = sp.velocity
        row[C.SP_ACC : C.SP_ACC + 3] = sp.acceleration
        if sp.yaw is not None:
            row[C.SP_YAW] = sp.yaw
        row[C.SP_YAW_RATE] = sp.yaw_rate
        if sp.attitude is not None:
            row[C.SP_ATT : C.SP_ATT + 4] = sp.attitude
        if sp.body_rates is not None:
            row[C.SP_RATES : C.SP_RATES + 3] = sp.body_rates
        if sp.thrust is not None:
            row[C.SP_THRUST] = sp.thrust
        row[C.SP_IDLE] = 1.0 if sp.idle else 0.0
        if sp.max_speed_xy is not None:
            row[C.SP_MAX_XY] = sp.max_speed_xy
        return row
