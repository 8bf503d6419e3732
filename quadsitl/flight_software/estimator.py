"""The onboard estimator: an error-state extended Kalman filter that fuses the IMU,
barometer, magnetometer and GPS into position, velocity, attitude, sensor biases and
their covariance: what the flight software flies on when EKF2_EN is 1.

The IMU drives the prediction (strapdown inertial navigation); the GPS position and
velocity correct it at the time they were measured (compared with the estimate then,
kept in a short history: the GPS arrives 0.12 s late), the barometer corrects the height
(with an offset state that follows its drift) and the magnetometer the heading. The
equations, the tuning and its sources are in docs/physics.md, "Estimator".

Batched over the N vehicles of one :class:`~quadsitl.physics.sensors.SensorSuite` in
numpy: a group's vehicles cost one call. Frames: world ENU, body FLU (the physics');
the MAVLink edge converts. Quaternions (w, x, y, z), body FLU -> world ENU.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from quadsitl import frames
from quadsitl.flight_software.estimator_params import (
    ACCEL_BIAS,
    ATT,
    BARO_OFFSET,
    GYRO_BIAS,
    POS,
    SIZE,
    VEL,
    EstimatorParams,
)
from quadsitl.physics import layout as L
from quadsitl.physics.sensors import SensorSuite
from quadsitl.physics.sensors.gps import FIX_3D
from quadsitl.physics.sensors.processes import Array

# Lean batched helpers: the filter runs every control period, where numpy's per-call
# overhead on a few vehicles' small arrays is most of the cost (frames' general
# functions accept any shape and pay for it).


def rotation_matrices(q: Array) -> Array:
    """(N, 3, 3) body -> world rotation matrices of (N, 4) unit quaternions."""
    w, x, y, z = q.T
    xx, yy, zz, xy, xz, yz, wx, wy, wz = (
        x * x,
        y * y,
        z * z,
        x * y,
        x * z,
        y * z,
        w * x,
        w * y,
        w * z,
    )
    return np.stack(
        [1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
         2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
         2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)],
        axis=1,
    ).reshape(-1, 3, 3)  # fmt: skip


def multiply(p: Array, q: Array) -> Array:
    """(N, 4) Hamilton products p ⊗ q."""
    pw, px, py, pz = p.T
    qw, qx, qy, qz = q.T
    return np.stack(
        [pw * qw - px * qx - py * qy - pz * qz,
         pw * qx + px * qw + py * qz - pz * qy,
         pw * qy - px * qz + py * qw + pz * qx,
         pw * qz + px * qy - py * qx + pz * qw],
        axis=1,
    )  # fmt: skip


def quat_from_rotation_vector(v: Array) -> Array:
    """(N, 4) the rotations by (N, 3) rotation vectors (rad; axis × angle)."""
    angle = np.sqrt(np.einsum("ij,ij->i", v, v))
    half = 0.5 * angle
    # sin(θ/2)/θ, → 1/2 for small θ (its series to second order)
    scale = np.where(angle > 1e-8, np.sin(half) / np.maximum(angle, 1e-300), 0.5 - angle**2 / 48)
    return np.concatenate([np.cos(half)[:, None], v * scale[:, None]], axis=1)


def horizontal_angle(v: Array) -> Array:
    """(N,) rad, the direction of (N, 3) world ENU vectors' horizontal parts, from east."""
    return np.arctan2(v[:, 1], v[:, 0])


class Estimator:
    """The EKF of every vehicle of ``suite``. :meth:`update` takes in whatever the
    sensors measured since the last call; each :class:`EstimatorSlot` reads its row.

    Args:
        suite: the sensors it reads (and their vehicles' number N).
        rest_height: m, the centre of mass's height at rest on the ground (the local
            frame's ground is z = 0): where a started estimate puts the vehicle.
        gravity: m/s².
        params: its tuning.

    Attributes:
        position, velocity: (N, 3) m, m/s, world ENU.
        quaternion: (N, 4) body FLU -> world ENU.
        rates: (N, 3) rad/s, body FLU: the gyroscope less its estimated bias.
        accel_bias, gyro_bias: (N, 3) m/s², rad/s, body FLU.
        baro_offset: (N,) m, barometric altitude minus the local height.
        covariance: (N, 16, 16) of the error state (module constants name its parts).
        time: s, of the last IMU sample taken in.
    """

    def __init__(
        self,
        suite: SensorSuite,
        rest_height: ArrayLike = 0.0,
        gravity: float = 9.81,
        params: EstimatorParams | None = None,
    ) -> None:
        n = suite.n
        self.suite, self.n, self.gravity = suite, n, gravity
        self.params = params or EstimatorParams()
        self.rest_height = np.broadcast_to(np.asarray(rest_height, np.float64), (n,)).copy()
        self.position, self.velocity = np.zeros((n, 3)), np.zeros((n, 3))
        self.quaternion = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        self.rates = np.zeros((n, 3))
        self.accel_bias, self.gyro_bias = np.zeros((n, 3)), np.zeros((n, 3))
        self.baro_offset = np.zeros(n)
        self.covariance = np.tile(self.params.initial_covariance(), (n, 1, 1))
        self._noise_density = self.params.process_noise()
        self._gravity = np.array([0.0, 0.0, gravity])  # m/s², world ENU: up
        self._transition = np.tile(np.eye(SIZE), (n, 1, 1))  # F, its constant parts set
        self._eye3, self._diagonal = np.eye(3), np.arange(SIZE)
        field = suite.field_enu  # (N, 3) gauss, world ENU: the Earth's field at home
        self._field_heading = horizontal_angle(field)  # rad
        # ∂(heading error)/∂δθ = B × ∇ψ, ψ = atan2(B_n, B_e): (0, 0, 1) plus the tilt
        # terms the field's inclination brings (≈ tan 63° at home).
        gradient = np.stack([-field[:, 1], field[:, 0], np.zeros(n)], axis=1)
        gradient /= (field[:, :2] ** 2).sum(axis=1, keepdims=True)
        self._heading_row = np.cross(field, gradient)
        self.pending = np.ones(n, bool)  # rows to start from the sensors at the next update
        self.time = -math.inf
        self._seen = (-1, -1, -1, -1)  # sample counts of IMU, barometer, magnetometer, GPS
        # The history of estimated position and velocity that late GPS fixes are compared
        # with, less the corrections made since: stored − corrections then + now.
        depth = max(2, math.ceil(self.params.history * suite.params.imu.rate) + 1)
        self._history_time = np.full(depth, -math.inf)
        self._history = np.zeros((depth, n, 6))
        self._history_next = 0
        self._corrections = np.zeros((n, 6))  # m, m/s: sum of all corrections made

    # --- the loop -----------------------------------------------------------------------
    def update(self) -> None:
        """Take in the sensor samples taken since the last call: predict with the IMU's,
        correct with the barometer's, the magnetometer's and the GPS's."""
        suite = self.suite.sample_due()
        imu, baro, mag, gps = suite.imu, suite.barometer, suite.magnetometer, suite.gps
        seen = (imu.samples, baro.samples, mag.samples, gps.samples)
        if seen == self._seen:
            return
        new = [now != before for now, before in zip(seen, self._seen, strict=True)]
        self._seen = seen
        now = imu.clock.last_sample
        if not math.isfinite(now):
            return  # no IMU sample yet
        if new[0]:
            if now < self.time - 1e-9:  # time went back (a reboot): start again
                self.restart()
            if math.isfinite(self.time) and now > self.time:
                self._predict(imu.gyro, imu.accel, now - self.time)
            if self.pending.any():
                self._start(self.pending)
            self.time = now
            self.rates = imu.gyro - self.gyro_bias
            self._remember()
        if not math.isfinite(self.time):
            return  # nothing to correct yet
        if new[1]:
            self._fuse_barometer(baro.altitude)
        if new[2]:
            self._fuse_heading(mag.field)
        if new[3]:
            self._fuse_gps()

    def restart(self, rows: ArrayLike | None = None) -> None:
        """Start the selected vehicles' estimates (all by default) again from their
        sensors at the next update, as at power-on on the ground."""
        mask = np.ones(self.n, bool) if rows is None else np.asarray(rows, dtype=bool)
        self.pending |= mask
        if rows is None:
            self.time = -math.inf
            self._history_time[:] = -math.inf

    def set_state(
        self,
        row: int,
        position: ArrayLike,
        velocity: ArrayLike,
        quaternion: ArrayLike,
        covariance: ArrayLike | None = None,
    ) -> None:
        """Put vehicle ``row``'s estimate somewhere (m, m/s ENU; attitude FLU -> ENU),
        e.g. wrong, to see it converge; ``covariance`` (16, 16) defaults to the
        starting one."""
        self.position[row], self.velocity[row] = position, velocity
        self.quaternion[row] = frames.quat_normalize(quaternion)
        start = self.params.initial_covariance() if covariance is None else covariance
        self.covariance[row] = start
        self.pending[row] = False

    # --- prediction ---------------------------------------------------------------------
    def _start(self, rows: np.ndarray) -> None:
        """Level and heading from the accelerometer and magnetometer at rest, horizontal
        position from the GPS if it has a fix (else the local origin), height at rest,
        at rest, biases zero, the barometer's offset from its reading."""
        suite = self.suite
        f = suite.imu.accel[rows]  # m/s², body FLU: (0, 0, g) rotated into the body
        roll = np.arctan2(f[:, 1], f[:, 2])
        pitch = np.arctan2(-f[:, 0], np.hypot(f[:, 1], f[:, 2]))
        level = frames.quat_from_euler(roll, pitch, np.zeros_like(roll))
        field = frames.quat_rotate(level, suite.magnetometer.field[rows])
        yaw = self._field_heading[rows] - horizontal_angle(field)
        self.quaternion[rows] = frames.quat_from_euler(roll, pitch, yaw)
        fix = suite.gps.fix
        fixed = fix.fix_type[rows] == FIX_3D
        self.position[rows] = 0.0
        self.position[rows, :2] = np.where(fixed[:, None], fix.position[rows, :2], 0.0)
        self.position[rows, 2] = self.rest_height[rows]
        self.velocity[rows] = self.accel_bias[rows] = self.gyro_bias[rows] = 0.0
        self.baro_offset[rows] = suite.barometer.altitude[rows] - self.rest_height[rows]
        self.covariance[rows] = self.params.initial_covariance()
        self.pending[rows] = False

    def _predict(self, gyro: Array, accel: Array, dt: float) -> None:
        """Strapdown over ``dt`` s with the IMU's gyro (N, 3) rad/s and accelerometer
        (N, 3) m/s², body FLU; the covariance by P ← F·P·Fᵀ + Q·dt."""
        rotation = rotation_matrices(self.quaternion)  # (N, 3, 3) body -> world
        force = np.einsum("nij,nj->ni", rotation, accel - self.accel_bias)  # world
        acceleration = force - self._gravity
        self.position += (self.velocity + 0.5 * dt * acceleration) * dt
        self.velocity += acceleration * dt
        turn = quat_from_rotation_vector((gyro - self.gyro_bias) * dt)
        q = multiply(self.quaternion, turn)
        self.quaternion = q / np.sqrt(np.einsum("ij,ij->i", q, q))[:, None]
        # F = I + A·dt: δp' = δv, δv' = −[R f]×·δθ − R·δb_a, δθ' = −R·δb_g
        f = self._transition
        f[:, POS, VEL] = self._eye3 * dt
        fx, fy, fz = (force * -dt).T  # −[R f]×·dt, entry by entry
        f[:, 3, 7], f[:, 3, 8], f[:, 4, 6] = -fz, fy, fz
        f[:, 4, 8], f[:, 5, 6], f[:, 5, 7] = -fx, -fy, fx
        f[:, VEL, ACCEL_BIAS] = f[:, ATT, GYRO_BIAS] = rotation * -dt
        p = f @ self.covariance @ f.transpose(0, 2, 1)
        p[:, self._diagonal, self._diagonal] += self._noise_density * dt
        self.covariance = 0.5 * (p + p.transpose(0, 2, 1))

    def _remember(self) -> None:
        """Keep the estimate of now (less the corrections so far) for late GPS fixes."""
        i = self._history_next
        self._history_time[i] = self.time
        self._history[i, :, :3] = self.position - self._corrections[:, :3]
        self._history[i, :, 3:] = self.velocity - self._corrections[:, 3:]
        self._history_next = (i + 1) % len(self._history_time)

    def _estimate_at(self, time: float) -> Array:
        """(N, 6) position and velocity estimated at ``time`` s (the nearest kept), with
        every correction made since."""
        i = int(np.argmin(np.abs(self._history_time - time)))
        return self._history[i] + self._corrections

    # --- corrections --------------------------------------------------------------------
    def _fuse(self, terms: dict[int, Array | float], innovation: Array, variance: Array) -> None:
        """One scalar measurement per vehicle, y = Σ h_k·δx_k + noise of ``variance``
        (N,), the terms {k: h_k} (h_k one per vehicle or one for all), with
        ``innovation`` (N,) = measured − predicted; NaN rows are skipped."""
        ok = np.isfinite(innovation) & np.isfinite(variance) & ~self.pending
        if not ok.any():
            return
        p = self.covariance
        ph = sum(p[:, :, k] * np.reshape(h, (-1, 1)) for k, h in terms.items())  # P·Hᵀ
        s = sum(ph[:, k] * h for k, h in terms.items()) + variance
        gain = np.where(ok[:, None], ph / s[:, None], 0.0)  # (N, 16)
        self.covariance = p - gain[:, :, None] * ph[:, None, :]
        self._inject(gain * np.where(ok, innovation, 0.0)[:, None])

    def _inject(self, dx: Array) -> None:
        """Move the estimate by the error-state correction ``dx`` (N, 16)."""
        self.position += dx[:, POS]
        self.velocity += dx[:, VEL]
        turn = quat_from_rotation_vector(dx[:, ATT])
        self.quaternion = multiply(turn, self.quaternion)
        self.accel_bias += dx[:, ACCEL_BIAS]
        self.gyro_bias += dx[:, GYRO_BIAS]
        self.baro_offset += dx[:, BARO_OFFSET]
        self._corrections += dx[:, :6]

    def _fuse_barometer(self, altitude: Array) -> None:
        """The barometric altitude (N,) m: h = z + offset."""
        predicted = self.position[:, 2] + self.baro_offset
        variance = np.full(self.n, self.params.baro_noise**2)
        self._fuse({2: 1.0, BARO_OFFSET: 1.0}, altitude - predicted, variance)

    def _fuse_heading(self, field_body: Array) -> None:
        """The heading of the magnetometer's field (N, 3) gauss, body FLU, seen through
        the estimated attitude, against the Earth's field at home: the heading error,
        and through the field's inclination the tilt error too."""
        seen = np.einsum("nij,nj->ni", rotation_matrices(self.quaternion), field_body)
        innovation = frames.wrap_angle(self._field_heading - horizontal_angle(seen))
        variance = np.full(self.n, self.params.heading_noise**2)
        h = self._heading_row
        self._fuse({6: h[:, 0], 7: h[:, 1], 8: h[:, 2]}, innovation, variance)

    def _fuse_gps(self) -> None:
        """The GPS fix: position and velocity, compared with the estimate when they were
        measured (``latency`` earlier), each axis in turn."""
        fix, p = self.suite.gps.fix, self.params
        fixed = fix.fix_type == FIX_3D
        if not fixed.any() or fix.measured_at < self._history_time.max() - p.history:
            return
        then = self._estimate_at(fix.measured_at)
        measured = np.concatenate([fix.position, fix.velocity], axis=1)
        innovation = np.where(fixed[:, None], measured - then, np.nan)
        sigma_h = np.maximum(p.gps_position_factor * fix.eph, p.gps_position_floor)
        sigma_v = np.maximum(p.gps_position_factor * fix.epv, p.gps_position_floor)
        sigma_speed = np.maximum(fix.speed_accuracy, p.gps_velocity_noise)
        sigmas = (sigma_h, sigma_h, sigma_v, sigma_speed, sigma_speed, sigma_speed)
        for k, sigma in enumerate(sigmas):
            before = self._corrections.copy()
            self._fuse({k: 1.0}, innovation[:, k], sigma**2)
            # The correction moved the estimate of the axes still to come as well.
            innovation[:, k + 1 :] -= (self._corrections - before)[:, k + 1 :]


class EstimatorSlot:
    """Vehicle ``index`` of an :class:`Estimator`: what its flight software reads.

    ``enabled`` (set by the EKF2_EN parameter) says whether the flight software flies on
    the estimate; while it is False nothing here runs."""

    def __init__(self, estimator: Estimator, index: int) -> None:
        if not 0 <= index < estimator.n:
            raise ValueError(f"vehicle {index} is not in an estimator of {estimator.n}")
        self.estimator, self.index = estimator, index
        self.enabled = False

    def restart(self) -> None:
        """Start this vehicle's estimate again from its sensors (power-on, a reboot)."""
        one = np.zeros(self.estimator.n, bool)
        one[self.index] = True
        self.estimator.restart(one)

    def state_row(self, truth: Array) -> Array:
        """(17,) the physics state row ``truth`` with position, velocity, attitude and
        body rates replaced by the estimate (the rotor speeds stay: ESC telemetry)."""
        e, i = self.estimator, self.index
        e.update()
        row = truth.copy()
        row[L.POS], row[L.VEL] = e.position[i], e.velocity[i]
        row[L.QUAT], row[L.RATES] = e.quaternion[i], e.rates[i]
        return row

    def reset_to(self, state: Array) -> None:
        """The vehicle was put in ``state`` (a physics row: a training episode's reset):
        the estimate starts there, with the starting covariance and the biases kept."""
        self.estimator.set_state(self.index, state[L.POS], state[L.VEL], state[L.QUAT])

    @property
    def covariance(self) -> Array:
        """(16, 16) of this vehicle's error state (module constants name its parts)."""
        return self.estimator.covariance[self.index]
