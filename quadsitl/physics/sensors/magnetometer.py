"""The magnetometer: the Earth's field at home (World Magnetic Model) in the body frame,
with white noise and a Gauss–Markov bias, for N vehicles at once."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadsitl.physics.sensors.processes import Array, SampleClock, check_number
from quadsitl.physics.sensors.processes import gauss_markov_step as _advance


@dataclass(frozen=True)
class MagnetometerParams:
    """Magnetometer noise, as PX4's Gazebo Iris model sets its magnetometer plugin
    (models/iris/iris.sdf: pubRate 100, noiseDensity 0.0004, randomWalk 6.4e-06,
    biasCorrelationTime 600).

    Attributes:
        rate: Hz.
        noise_density: gauss/√Hz.
        random_walk: gauss/s/√Hz, driving noise of the bias.
        bias_tau: s, correlation time of the bias.
    """

    rate: float = 100.0
    noise_density: float = 0.0004
    random_walk: float = 6.4e-06
    bias_tau: float = 600.0

    def __post_init__(self) -> None:
        check_number("magnetometer rate", self.rate, positive=True)
        check_number("magnetometer noise_density", self.noise_density)
        check_number("magnetometer random_walk", self.random_walk)
        check_number("magnetometer bias_tau", self.bias_tau, positive=True)


class Magnetometer:
    """N magnetometers.

    Attributes:
        field: (N, 3) gauss, body FLU: the latest reading.
        bias: (N, 3) gauss at noise scale 1 (it starts at 0).
    """

    def __init__(self, n: int, params: MagnetometerParams, rng: np.random.Generator) -> None:
        self.params, self.rng = params, rng
        self.clock = SampleClock(params.rate)
        self.field = np.zeros((n, 3))
        self.bias = np.zeros((n, 3))
        self.samples = 0

    def reset(self, rows: np.ndarray) -> None:
        self.bias[rows] = 0.0

    def sample(self, time: float, field_body: Array, noise_scale: Array) -> None:
        """Read the true field (N, 3) gauss, body FLU, at ``time`` s."""
        p = self.params
        last, self.clock.last_sample = self.clock.last_sample, time
        elapsed = time - last if math.isfinite(last) else 0.0
        draws = self.rng.standard_normal((2, *self.field.shape))
        _advance(self.bias, elapsed, p.bias_tau, p.random_walk, draws[0])
        white = p.noise_density * math.sqrt(p.rate) * draws[1]
        self.field = field_body + noise_scale * (self.bias + white)
        self.samples += 1
