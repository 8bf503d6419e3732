"""The GPS receiver: position and velocity with correlated noise, delivered late through
a delay line, at its own rate, with an accuracy (EPH/EPV) and a satellite count that
settle after the fix. For N vehicles at once."""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from quadsitl.physics.sensors.processes import Array, SampleClock, check_number
from quadsitl.physics.sensors.processes import gauss_markov_step as _advance

NO_FIX, FIX_3D = 1, 3  # GPS_FIX_TYPE values


@dataclass(frozen=True)
class GpsParams:
    """GPS noise, latency and settling.

    Attributes:
        rate: Hz (a u-blox M8 navigates at up to 10 Hz; PX4's HIL_GPS is sent at 10 Hz).
        latency: s from measurement to delivery (PX4's Gazebo GPS plugin: 0.12 s).
        horizontal_sigma: m, 1-σ error of each horizontal axis once settled (PX4 EKF2's
            default EKF2_GPS_P_NOISE, 0.5 m).
        vertical_sigma: m, 1-σ vertical error once settled (1.5× the horizontal: a
            vertical dilution of precision 1.5× the horizontal one).
        velocity_sigma: m/s, white, per axis (u-blox M8 data sheet: 0.05 m/s; twice that).
        error_tau: s, correlation time of the position error (a Gauss–Markov process;
            real receivers wander over minutes: set 60 for that).
        fix_sigma_factor: the errors just after the fix, as a multiple of the settled ones.
        settle_tau: s, time constant with which accuracy and satellites settle.
        satellites_at_fix, satellites: satellites used at the fix and once settled.
        uere: m, user equivalent range error: the dilutions of precision are σ/UERE.
        time_to_fix: s after the start (or a reboot) until the first fix (0: hot start).
    """

    rate: float = 10.0
    latency: float = 0.12
    horizontal_sigma: float = 0.5
    vertical_sigma: float = 0.75
    velocity_sigma: float = 0.1
    error_tau: float = 1.0
    fix_sigma_factor: float = 5.0
    settle_tau: float = 15.0
    satellites_at_fix: int = 6
    satellites: int = 14
    uere: float = 0.6
    time_to_fix: float = 0.0

    def __post_init__(self) -> None:
        check_number("GPS rate", self.rate, positive=True)
        check_number("GPS latency", self.latency)
        for name in ("horizontal_sigma", "vertical_sigma", "velocity_sigma", "time_to_fix"):
            check_number(f"GPS {name}", getattr(self, name))
        for name in ("error_tau", "settle_tau", "uere"):
            check_number(f"GPS {name}", getattr(self, name), positive=True)
        check_number("GPS fix_sigma_factor", self.fix_sigma_factor, low=1.0)
        for name in ("satellites_at_fix", "satellites"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 254:
                raise ValueError(f"GPS {name} must be a whole number 0..254, got {value!r}")


@dataclass
class GpsFix:
    """What the receiver delivers: one row per vehicle.

    Attributes:
        measured_at: s, when the position was true (delivery time − latency).
        position: (N, 3) m, world ENU (of the local frame).
        velocity: (N, 3) m/s, world ENU.
        eph, epv: (N,) m, 1-σ horizontal (per axis) and vertical accuracy: the
            standard deviations of the position error delivered.
        speed_accuracy: (N,) m/s, 1-σ per axis.
        hdop, vdop: (N,) dilutions of precision (σ/UERE).
        satellites: (N,) satellites used.
        fix_type: (N,) NO_FIX or FIX_3D.
    """

    measured_at: float
    position: Array
    velocity: Array
    eph: Array
    epv: Array
    speed_accuracy: Array
    hdop: Array
    vdop: Array
    satellites: Array
    fix_type: Array


class Gps:
    """N receivers: :meth:`sample` measures when the clock says so, :meth:`deliver` hands
    over what has come through the delay line by then (``fix``; ``samples`` counts the
    deliveries)."""

    def __init__(self, n: int, params: GpsParams, rng: np.random.Generator) -> None:
        self.params, self.rng = params, rng
        self.clock = SampleClock(params.rate)
        self.error = rng.standard_normal((n, 3))  # unit Gauss–Markov, stationary
        self.fix_time = np.full(n, params.time_to_fix)  # s, when each vehicle gets its fix
        self.queue: deque[tuple[float, GpsFix]] = deque()
        zeros = np.zeros(n)
        self.fix = GpsFix(
            -math.inf, np.zeros((n, 3)), np.zeros((n, 3)), zeros, zeros, zeros, zeros, zeros,
            np.zeros(n, np.int64), np.full(n, NO_FIX),
        )  # fmt: skip
        self.samples = 0

    def reset(self, rows: np.ndarray, time: float) -> None:
        """Start the selected receivers again at ``time`` s: no fix until time_to_fix."""
        self.error[rows] = self.rng.standard_normal((int(np.count_nonzero(rows)), 3))
        self.fix_time[rows] = time + self.params.time_to_fix

    def settling(self, time: float) -> Array:
        """(N,) 0 at the fix, → 1 once settled (−inf before the fix)."""
        since = time - self.fix_time
        return np.where(
            since >= 0, 1.0 - np.exp(-np.maximum(since, 0) / self.params.settle_tau), -np.inf
        )

    def sample(self, time: float, position: Array, velocity: Array, noise_scale: Array) -> None:
        """Measure the true position (N, 3) m and velocity (N, 3) m/s (world ENU) at
        ``time`` s; the measurement is delivered ``latency`` s later."""
        p = self.params
        last, self.clock.last_sample = self.clock.last_sample, time
        elapsed = time - last if math.isfinite(last) else 0.0
        draws = self.rng.standard_normal((2, *position.shape))
        _advance(self.error, elapsed, p.error_tau, math.sqrt(2.0 / p.error_tau), draws[0])
        settled = self.settling(time)
        fixed = np.isfinite(settled)
        factor = np.where(
            fixed, p.fix_sigma_factor - (p.fix_sigma_factor - 1) * settled, p.fix_sigma_factor
        )
        scale = noise_scale[:, 0]
        sigma = np.stack([factor * p.horizontal_sigma] * 2 + [factor * p.vertical_sigma], axis=1)
        sigma *= noise_scale
        at_fix, settled_count = p.satellites_at_fix, p.satellites
        satellites = np.where(fixed, np.round(at_fix + (settled_count - at_fix) * settled), 0)
        measured = GpsFix(
            measured_at=time,
            position=position + sigma * self.error,
            velocity=velocity + noise_scale * p.velocity_sigma * draws[1],
            eph=sigma[:, 0],
            epv=sigma[:, 2],
            speed_accuracy=scale * p.velocity_sigma,
            hdop=factor * p.horizontal_sigma / p.uere,
            vdop=factor * p.vertical_sigma / p.uere,
            satellites=satellites.astype(np.int64),
            fix_type=np.where(fixed, FIX_3D, NO_FIX),
        )
        self.queue.append((time + p.latency, measured))

    def deliver(self, time: float) -> bool:
        """Hand over the newest measurement due by ``time`` s; True when there was one."""
        delivered = False
        while self.queue and self.queue[0][0] <= time + 1e-9:
            self.fix = self.queue.popleft()[1]
            delivered = True
        if delivered:
            self.samples += 1
        return delivered

    def clear(self) -> None:
        """Forget what is in the delay line (time went back: a reboot)."""
        self.queue.clear()
