"""Sensor noise on what a policy observes: the gym envs' ``sensor_noise`` option.

The envs observe the state (position, attitude, velocity, body rates). With noise, each
env's policy sees a perturbed copy of its state, perturbed as the sensors would: the GPS
position error (the same correlated process, settled accuracy), the GPS velocity noise,
the gyroscope's white noise and drifting bias, and an attitude error of 0.5° per axis (an
attitude estimator's, of the order PX4's EKF2 reaches with this IMU and magnetometer). The
rewards and the episode's end keep reading the truth. Every term is scaled by the env's
noise scale; the noise of env i comes from a generator drawn from env i's own at each
reset, so a vector env of N sees what N single envs see.
"""

from __future__ import annotations

import math

import numpy as np

from quadsitl.frames import quat_multiply
from quadsitl.physics import layout as L
from quadsitl.physics.sensors.processes import Array, check_number, gauss_markov_step
from quadsitl.physics.sensors.suite import SensorParams

ATTITUDE_SIGMA = math.radians(0.5)  # rad per axis, white


class ObservationNoise:
    """Noise for N envs' observed states, at noise ``scale`` (0 < scale)."""

    def __init__(self, n: int, scale: float, params: SensorParams | None = None) -> None:
        self.scale = check_number("sensor_noise", scale)
        self.params = params or SensorParams()
        self.rngs = [np.random.default_rng(i) for i in range(n)]  # replaced at each reset
        self.position_error = np.zeros((n, 3))  # unit Gauss–Markov (the GPS's)
        self.gyro_bias = np.zeros((n, 3))  # rad/s at scale 1

    def reset(self, rows: np.ndarray, env_rngs: list[np.random.Generator]) -> None:
        """New episodes in ``rows``: each env's noise generator is drawn from its own."""
        for i, rng in zip(rows, env_rngs, strict=True):
            self.rngs[i] = np.random.default_rng(int(rng.integers(2**62)))
            self.position_error[i] = self.rngs[i].standard_normal(3)
            self.gyro_bias[i] = 0.0

    def perturb(self, state: Array, rows: np.ndarray, elapsed: float) -> Array:
        """A noisy copy of ``state`` (one row per env of ``rows``), the noise processes
        moved on by ``elapsed`` s."""
        gps, imu = self.params.gps, self.params.imu
        draws = np.stack([self.rngs[i].standard_normal(15) for i in rows])
        error, bias = self.position_error[rows], self.gyro_bias[rows]
        gauss_markov_step(
            error, elapsed, gps.error_tau, math.sqrt(2.0 / gps.error_tau), draws[:, 0:3]
        )
        gauss_markov_step(bias, elapsed, imu.gyro_bias_tau, imu.gyro_random_walk, draws[:, 3:6])
        self.position_error[rows], self.gyro_bias[rows] = error, bias
        s = self.scale
        sigma = np.array([gps.horizontal_sigma, gps.horizontal_sigma, gps.vertical_sigma])
        noisy = state.copy()
        noisy[:, L.POS] += s * sigma * error
        noisy[:, L.VEL] += s * gps.velocity_sigma * draws[:, 6:9]
        white = imu.gyro_noise_density * math.sqrt(imu.rate) * draws[:, 9:12]
        noisy[:, L.RATES] += s * (bias + white)
        half = 0.5 * s * ATTITUDE_SIGMA * draws[:, 12:15]  # small rotation, body frame
        turn = np.concatenate([np.ones((len(rows), 1)), half], axis=1)
        turn /= np.linalg.norm(turn, axis=1, keepdims=True)
        noisy[:, L.QUAT] = quat_multiply(state[:, L.QUAT], turn)
        return noisy
