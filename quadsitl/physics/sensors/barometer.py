"""The barometer: static pressure of the standard atmosphere at the vehicle, with white
noise and a slow drift, for N vehicles at once."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadsitl.physics.sensors import environment as E
from quadsitl.physics.sensors.processes import Array, SampleClock, check_number
from quadsitl.physics.sensors.processes import gauss_markov_step as _advance


@dataclass(frozen=True)
class BarometerParams:
    """Barometer noise.

    Attributes:
        rate: Hz (PX4's Gazebo barometer plugin: 50).
        noise: Pa, white, per sample (that plugin: 1 Pa RMS, ≈ 8 cm).
        drift_sigma: Pa, the drift's stationary standard deviation (our choice: 6 Pa ≈
            0.5 m, the order of a MEMS barometer's altitude wander in flight).
        drift_tau: s, the drift's correlation time (our choice: 300 s).
    """

    rate: float = 50.0
    noise: float = 1.0
    drift_sigma: float = 6.0
    drift_tau: float = 300.0

    def __post_init__(self) -> None:
        check_number("barometer rate", self.rate, positive=True)
        check_number("barometer noise", self.noise)
        check_number("barometer drift_sigma", self.drift_sigma)
        check_number("barometer drift_tau", self.drift_tau, positive=True)

    @property
    def drift_random_walk(self) -> float:
        """Pa/√s: the drift's driving density σ·√(2/τ)."""
        return self.drift_sigma * math.sqrt(2.0 / self.drift_tau)


class Barometer:
    """N barometers.

    Attributes:
        pressure: (N,) Pa, the latest reading.
        temperature: (N,) K, the ISA temperature at the vehicle.
        altitude: (N,) m above mean sea level: the ISA pressure altitude of the reading.
        drift: (N,) Pa, the drift at noise scale 1 (it starts at 0: zeroed at boot).
    """

    def __init__(self, n: int, params: BarometerParams, rng: np.random.Generator) -> None:
        self.params, self.rng = params, rng
        self.clock = SampleClock(params.rate)
        self.pressure = np.full(n, E.ISA_SEA_LEVEL_PRESSURE)
        self.temperature = np.full(n, E.ISA_SEA_LEVEL_TEMPERATURE)
        self.altitude = np.zeros(n)
        self.drift = np.zeros(n)
        self.samples = 0

    def reset(self, rows: np.ndarray) -> None:
        self.drift[rows] = 0.0

    def sample(self, time: float, altitude: Array, noise_scale: Array) -> None:
        """Read the pressure at the true ``altitude`` (N,) m AMSL at ``time`` s."""
        p = self.params
        last, self.clock.last_sample = self.clock.last_sample, time
        elapsed = time - last if math.isfinite(last) else 0.0
        draws = self.rng.standard_normal((2, len(altitude)))
        _advance(self.drift, elapsed, p.drift_tau, p.drift_random_walk, draws[0])
        self.pressure = E.isa_pressure(altitude) + noise_scale * (self.drift + p.noise * draws[1])
        self.temperature = E.isa_temperature(altitude)
        self.altitude = E.pressure_altitude(self.pressure)
        self.samples += 1
