"""The IMU: a three-axis gyroscope and accelerometer, body FLU, for N vehicles at once.

Each axis reads truth + turn-on bias + Gauss–Markov bias + white noise (the model of the
Kalibr IMU noise model and of PX4's Gazebo IMU plugin), every noise term times the
vehicle's noise scale. The accelerometer measures specific force, what the rotors and the
air push on the airframe per unit mass: f = a − g, (0, 0, +g) at rest (body FLU).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from quadsitl.physics.sensors.processes import Array, SampleClock, check_number
from quadsitl.physics.sensors.processes import gauss_markov_step as _advance


@dataclass(frozen=True)
class ImuParams:
    """IMU noise: the ADIS16448's, the IMU of PX4's Gazebo Iris model (Tools/simulation/
    gazebo classic, models/iris/iris.sdf: its noise densities are the data sheet's angular
    and velocity random walks, 0.66°/√h and 0.11 m/s/√h), with two departures.

    The accelerometer's bias random walk is the ADIS16448's as Kalibr's IMU example gives
    it (2e-4 m/s³/√Hz: a bias that settles at 0.25 mg, the data sheet's in-run bias
    stability), not the Gazebo model's 6e-3 (rotors_simulator's doubled guess): that bias
    wandered by 7 mg within minutes, twice as fast as PX4's EKF2 lets its bias estimate
    move (EKF2_ACC_B_NOISE 3e-3), and tilted an estimator's level by b/g, which the
    Earth's field, inclined 63° at the default home, turns into twice as much heading
    (tests/test_px4_heading.py). And the turn-on bias is 0 (a calibrated IMU; the Iris
    model's uncalibrated one is 0.0087 rad/s and 0.196 m/s²).

    Attributes:
        rate: samples per second, Hz (PX4 reads its IMU at 250 Hz in simulation).
        gyro_noise_density: rad/s/√Hz.
        gyro_random_walk: rad/s²/√Hz, driving noise of the gyro's Gauss–Markov bias.
        gyro_bias_tau: s, correlation time of that bias.
        gyro_turn_on_sigma: rad/s, a constant bias drawn at each reset.
        accel_noise_density: m/s²/√Hz.
        accel_random_walk: m/s³/√Hz.
        accel_bias_tau: s.
        accel_turn_on_sigma: m/s².
    """

    rate: float = 250.0
    gyro_noise_density: float = 0.00018665
    gyro_random_walk: float = 3.8785e-05
    gyro_bias_tau: float = 1000.0
    gyro_turn_on_sigma: float = 0.0
    accel_noise_density: float = 0.00186
    accel_random_walk: float = 2.0e-4
    accel_bias_tau: float = 300.0
    accel_turn_on_sigma: float = 0.0

    def __post_init__(self) -> None:
        check_number("IMU rate", self.rate, positive=True)
        for name in ("gyro_bias_tau", "accel_bias_tau"):
            if getattr(self, name) != math.inf:
                check_number(f"IMU {name}", getattr(self, name), positive=True)
        for name in (
            "gyro_noise_density",
            "gyro_random_walk",
            "gyro_turn_on_sigma",
            "accel_noise_density",
            "accel_random_walk",
            "accel_turn_on_sigma",
        ):
            check_number(f"IMU {name}", getattr(self, name))


class Imu:
    """N IMUs: call :meth:`sample` when the clock says one is due.

    Attributes:
        gyro: (N, 3) rad/s, body FLU: the latest reading.
        accel: (N, 3) m/s², body FLU: the latest specific-force reading.
        gyro_bias, accel_bias: (N, 3), the Gauss–Markov biases at noise scale 1.
        samples: readings taken since the start.
    """

    def __init__(self, n: int, params: ImuParams, rng: np.random.Generator) -> None:
        self.params, self.rng = params, rng
        self.clock = SampleClock(params.rate)
        self.gyro, self.accel = np.zeros((n, 3)), np.zeros((n, 3))
        self.gyro_bias, self.accel_bias = np.zeros((n, 3)), np.zeros((n, 3))
        self.gyro_turn_on, self.accel_turn_on = np.zeros((n, 3)), np.zeros((n, 3))
        self.samples = 0

    def reset(self, rows: np.ndarray) -> None:
        """New turn-on biases for the selected vehicles; their drifting biases start at 0."""
        p, k = self.params, int(np.count_nonzero(rows))
        self.gyro_turn_on[rows] = p.gyro_turn_on_sigma * self.rng.standard_normal((k, 3))
        self.accel_turn_on[rows] = p.accel_turn_on_sigma * self.rng.standard_normal((k, 3))
        self.gyro_bias[rows] = 0.0
        self.accel_bias[rows] = 0.0

    def sample(self, time: float, rates: Array, specific_force: Array, noise_scale: Array) -> None:
        """Read the true body rates (N, 3) rad/s and specific force (N, 3) m/s² (body FLU)
        at ``time`` s; ``noise_scale`` (N, 1) multiplies every noise term."""
        p = self.params
        last, self.clock.last_sample = self.clock.last_sample, time
        elapsed = time - last if math.isfinite(last) else 0.0
        draws = self.rng.standard_normal((4, *self.gyro.shape))
        _advance(self.gyro_bias, elapsed, p.gyro_bias_tau, p.gyro_random_walk, draws[0])
        _advance(self.accel_bias, elapsed, p.accel_bias_tau, p.accel_random_walk, draws[1])
        root_rate = math.sqrt(p.rate)
        gyro_error = (
            self.gyro_turn_on + self.gyro_bias + p.gyro_noise_density * root_rate * draws[2]
        )
        accel_error = (
            self.accel_turn_on + self.accel_bias + p.accel_noise_density * root_rate * draws[3]
        )
        self.gyro = rates + noise_scale * gyro_error
        self.accel = specific_force + noise_scale * accel_error
        self.samples += 1
