"""The sensors of N vehicles, each at its own rate, fed from the physics state.

:class:`SensorSuite` is told after each physics step (or each control period) where the
state is; each sensor samples at the multiples of its own period (the GPS when they come,
the others when read), so calling it more often costs one comparison. Everything is
seeded, and one noise scale per vehicle multiplies every noise term (0: the truth,
sampled at each sensor's rate and, for GPS, delivered late). Frames: world ENU, body FLU
(the physics'); the MAVLink edge converts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike

from quadsitl.physics import kernel
from quadsitl.physics import layout as L
from quadsitl.physics.sensors import failures as FL
from quadsitl.physics.sensors.barometer import Barometer, BarometerParams
from quadsitl.physics.sensors.environment import magnetic_field_enu
from quadsitl.physics.sensors.gps import NO_FIX, Gps, GpsParams
from quadsitl.physics.sensors.imu import Imu, ImuParams
from quadsitl.physics.sensors.magnetometer import Magnetometer, MagnetometerParams
from quadsitl.physics.sensors.processes import Array, check_number


@dataclass(frozen=True)
class SensorParams:
    """The parameters of every sensor (defaults and sources: docs/physics.md)."""

    imu: ImuParams = field(default_factory=ImuParams)
    barometer: BarometerParams = field(default_factory=BarometerParams)
    magnetometer: MagnetometerParams = field(default_factory=MagnetometerParams)
    gps: GpsParams = field(default_factory=GpsParams)


def check_noise_scale(value: object) -> float:
    """A noise scale (0 = perfect, 1 = the defaults, 3 = three times), or ValueError."""
    return check_number("sensor noise scale", value)


@numba.njit(cache=True, error_model="numpy")
def _rotate_into_body(qw, qx, qy, qz, x, y, z):  # pragma: no cover - compiled
    """World ENU (x, y, z) in the body FLU frame of quaternion q: v_body = q* ⊗ v ⊗ q,
    the transpose of the body -> world rotation."""
    tx = 2.0 * (qy * z - qz * y)
    ty = 2.0 * (qz * x - qx * z)
    tz = 2.0 * (qx * y - qy * x)
    return (
        x - qw * tx + (qy * tz - qz * ty),
        y - qw * ty + (qz * tx - qx * tz),
        z - qw * tz + (qx * ty - qy * tx),
    )


@numba.njit(cache=True, error_model="numpy")
def _body_from_world(state, vectors, out):  # pragma: no cover - compiled
    for j in range(state.shape[0]):
        out[j, 0], out[j, 1], out[j, 2] = _rotate_into_body(
            state[j, L.I_QW], state[j, L.I_QX], state[j, L.I_QY], state[j, L.I_QZ],
            vectors[j, 0], vectors[j, 1], vectors[j, 2],
        )  # fmt: skip


def body_from_world(state: Array, vectors: Array) -> Array:
    """(N, 3) world ENU vectors expressed in each vehicle's body FLU frame."""
    out = np.empty((state.shape[0], 3))
    _body_from_world(state, np.broadcast_to(vectors, out.shape), out)
    return out


@numba.njit(cache=True, error_model="numpy")
def _specific_force(state, params, contact, air_velocity, out):  # pragma: no cover - compiled
    kernel.specific_force(state, params, contact, air_velocity, out)
    for j in range(state.shape[0]):
        out[j, 0], out[j, 1], out[j, 2] = _rotate_into_body(
            state[j, L.I_QW], state[j, L.I_QX], state[j, L.I_QY], state[j, L.I_QZ],
            out[j, 0], out[j, 1], out[j, 2],
        )  # fmt: skip


def specific_force(state: Array, params: Array, contact: np.ndarray, air_velocity: Array) -> Array:
    """(N, 3) m/s², body FLU: what an ideal accelerometer reads, a − g, from the forces the
    physics integrates (:func:`quadsitl.physics.kernel.specific_force`: thrust with each
    rotor's efficiency and ground effect, drag through the air); on the ground, which
    holds the vehicle up, gravity's reaction (0, 0, g) in world. Compiled: a PX4 round
    reads it twice for one vehicle, where numpy's per-call costs made it 31 µs."""
    out = np.empty((state.shape[0], 3))
    _specific_force(state, params, contact, air_velocity, out)
    return out


class SensorSuite:
    """IMU, barometer, magnetometer and GPS of N vehicles: :meth:`update` after the
    physics moves, :meth:`sample_due` before reading the IMU, barometer or magnetometer
    (the :class:`SensorSlot` accessors do).

    Args:
        n: vehicles.
        latitude, longitude: degrees, one per vehicle (or one for all): where the
            magnetic field is looked up (the home position).
        altitude_offset: m above mean sea level of each vehicle's local z = 0 (what the
            barometer adds to the height).
        params: the sensors' parameters.
        noise_scale: one for all vehicles, or one each.
        seed: of the noise.
    """

    def __init__(
        self,
        n: int,
        latitude: ArrayLike = 47.397742,
        longitude: ArrayLike = 8.545594,
        altitude_offset: ArrayLike = 0.0,
        params: SensorParams | None = None,
        noise_scale: ArrayLike = 1.0,
        seed: int = 0,
    ) -> None:
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        self.n = int(n)
        self.params = params or SensorParams()
        self.rng = np.random.default_rng(seed)
        lat = np.broadcast_to(np.asarray(latitude, dtype=np.float64), (self.n,))
        lon = np.broadcast_to(np.asarray(longitude, dtype=np.float64), (self.n,))
        self.field_enu = np.stack([magnetic_field_enu(a, b) for a, b in zip(lat, lon, strict=True)])
        self.altitude_offset = np.broadcast_to(np.asarray(altitude_offset, np.float64), (self.n,))
        self.noise_scale = np.ones((self.n, 1))
        self.set_noise_scale(noise_scale)
        p = self.params
        self.imu = Imu(self.n, p.imu, self.rng)
        self.barometer = Barometer(self.n, p.barometer, self.rng)
        self.magnetometer = Magnetometer(self.n, p.magnetometer, self.rng)
        self.gps = Gps(self.n, p.gps, self.rng)
        self._clocks = (self.imu.clock, self.barometer.clock, self.magnetometer.clock)
        self._last_time = 0.0
        self._next_due = 0.0
        self._truth: tuple[Array, Array, np.ndarray, Array] | None = None
        # Per vehicle and sensor (failures.SENSORS): OK, OFF or STUCK.
        self.failed = np.zeros((self.n, len(FL.SENSORS)), np.int8)
        self.reset()

    def set_noise_scale(self, scale: ArrayLike, mask: ArrayLike | None = None) -> None:
        """Noise scale of all vehicles, or of those selected by a boolean mask."""
        values = np.asarray(scale, dtype=np.float64).ravel()
        for value in values:
            check_noise_scale(float(value))
        rows = np.ones(self.n, bool) if mask is None else np.asarray(mask, dtype=bool)
        self.noise_scale[rows, 0] = values if values.size > 1 else values[0]

    def fail(self, vehicle: int, sensor: str, kind: int) -> None:
        """Sensor ``sensor`` of ``vehicle`` fails (failures.OFF or STUCK) or works again
        (failures.OK); a reboot (:meth:`reset`) heals it."""
        if kind not in FL.FAILURE_NAMES:
            raise ValueError(f"unknown sensor failure {kind!r}; choose one of {FL.FAILURE_NAMES}")
        self.failed[vehicle, FL.sensor_index(sensor)] = kind

    def reset(self, mask: ArrayLike | None = None, time: float | None = None) -> None:
        """Restart the selected vehicles' sensors (all by default): new turn-on biases,
        drifts at 0, the GPS without a fix until time_to_fix from ``time`` (default: the
        last update's), no failure."""
        rows = np.ones(self.n, bool) if mask is None else np.asarray(mask, dtype=bool)
        self.failed[rows] = FL.OK
        when = self._last_time if time is None else time
        self.imu.reset(rows)
        self.barometer.reset(rows)
        self.magnetometer.reset(rows)
        self.gps.reset(rows, when)

    def _restart(self, time: float) -> None:
        """Time went back (a vehicle alone rebooted): start every clock again."""
        for clock in (*self._clocks, self.gps.clock):
            clock.restart(time)
        self.gps.clear()
        self.reset(time=time)

    def update(
        self, time: float, state: Array, params: Array, contact: np.ndarray, air_velocity: Array
    ) -> None:
        """The physics moved to ``time`` s: state (N, 17), params (N, N_PARAMS), contact
        (N,), the air's velocity (N, 3) m/s world ENU (kept, not copied: the arrays the
        physics steps in place). The GPS measures now when due (its delay line needs the
        past); the IMU, barometer and magnetometer take the sample due by now when they
        are read (:meth:`sample_due`): statistically the same as sampling at every due
        tick (the biases move on exactly over any interval), and free while nobody reads
        them."""
        if time + 1e-9 < self._last_time:
            self._restart(time)
        self._last_time = time
        self._truth = (state, params, contact, air_velocity)
        if time + 1e-9 < self._next_due:
            return
        if self.gps.clock.due(time):
            self.gps.sample(time, state[:, L.POS], state[:, L.VEL], self.noise_scale)
        before = self.gps.fix
        if self.gps.deliver(time) and self.failed[:, FL.GPS].any():
            self._hold_gps(before)
        self._next_due = self.gps.clock.next_due
        if self.gps.queue:
            self._next_due = min(self._next_due, self.gps.queue[0][0])

    def sample_due(self) -> SensorSuite:
        """Take the IMU, barometer and magnetometer samples due at the last update's time
        (their clocks' latest multiple of 1/rate), from the state then; returns self."""
        if self._truth is None:
            return self
        time, scale = self._last_time, self.noise_scale
        state, params, contact, air_velocity = self._truth
        failed, imu, baro, mag = self.failed, self.imu, self.barometer, self.magnetometer
        before: list[np.ndarray]  # each sensor's readings before its sample
        if imu.clock.due(time):
            before = [imu.gyro.copy(), imu.accel.copy()]
            force = specific_force(state, params, contact, air_velocity)
            imu.sample(time, state[:, L.RATES], force, scale)
            FL.hold(failed, FL.GYRO, [imu.gyro], before[:1])
            FL.hold(failed, FL.ACCEL, [imu.accel], before[1:])
        if baro.clock.due(time):
            before = [baro.pressure.copy(), baro.temperature.copy(), baro.altitude.copy()]
            baro.sample(time, self.altitude_offset + state[:, L.I_PZ], scale[:, 0])
            FL.hold(failed, FL.BARO, [baro.pressure, baro.temperature, baro.altitude], before)
        if mag.clock.due(time):
            before = [mag.field.copy()]
            mag.sample(time, body_from_world(state, self.field_enu), scale)
            FL.hold(failed, FL.MAG, [mag.field], before)
        return self

    def _hold_gps(self, before: Any) -> None:
        """The GPS fix just delivered, for the vehicles whose GPS failed: the last one
        (stuck), or no fix at all (off)."""
        fix, failed = self.gps.fix, self.failed[:, FL.GPS]
        stuck, off = failed == FL.STUCK, failed == FL.OFF
        for name in ("position", "velocity", "eph", "epv", "speed_accuracy", "hdop", "vdop"):
            now = getattr(fix, name).copy()
            now[stuck | off] = getattr(before, name)[stuck | off]
            setattr(fix, name, now)
        satellites, fix_type = fix.satellites.copy(), fix.fix_type.copy()
        satellites[stuck], fix_type[stuck] = before.satellites[stuck], before.fix_type[stuck]
        satellites[off], fix_type[off] = 0, NO_FIX
        fix.satellites, fix.fix_type = satellites, fix_type


class SensorSlot:
    """Vehicle ``index`` of a :class:`SensorSuite`: its readings, for one vehicle's
    telemetry. ``fresh`` tells which sensors sampled since the last call of it."""

    def __init__(self, suite: SensorSuite, index: int) -> None:
        if not 0 <= index < suite.n:
            raise ValueError(f"vehicle {index} is not in a sensor suite of {suite.n}")
        self.suite, self.index = suite, index
        self._seen = (-1, -1, -1, -1)

    @property
    def gyro(self) -> Array:
        """(3,) rad/s, body FLU."""
        return self.suite.sample_due().imu.gyro[self.index]

    @property
    def accel(self) -> Array:
        """(3,) m/s², body FLU: specific force."""
        return self.suite.sample_due().imu.accel[self.index]

    @property
    def magnetic_field(self) -> Array:
        """(3,) gauss, body FLU."""
        return self.suite.sample_due().magnetometer.field[self.index]

    @property
    def pressure(self) -> float:
        """Pa."""
        return float(self.suite.sample_due().barometer.pressure[self.index])

    @property
    def temperature(self) -> float:
        """K."""
        return float(self.suite.sample_due().barometer.temperature[self.index])

    @property
    def pressure_altitude(self) -> float:
        """m above mean sea level."""
        return float(self.suite.sample_due().barometer.altitude[self.index])

    @property
    def noise_scale(self) -> float:
        return float(self.suite.noise_scale[self.index, 0])

    def gps(self) -> dict[str, Any]:
        """This vehicle's latest GPS fix: measured_at s, position (3,) m and velocity (3,)
        m/s world ENU, eph/epv m, speed_accuracy m/s, hdop, vdop, satellites, fix_type."""
        fix, i = self.suite.gps.fix, self.index
        out: dict[str, Any] = {"measured_at": fix.measured_at}
        for name in ("position", "velocity"):
            out[name] = getattr(fix, name)[i]
        for name in ("eph", "epv", "speed_accuracy", "hdop", "vdop"):
            out[name] = float(getattr(fix, name)[i])
        out["satellites"] = int(fix.satellites[i])
        out["fix_type"] = int(fix.fix_type[i])
        return out

    def fresh(self) -> tuple[bool, bool, bool, bool]:
        """(IMU, magnetometer, barometer, GPS): True for each that sampled since the last
        call."""
        s = self.suite.sample_due()
        counts = (s.imu.samples, s.magnetometer.samples, s.barometer.samples, s.gps.samples)
        fresh = [now != seen for now, seen in zip(counts, self._seen, strict=True)]
        self._seen = counts
        off = self.suite.failed[self.index] == FL.OFF  # a sensor that is off sends nothing
        fresh[0] = fresh[0] and not (off[FL.GYRO] and off[FL.ACCEL])
        fresh[1] = fresh[1] and not off[FL.MAG]
        fresh[2] = fresh[2] and not off[FL.BARO]
        fresh[3] = fresh[3] and not off[FL.GPS]
        return tuple(fresh)  # type: ignore[return-value]

    def off(self, sensor: str) -> bool:
        """Whether this vehicle's ``sensor`` (failures.SENSORS) is off (failed, gone)."""
        return bool(self.suite.failed[self.index, FL.sensor_index(sensor)] == FL.OFF)

    def fail(self, sensor: str, kind: int) -> None:
        """This vehicle's ``sensor`` fails (OFF, STUCK) or works again (OK)."""
        self.suite.fail(self.index, sensor, kind)

    def reset(self) -> None:
        """Restart this vehicle's sensors (a reboot)."""
        one = np.zeros(self.suite.n, bool)
        one[self.index] = True
        self.suite.reset(one)
