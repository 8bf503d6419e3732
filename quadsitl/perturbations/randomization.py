"""Domain randomisation: what each episode draws, from documented distributions.

One option, ``randomize=``, draws per episode and per env, from the env's own generator:

* the **airframe**: each named parameter scaled by U(1 − f, 1 + f) (mass, inertia,
  thrust and torque coefficients, motor rate = 1 / motor time constant, drag and
  aerodynamic-moment coefficients);
* the **wind**: mean speed U(low, high) m/s from a direction U(low, high)°, and a
  turbulence level chosen uniformly from a list (:class:`WindDraw`);
* the **delay**: observation and actuation delay ranges (:class:`~.delay.Delay`);
* **sensor noise**: a hook for the sensor models (none yet: only None is accepted).

``airframe_scale=`` scales parameters exactly (the same every episode), e.g. a vehicle
30 % heavier; randomisation then draws around the scaled values.

What stays nominal, as a real controller's knowledge of its vehicle would: Eq. 19's
hover speed Ω_h (action 0), the action bounds, and Ω_max (the motors' own limit, which
normalises the rotor observation). Each episode starts with the rotors at the drawn
vehicle's own hover speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from quadsitl.perturbations.delay import Delay
from quadsitl.physics import layout as L
from quadsitl.physics.wind import MAX_WIND_SPEED, Wind

# Parameter columns each airframe scale acts on.
AIRFRAME_COLUMNS: dict[str, list[int]] = {
    "mass": [L.P_MASS],
    "inertia": [L.P_JXX, L.P_JYY, L.P_JZZ],
    "thrust_coeff": [L.P_KT],
    "torque_coeff": [L.P_KQ],
    "drag_coeff": [L.P_KD],
    "aero_moment_coeff": [L.P_KM],
    "motor_rate": [L.P_MOTOR_RATE],
}
# Default half-widths f of U(1 − f, 1 + f): manufacturing spread, payload and battery for
# mass and inertia; propeller wear and air density for the rotor coefficients; motor
# and ESC response for the motor rate; the drag law's coefficients are the least known.
DEFAULT_AIRFRAME_SPREAD: dict[str, float] = {
    "mass": 0.2,
    "inertia": 0.2,
    "thrust_coeff": 0.1,
    "torque_coeff": 0.1,
    "motor_rate": 0.2,
    "drag_coeff": 0.3,
    "aero_moment_coeff": 0.3,
}
DEFAULT_DELAY = Delay(observation=(0.0, 0.02), action=(0.0, 0.02))  # s
MAX_SCALE = 10.0  # an exact airframe scale beyond 0.1x..10x is not the same vehicle


@dataclass(frozen=True)
class WindDraw:
    """The weather drawn per episode: speed U(speed) m/s blowing from U(from_deg)°
    (clockwise from north), turbulence one of ``turbulence`` (each equally likely)."""

    speed: tuple[float, float] = (0.0, 5.0)
    from_deg: tuple[float, float] = (0.0, 360.0)
    turbulence: tuple[str | float | None, ...] = (None, "light")

    def __post_init__(self) -> None:
        for name in ("speed", "from_deg"):
            pair = getattr(self, name)
            if not (
                isinstance(pair, (tuple, list))
                and len(pair) == 2
                and all(_is_real(v) and math.isfinite(v) for v in pair)
                and pair[0] <= pair[1]
            ):
                raise ValueError(
                    f"randomize wind {name} must be a finite (low, high) pair, got {pair!r}"
                )
        if self.speed[0] < 0 or self.speed[1] > MAX_WIND_SPEED:
            raise ValueError(
                f"randomize wind speed must be >= 0 m/s and at most {MAX_WIND_SPEED:g} m/s, "
                f"got {self.speed!r}"
            )
        if not isinstance(self.turbulence, (tuple, list)) or not self.turbulence:
            raise ValueError(
                f"randomize wind turbulence must be a non-empty list, got {self.turbulence!r}"
            )
        for level in self.turbulence:  # each checked as Wind checks it
            Wind(turbulence=level)

    def draw(self, rng: np.random.Generator) -> Wind:
        # low + (high − low)·u is what rng.uniform(low, high) computes, from the same u,
        # without its argument checks (a quarter of the time).
        (speed_low, speed_high), (from_low, from_high) = self.speed, self.from_deg
        speed = speed_low + (speed_high - speed_low) * rng.random()
        from_deg = from_low + (from_high - from_low) * rng.random()
        level = self.turbulence[int(rng.integers(len(self.turbulence)))]
        return Wind(speed=float(speed), from_deg=float(from_deg), turbulence=level)


@dataclass(frozen=True)
class Randomization:
    """What each episode draws (see the module docstring); None parts are not drawn."""

    airframe: dict[str, float] = field(default_factory=dict)  # name: half-width f
    wind: WindDraw | None = None
    delay: Delay | None = None
    sensor_noise: None = None  # hook for the sensor models' noise scale

    @classmethod
    def parse(cls, value: Any) -> Randomization | None:
        """The ``randomize`` option: None/False (nothing), True or "default" (every
        default below), or a dict naming what to draw: airframe parameter names with a
        half-width f in [0, 1) or "default", ``"wind"`` (a dict of WindDraw fields or
        "default"), ``"delay"`` (as the ``delay`` option, or "default")."""
        if value is None or value is False or isinstance(value, Randomization):
            return value or None
        if value is True or value == "default":
            return cls(dict(DEFAULT_AIRFRAME_SPREAD), WindDraw(), DEFAULT_DELAY)
        if not isinstance(value, dict):
            raise ValueError(
                "randomize must be True, 'default' or a dict such as "
                f"{{'mass': 0.3, 'wind': 'default'}}, got {value!r}"
            )
        known = [*AIRFRAME_COLUMNS, "wind", "delay", "sensor_noise"]
        unknown = sorted(set(value) - set(known))
        if unknown:
            raise ValueError(f"cannot randomise {unknown}; randomisable: {known}")
        airframe = {
            name: check_spread(name, DEFAULT_AIRFRAME_SPREAD[name] if f == "default" else f)
            for name, f in value.items()
            if name in AIRFRAME_COLUMNS
        }
        wind = value.get("wind")
        if wind == "default":
            wind = WindDraw()
        elif isinstance(wind, dict):
            wind = WindDraw(**{k: tuple(v) if isinstance(v, list) else v for k, v in wind.items()})
        elif wind is not None:
            raise ValueError(f"randomize['wind'] must be a dict or 'default', got {wind!r}")
        delay = value.get("delay")
        delay = DEFAULT_DELAY if delay == "default" else Delay.parse(delay)
        if value.get("sensor_noise") is not None:
            raise ValueError("randomize['sensor_noise']: this version has no sensor models")
        return cls(airframe, wind, delay)

    def draw_airframes(self, rngs: list[np.random.Generator], base: np.ndarray) -> np.ndarray:
        """(len(rngs), N_PARAMS) rows: ``base`` scaled, each row by its generator's
        draws, one ``uniform(1 − f, 1 + f)`` per parameter in the dict's order."""
        spread, k = np.array(list(self.airframe.values())), len(self.airframe)
        # low + (high − low)·u is what rng.uniform(low, high) computes, from the same u.
        low, high = 1 - spread, 1 + spread
        scales = low + (high - low) * np.array([rng.random(k) for rng in rngs])
        factors = np.ones((len(rngs), L.N_PARAMS))
        for k, name in enumerate(self.airframe):
            factors[:, AIRFRAME_COLUMNS[name]] *= scales[:, k : k + 1]
        return base * factors


def _is_real(value: object) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)


def check_spread(name: str, fraction: Any, option: str = "randomize") -> float:
    """A half-width f in [0, 1) (one-line ValueError otherwise)."""
    if not (_is_real(fraction) and 0 <= fraction < 1):
        raise ValueError(f"{option}[{name!r}] must be a number in [0, 1), got {fraction!r}")
    return float(fraction)


def airframe_scale_row(scale: Any) -> np.ndarray | None:
    """The ``airframe_scale`` option ({name: factor}) as factors per parameter column
    (None: no scaling); factors are finite, in [0.1, 10]."""
    if scale is None:
        return None
    if not isinstance(scale, dict):
        raise ValueError(f"airframe_scale must be a dict such as {{'mass': 1.3}}, got {scale!r}")
    row = np.ones(L.N_PARAMS)
    for name, factor in scale.items():
        if name not in AIRFRAME_COLUMNS:
            raise ValueError(f"cannot scale {name!r}; scalable: {list(AIRFRAME_COLUMNS)}")
        if not (_is_real(factor) and 1 / MAX_SCALE <= factor <= MAX_SCALE):
            raise ValueError(
                f"airframe_scale[{name!r}] must be a factor in [{1 / MAX_SCALE:g}, "
                f"{MAX_SCALE:g}], got {factor!r}"
            )
        row[AIRFRAME_COLUMNS[name]] *= factor
    return row
