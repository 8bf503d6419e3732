"""Airframes as data: one frozen dataclass per vehicle type, with units and sources.

The default preset ``"paper"`` is the plus-configuration airframe of the paper, with the
numbers read from the authors' code (the table and its source: docs/physics.md). ``"paper-x"``
is the same vehicle with its arms turned 45° into an X, rotors numbered as PX4 does.

Derived quantities (hover and maximum rotor speed) are computed here and nowhere else.
Body frame: Forward-Left-Up. Rotor positions are body-frame (x, y) in metres.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from quadsitl.physics import layout as L

SQRT_HALF = math.sqrt(0.5)


def hover_rotor_speed(mass: Any, gravity: Any, thrust_coeff: Any) -> Any:
    """Ω_h = sqrt(m g / (4 kt)), rad/s: each rotor carries a quarter of the weight.

    Works on floats and on per-vehicle arrays alike.
    """
    return (mass * gravity / (L.N_ROTORS * thrust_coeff)) ** 0.5


@dataclass(frozen=True)
class Airframe:
    """Physical parameters of one quadrotor. Every field: unit, then source."""

    name: str
    mass: float = 0.65  # kg; docs/physics.md
    inertia: tuple[float, float, float] = (7.5e-3, 7.5e-3, 1.3e-2)  # kg·m², diagonal J; paper-ref
    arm_length: float = 0.23  # m, centre of mass to rotor axis; docs/physics.md
    thrust_coeff: float = 3.13e-5  # N/(rad/s)², kt; docs/physics.md
    torque_coeff: float = 7.5e-7  # N·m/(rad/s)², kq; docs/physics.md
    drag_coeff: float = 9e-3  # N/(m/s)², kd in F = -kd|v|v; docs/physics.md
    aero_moment_coeff: float = 9e-4  # N·m/(rad/s)², km in M = -km|ω|ω; docs/physics.md
    motor_rate: float = 1.0 / 0.18  # 1/s, k_Ω in Ω̇ = -k_Ω(Ω - Ω_c); docs/physics.md
    hover_thrust_fraction: float = 0.5  # hover thrust / max thrust (T/W = 2); docs/physics.md
    gravity: float = 9.81  # m/s²; docs/physics.md
    rotor_radius: float = 0.1  # m, for crash geometry only; docs/physics.md
    # Rotor i sits at rotor_xy[i] (m, body FLU) and reacts on the body with
    # rotor_yaw_sign[i]·kq·Ω_i² about +z. Plus layout, paper numbering:
    # 1 front, 2 left, 3 back, 4 right; Mz = kq(−Ω1² + Ω2² − Ω3² + Ω4²).
    rotor_xy: tuple[tuple[float, float], ...] = ((1, 0), (0, 1), (-1, 0), (0, -1))
    rotor_yaw_sign: tuple[float, float, float, float] = (-1.0, 1.0, -1.0, 1.0)
    # Ground contact. Not in the paper: chosen for a 0.65 kg racer-size frame.
    gear_height: float = 0.1  # m, centre of mass above ground when resting
    max_touchdown_speed: float = 1.0  # m/s, faster vertical touchdown is a crash
    max_touchdown_tilt_deg: float = 15.0  # deg, more tilted touchdown is a crash

    def __post_init__(self) -> None:
        positive = (
            "mass",
            "arm_length",
            "thrust_coeff",
            "torque_coeff",
            "motor_rate",
            "gravity",
            "rotor_radius",
            "gear_height",
            "max_touchdown_speed",
            "max_touchdown_tilt_deg",
        )
        for field in positive:
            value = getattr(self, field)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"airframe {self.name!r}: {field} must be positive, got {value}")
        for field in ("drag_coeff", "aero_moment_coeff"):
            value = getattr(self, field)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"airframe {self.name!r}: {field} must be >= 0, got {value}")
        if len(self.inertia) != 3 or not all(math.isfinite(j) and j > 0 for j in self.inertia):
            raise ValueError(
                f"airframe {self.name!r}: inertia must be 3 positive values, got {self.inertia}"
            )
        if not 0 < self.hover_thrust_fraction < 1:
            raise ValueError(
                f"airframe {self.name!r}: hover_thrust_fraction must be in (0, 1), "
                f"got {self.hover_thrust_fraction}"
            )
        if len(self.rotor_xy) != L.N_ROTORS or len(self.rotor_yaw_sign) != L.N_ROTORS:
            raise ValueError(f"airframe {self.name!r}: needs exactly {L.N_ROTORS} rotors")
        if not self.max_touchdown_tilt_deg < 90:
            raise ValueError(f"airframe {self.name!r}: max_touchdown_tilt_deg must be < 90")

    # --- derived values: computed here only ---------------------------------------------

    @property
    def weight(self) -> float:
        """N."""
        return self.mass * self.gravity

    @property
    def hover_rotor_speed(self) -> float:
        """Ω_h, rad/s (see :func:`hover_rotor_speed`)."""
        return float(hover_rotor_speed(self.mass, self.gravity, self.thrust_coeff))

    @property
    def max_rotor_speed(self) -> float:
        """Ω_max = Ω_h / sqrt(hover thrust fraction), rad/s (thrust grows with Ω²)."""
        return self.hover_rotor_speed / math.sqrt(self.hover_thrust_fraction)

    @property
    def terminal_velocity(self) -> float:
        """Free-fall terminal speed sqrt(m g / kd), m/s (inf without drag)."""
        return math.sqrt(self.weight / self.drag_coeff) if self.drag_coeff > 0 else math.inf

    def rotor_positions(self) -> np.ndarray:
        """(4, 3) rotor hub positions in body FLU, m."""
        xy = np.asarray(self.rotor_xy, dtype=np.float64) * self.arm_length
        return np.column_stack([xy, np.zeros(L.N_ROTORS)])

    def replace(self, **changes: Any) -> Airframe:
        """A copy with some fields changed (validated). Unknown names raise ValueError."""
        known = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise ValueError(f"unknown airframe parameter(s) {unknown}; known: {sorted(known)}")
        return dataclasses.replace(self, **changes)

    def to_params(self, ground_z: float = 0.0) -> np.ndarray:
        """One row of the per-vehicle parameter array read by the physics (see layout)."""
        row = np.empty(L.N_PARAMS)
        row[L.P_MASS] = self.mass
        row[L.P_INERTIA] = self.inertia
        row[L.P_KT] = self.thrust_coeff
        row[L.P_KQ] = self.torque_coeff
        row[L.P_KD] = self.drag_coeff
        row[L.P_KM] = self.aero_moment_coeff
        row[L.P_MOTOR_RATE] = self.motor_rate
        row[L.P_OMEGA_MAX] = self.max_rotor_speed
        row[L.P_GRAVITY] = self.gravity
        row[L.P_ROTOR_RADIUS] = self.rotor_radius
        row[L.P_GEAR_HEIGHT] = self.gear_height
        row[L.P_MAX_TOUCHDOWN_SPEED] = self.max_touchdown_speed
        row[L.P_COS_MAX_TILT] = math.cos(math.radians(self.max_touchdown_tilt_deg))
        row[L.P_GROUND_Z] = ground_z
        positions = self.rotor_positions()
        row[L.P_ROTOR_X] = positions[:, 0]
        row[L.P_ROTOR_Y] = positions[:, 1]
        row[L.P_ROTOR_YAW_SIGN] = self.rotor_yaw_sign
        row[L.P_GROUND_EFFECT] = 0.0  # the world beyond the airframe: set by the Fleet
        row[L.P_ROTOR_EFFICIENCY] = 1.0
        return row


PAPER = Airframe(name="paper")
"""The paper's plus-configuration quadrotor (default)."""

PAPER_X = Airframe(
    name="paper-x",
    # X layout, PX4 numbering: 1 front-right, 2 back-left, 3 front-left, 4 back-right;
    # 1 and 2 spin counter-clockwise seen from above (reaction torque −z).
    rotor_xy=(
        (SQRT_HALF, -SQRT_HALF),
        (-SQRT_HALF, SQRT_HALF),
        (SQRT_HALF, SQRT_HALF),
        (-SQRT_HALF, -SQRT_HALF),
    ),
    rotor_yaw_sign=(-1.0, -1.0, 1.0, 1.0),
)
"""The same vehicle with its arms in an X (PX4 motor order)."""

PAPER_X_FAST = PAPER_X.replace(name="paper-x-fast", motor_rate=1.0 / 0.03)
"""paper-x with a 0.03 s motor (1/s: 1/0.03), typical of real quadrotor motors (0.02–0.05 s):
the paper's 0.18 s motor makes ArduPilot's and PX4's stock gains unstable (docs/autopilots.md)."""

# 3DR Iris as PX4's Gazebo-classic model (models/iris/iris.sdf) gives it; docs/autopilots.md.
_IRIS_ROTORS_M = ((0.13, -0.22), (-0.13, 0.20), (0.13, 0.22), (-0.13, -0.20))  # body FLU, m
_IRIS_ARM = math.hypot(0.13, 0.22)  # m, the longer (front) arms
_IRIS_KT = 5.84e-6  # N/(rad/s)², motorConstant
_IRIS_MAX_ROTOR_SPEED = 1100.0  # rad/s, maxRotVelocity
IRIS = Airframe(
    name="iris",
    mass=1.5,  # kg, base_link
    inertia=(0.029125, 0.029125, 0.055225),  # kg·m², base_link
    arm_length=_IRIS_ARM,
    thrust_coeff=_IRIS_KT,
    torque_coeff=0.06 * _IRIS_KT,  # N·m/(rad/s)², momentConstant (m) × motorConstant
    # 1/s: the model's single lag takes the mean of timeConstantUp 0.0125 s and Down 0.025 s
    motor_rate=1.0 / (0.5 * (0.0125 + 0.025)),
    # hover thrust / thrust at maxRotVelocity, so that Ω_max is the model's 1,100 rad/s
    hover_thrust_fraction=1.5 * 9.81 / (L.N_ROTORS * _IRIS_KT * _IRIS_MAX_ROTOR_SPEED**2),
    rotor_radius=0.128,  # m, rotor collision cylinder
    # PX4 numbering as paper-x; rotors 1 and 2 turn counter-clockwise ("ccw" in the model)
    rotor_xy=tuple((x / _IRIS_ARM, y / _IRIS_ARM) for x, y in _IRIS_ROTORS_M),
    rotor_yaw_sign=(-1.0, -1.0, 1.0, 1.0),
)
"""The 3DR Iris of PX4's and ArduPilot's default Gazebo vehicle (quad X, PX4 motor order);
drag, aerodynamic moment and landing gear are the paper's (the Gazebo model has none of those
in this form)."""

AIRFRAMES: dict[str, Airframe] = {a.name: a for a in (PAPER, PAPER_X, PAPER_X_FAST, IRIS)}


def get_airframe(airframe: str | Airframe) -> Airframe:
    """Look an airframe up by preset name, or pass an :class:`Airframe` through."""
    if isinstance(airframe, Airframe):
        return airframe
    try:
        return AIRFRAMES[airframe]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown airframe {airframe!r}; known presets: {sorted(AIRFRAMES)}"
        ) from None
