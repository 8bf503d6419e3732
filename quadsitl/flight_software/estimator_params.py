"""The onboard estimator's error-state layout and tuning (the filter:
:mod:`quadsitl.flight_software.estimator`; equations and sources: docs/physics.md, "Estimator")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadsitl.physics.sensors.processes import Array

# The error state δx (x_true − x_estimated), 16 values per vehicle.
POS = slice(0, 3)  # m, world ENU
VEL = slice(3, 6)  # m/s, world ENU
ATT = slice(6, 9)  # rad, a small rotation in world ENU: R_true = (I + [δθ]×)·R_est
ACCEL_BIAS = slice(9, 12)  # m/s², body FLU
GYRO_BIAS = slice(12, 15)  # rad/s, body FLU
BARO_OFFSET = 15  # m, barometric altitude minus local height
SIZE = 16


@dataclass(frozen=True)
class EstimatorParams:
    """The filter's tuning: noise densities of its model (continuous time) and of its
    measurements (1 σ). The IMU terms start from the sensors' data (docs/physics.md,
    "Sensors") and are inflated for what the model leaves out (sampling the IMU once a
    control period, the GPS error's correlation), as PX4's EKF2 defaults are.

    Attributes:
        accel_noise: m/s²/√Hz, drives the velocity (the IMU's 0.00186, ×10).
        gyro_noise: rad/s/√Hz, drives the attitude (the IMU's 0.00019, ×5).
        accel_bias_walk: m/s³/√Hz (the Gazebo Iris model's random walk, 0.006: 30× the
            IMU's 2e-4, a margin).
        gyro_bias_walk: rad/s²/√Hz (the IMU's 3.9e-5, ×2.5).
        baro_offset_walk: m/√s, how fast the barometer's offset may move (its drift's
            driving density, 6 Pa·√(2/300 s) ≈ 0.04 m/√s).
        baro_noise: m, one barometer reading (1 Pa ≈ 0.087 m, ×1.5).
        heading_noise: rad, one magnetometer heading (EKF2_HEAD_NOISE: 0.3; ours is a
            clean, undisturbed field: 0.05).
        gps_position_factor: the GPS position's variance is (factor × EPH)²: its error
            is correlated over about a second, so ten fixes carry little more than one.
        gps_position_floor: m, the smallest GPS position σ assumed.
        gps_velocity_noise: m/s, the smallest GPS velocity σ assumed (else the
            receiver's speed accuracy).
        history: s of estimates kept to compare late GPS fixes with.
        initial_position, initial_velocity, initial_tilt, initial_heading,
        initial_accel_bias, initial_gyro_bias, initial_baro_offset: 1-σ uncertainty at
            the start (m, m/s, rad, rad, m/s², rad/s, m).
    """

    accel_noise: float = 0.02
    gyro_noise: float = 0.001
    accel_bias_walk: float = 0.006
    gyro_bias_walk: float = 1e-4
    baro_offset_walk: float = 0.04
    baro_noise: float = 0.15
    heading_noise: float = 0.05
    gps_position_factor: float = 3.0
    gps_position_floor: float = 0.1
    gps_velocity_noise: float = 0.1
    history: float = 0.5
    initial_position: float = 1.0
    initial_velocity: float = 0.3
    initial_tilt: float = 0.05
    initial_heading: float = 0.2
    initial_accel_bias: float = 0.1
    initial_gyro_bias: float = 0.005
    initial_baro_offset: float = 0.5

    def initial_covariance(self) -> Array:
        """(16, 16) the diagonal covariance a (re)started estimate begins with."""
        sigma = np.empty(SIZE)
        sigma[POS], sigma[VEL] = self.initial_position, self.initial_velocity
        sigma[ATT] = (self.initial_tilt, self.initial_tilt, self.initial_heading)
        sigma[ACCEL_BIAS], sigma[GYRO_BIAS] = self.initial_accel_bias, self.initial_gyro_bias
        sigma[BARO_OFFSET] = self.initial_baro_offset
        return np.diag(sigma**2)

    def process_noise(self) -> Array:
        """(16,) spectral densities of the process noise, per second."""
        q = np.zeros(SIZE)
        q[VEL], q[ATT] = self.accel_noise**2, self.gyro_noise**2
        q[ACCEL_BIAS], q[GYRO_BIAS] = self.accel_bias_walk**2, self.gyro_bias_walk**2
        q[BARO_OFFSET] = self.baro_offset_walk**2
        return q
