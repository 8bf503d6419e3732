"""The options every task accepts, checked once when an env is made."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from quadsitl.perturbations import faults as FT
from quadsitl.perturbations.delay import Delay
from quadsitl.perturbations.randomization import (
    AIRFRAME_COLUMNS,
    Randomization,
    airframe_scale_row,
    check_spread,
)
from quadsitl.physics import get_airframe
from quadsitl.physics.wind import Wind
from quadsitl.tasks import proximity

# Time steps a simulation can sensibly take: finer than 0.1 ms costs seconds per env
# step for nothing (RK4 at 0.01 s is already accurate, docs/physics.md); coarser than
# 50 ms is unstable for this airframe.
LIMITS = {"physics_dt": (1e-4, 0.05), "control_period": (1e-4, 1.0)}
MAX_EPISODE_SECONDS = 3600.0
# Start-state noise a task can sensibly draw (half-widths): beyond these the vehicle starts
# far outside every task's arena (waypoints lie within a few metres), faster than it can fly
# (about 10 m/s) or tumbling beyond what its rotors can stop.
NOISE_LIMITS = {
    "init_position_noise": (100.0, "m"),
    "init_attitude_noise": (math.pi / 2, "rad"),
    "init_velocity_noise": (20.0, "m/s"),
    "init_rate_noise": (20.0, "rad/s"),
}


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


@dataclass(frozen=True)
class TaskOptions:
    """Options every task accepts as keyword arguments.

    Attributes:
        airframe: airframe preset name (``"paper"``, ``"paper-x"``) or an Airframe.
        physics_dt: physics step, s (the paper: 0.01).
        control_period: seconds per env step, a whole number of physics steps (0.05).
        episode_seconds: episode length, s; None = the task's (paper) value.
        beta: action bandwidth β, rad/s: Ω_c = Ω_hover + β·a (Eq. 19; the paper: 35).
        init_position_noise: half-width, m, of a uniform offset added to the start
            position on each axis (0 = the paper's start).
        init_attitude_noise: half-width, rad, of uniform roll, pitch and yaw at start.
        init_velocity_noise: half-width, m/s, of a uniform start velocity per axis.
        init_rate_noise: half-width, rad/s, of uniform start body rates per axis.
        param_randomization: {parameter: fraction}: each episode, scale that airframe
            parameter by U(1 − f, 1 + f) (names: mass, inertia, thrust_coeff,
            torque_coeff, drag_coeff, aero_moment_coeff, motor_rate); the airframe part
            of ``randomize``, kept for existing configurations.
        wind: the weather every episode is flown in: a
            :class:`~quadsitl.physics.wind.Wind` or a dict of its fields (e.g.
            ``{"speed": 6, "from_deg": 270, "turbulence": "moderate"}``); None: still
            air. Each episode's turbulence is drawn from the env's own generator.
        delay: observation and actuation delay (:mod:`quadsitl.perturbations.delay`): a dict
            ``{"observation": s, "action": s}``, each seconds (held in whole physics
            steps) or a (low, high) range drawn per episode; None: none.
        randomize: domain randomisation (:mod:`quadsitl.perturbations.randomization`): True or
            "default" for every documented default, or a dict naming what to draw.
        airframe_scale: exact airframe scales, the same every episode, e.g.
            ``{"mass": 1.3}`` for a vehicle 30 % heavier.
        ground_effect: True: each rotor gains thrust near the ground (Cheeseman–Bennett;
            docs/physics.md). Off by default, in every task.
        faults: a motor that fails during every episode: ``{"motor": 2, "efficiency":
            0.6, "at": 1.0}`` (motor 1-4, thrust fraction 0..1, s into the episode), a
            sensor that sticks: ``{"sensor": "gps", "at": 2.0}``
            (:mod:`quadsitl.perturbations.sensor_faults`), or a list of them
            (:mod:`quadsitl.perturbations.faults`); None: healthy motors and sensors.
        sensor_noise: noise scale of the observation as the sensors would measure it
            (position and velocity as the GPS, rates as the gyroscope, attitude as an
            estimator: :mod:`quadsitl.physics.sensors.observation`); 0: the exact state.
            Rewards and episode ends keep reading the truth.
        observe_position: False: the observation's position slots (0-2) read 0, so a
            policy sees where it is only through its offsets to the goal (the same
            flight wherever it starts). True: the paper's observation.
        observe_integral: True: three more observation values at the end, the integral
            of the observed goal offset near the goal (m·s, world ENU, clamped;
            :mod:`quadsitl.tasks.error_integral`): integral action, so that a steady
            wind or a heavier airframe leaves no steady position error. False: the
            paper's observation.
        proximity_reward: ``{"weight": w, "radius": r}``: every step also earns
            w·max(0, 1 − d/r) for a distance d (m) to the goal, on top of the task's
            reward, so that precision pays (:mod:`quadsitl.tasks.proximity`); None: the
            paper's reward alone.
    """

    airframe: object = "paper"
    physics_dt: float = 0.01
    control_period: float = 0.05
    episode_seconds: float | None = None
    beta: float = 35.0
    init_position_noise: float = 0.0
    init_attitude_noise: float = 0.0
    init_velocity_noise: float = 0.0
    init_rate_noise: float = 0.0
    param_randomization: dict[str, float] | None = None
    wind: Wind | dict[str, Any] | None = None
    delay: Delay | dict[str, Any] | None = None
    randomize: Randomization | bool | str | dict[str, Any] | None = None
    airframe_scale: dict[str, float] | None = None
    sensor_noise: float = 0.0
    ground_effect: bool = False
    faults: Any = None
    observe_position: bool = True
    observe_integral: bool = False
    proximity_reward: dict[str, float] | None = None

    @classmethod
    def from_kwargs(cls, **options: object) -> TaskOptions:
        """Build from keyword arguments; an unknown name raises ValueError."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise ValueError(f"unknown task option(s) {unknown}; known: {sorted(known)}")
        return cls(**options)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        get_airframe(self.airframe)  # type: ignore[arg-type]
        for name in ("physics_dt", "control_period", "beta"):
            value = getattr(self, name)
            if not (_is_real(value) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        for name, (low, high) in LIMITS.items():
            value = getattr(self, name)
            if not low <= value <= high:
                raise ValueError(f"{name} must be in [{low:g}, {high:g}] s, got {value!r}")
        ratio = self.control_period / self.physics_dt
        if abs(ratio - round(ratio)) > 1e-9:
            raise ValueError(
                f"control_period ({self.control_period}) must be a whole number of "
                f"physics_dt ({self.physics_dt})"
            )
        seconds = self.episode_seconds
        if seconds is not None and not (
            _is_real(seconds) and self.control_period <= seconds <= MAX_EPISODE_SECONDS
        ):
            raise ValueError(
                f"episode_seconds must be in [control_period, {MAX_EPISODE_SECONDS:g}] s, "
                f"got {seconds!r}"
            )
        for name, (limit, unit) in NOISE_LIMITS.items():
            value = getattr(self, name)
            if not (_is_real(value) and 0 <= value <= limit):
                raise ValueError(f"{name} must be in [0, {limit:.4g}] {unit}, got {value!r}")
        noise = self.sensor_noise
        if not (_is_real(noise) and 0 <= noise <= 100):
            raise ValueError(f"sensor_noise must be a scale in [0, 100], got {noise!r}")
        self._check_param_randomization()
        object.__setattr__(self, "wind", self._weather())
        if not isinstance(self.ground_effect, bool):
            raise ValueError(f"ground_effect must be True or False, got {self.ground_effect!r}")
        for name in ("observe_position", "observe_integral"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        object.__setattr__(self, "faults", FT.parse_faults(self.faults))
        object.__setattr__(self, "proximity_reward", proximity.parse(self.proximity_reward))
        object.__setattr__(self, "delay", Delay.parse(self.delay))
        object.__setattr__(self, "randomize", self._randomization())
        airframe_scale_row(self.airframe_scale)

    def _weather(self) -> Wind | None:
        """The ``wind`` option as a checked Wind (None: still air)."""
        wind = self.wind
        if wind is None or isinstance(wind, Wind):
            return None if wind is None or wind.calm else wind
        if not isinstance(wind, dict):
            raise ValueError(
                "wind must be a Wind or a dict of its fields, e.g. "
                f"{{'speed': 6, 'from_deg': 270, 'turbulence': 'moderate'}}, got {wind!r}"
            )
        known = {f.name for f in dataclasses.fields(Wind)}
        unknown = sorted(set(wind) - known)
        if unknown:
            raise ValueError(f"unknown wind field(s) {unknown}; known: {sorted(known)}")
        weather = Wind(**wind)
        return None if weather.calm else weather

    def _randomization(self) -> Randomization | None:
        """``randomize`` (or the older ``param_randomization``) as a Randomization; a
        part of the world drawn per episode must not also be fixed by its own option."""
        randomization = Randomization.parse(self.randomize)
        if self.param_randomization:
            if randomization is not None:
                raise ValueError("give param_randomization or randomize, not both")
            return Randomization(airframe=dict(self.param_randomization))
        if randomization is not None:
            for part in ("wind", "delay"):
                if getattr(randomization, part) is not None and getattr(self, part) is not None:
                    raise ValueError(
                        f"{part} is both fixed ({part}=) and drawn (randomize); give one"
                    )
        return randomization

    def _check_param_randomization(self) -> None:
        randomization = self.param_randomization
        if randomization is None:
            return
        if not isinstance(randomization, dict):
            raise ValueError(
                "param_randomization must be a dict of parameter name to fraction, e.g. "
                f"{{'mass': 0.1}}, got {randomization!r}"
            )
        for name, fraction in randomization.items():
            if name not in AIRFRAME_COLUMNS:
                raise ValueError(
                    f"cannot randomise {name!r}; randomisable: {sorted(AIRFRAME_COLUMNS)}"
                )
            check_spread(name, fraction, "param_randomization")
