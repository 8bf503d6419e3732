"""The sensor models against their specifications: Allan deviation, bias growth, GPS
latency, rate and settling, barometer noise, the magnetic field at home, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl.frames import quat_to_matrix
from quadsitl.physics import Fleet, reference
from quadsitl.physics import layout as L
from quadsitl.physics.sensors import (
    BarometerParams,
    GpsParams,
    ImuParams,
    MagnetometerParams,
    SensorParams,
    SensorSuite,
)
from quadsitl.physics.sensors import environment as E
from quadsitl.physics.sensors.gps import FIX_3D
from quadsitl.physics.sensors.imu import Imu
from quadsitl.physics.sensors.processes import (
    allan_deviation,
    allan_variance_model,
    gauss_markov_variance,
)
from quadsitl.physics.sensors.suite import specific_force
from quadsitl.physics.wind import Wind


def _imu_record(n: int, seconds: float, params: ImuParams, seed: int = 1) -> np.ndarray:
    """(samples, n, 6) gyro and accelerometer errors of ``n`` IMUs at rest, at their rate."""
    imu = Imu(n, params, np.random.default_rng(seed))
    zeros, scale = np.zeros((n, 3)), np.ones((n, 1))
    count = round(seconds * params.rate)
    out = np.empty((count, n, 6))
    for k in range(count):
        imu.sample(k / params.rate, zeros, zeros, scale)
        out[k, :, :3], out[k, :, 3:] = imu.gyro, imu.accel
    return out


def test_imu_allan_deviation_at_one_second_matches_its_parameters():
    p = ImuParams()
    record = _imu_record(50, 100.0, p)
    measured = allan_deviation(record, p.rate, 1.0)  # (n, 6)
    gyro = math.sqrt(
        allan_variance_model(1.0, p.gyro_noise_density, p.gyro_random_walk, p.gyro_bias_tau)
    )
    accel = math.sqrt(
        allan_variance_model(1.0, p.accel_noise_density, p.accel_random_walk, p.accel_bias_tau)
    )
    assert np.mean(measured[:, :3]) == pytest.approx(gyro, rel=0.10)
    assert np.mean(measured[:, 3:]) == pytest.approx(accel, rel=0.10)
    # At 1 s the white noise dominates both: the Allan deviation is the noise density's
    # (1.007 N and 1.002 N, as docs/physics.md says; the Gazebo Iris model's accelerometer
    # walk, 6e-3, gave 2.1 N: its bias crossed over at 0.54 s).
    assert gyro / p.gyro_noise_density == pytest.approx(1.007, abs=0.001)
    assert accel / p.accel_noise_density == pytest.approx(1.002, abs=0.001)
    gazebo = allan_variance_model(1.0, p.accel_noise_density, 6e-3, p.accel_bias_tau)
    assert math.sqrt(gazebo) / p.accel_noise_density == pytest.approx(2.1, abs=0.05)


def test_the_accelerometer_bias_settles_at_the_adis16448_in_run_stability():
    """σ_rw·√(τ/2) = 0.25 mg: the data sheet's in-run bias stability, not the 7 mg the
    Gazebo Iris model's walk settled at."""
    p = ImuParams()
    settled = p.accel_random_walk * math.sqrt(p.accel_bias_tau / 2)
    assert settled / 9.80665e-3 == pytest.approx(0.25, abs=0.01)  # mg


def test_allan_deviation_of_white_noise_falls_as_one_over_root_tau():
    p = ImuParams(gyro_random_walk=0.0, accel_random_walk=0.0)
    record = _imu_record(20, 60.0, p)
    short, long = (np.mean(allan_deviation(record, p.rate, tau)[:, :3]) for tau in (0.1, 1.0))
    assert short / long == pytest.approx(math.sqrt(10.0), rel=0.10)


@pytest.mark.parametrize("update_rate", [10.0, 250.0])
def test_bias_drift_grows_as_the_random_walk_whatever_the_update_rate(update_rate):
    """The biases' variance after t s is σ_rw²·τ/2·(1 − e^(−2t/τ)) ≈ σ_rw²·t, within 10 %,
    whether the IMU is advanced 10 or 250 times a second (exact discretisation)."""
    p, n = ImuParams(rate=update_rate), 1500
    imu = Imu(n, p, np.random.default_rng(7))
    zeros, scale = np.zeros((n, 3)), np.ones((n, 1))
    variances = {}
    for k in range(round(40.0 * update_rate) + 1):
        t = k / update_rate
        imu.sample(t, zeros, zeros, scale)
        if k in (round(10 * update_rate), round(40 * update_rate)):
            variances[round(t)] = (np.var(imu.gyro_bias), np.var(imu.accel_bias))
    for seconds, (gyro, accel) in variances.items():
        expected = gauss_markov_variance(seconds, p.gyro_bias_tau, p.gyro_random_walk)
        assert gyro == pytest.approx(expected, rel=0.10)
        assert gyro == pytest.approx(p.gyro_random_walk**2 * seconds, rel=0.10)  # a random walk
        expected = gauss_markov_variance(seconds, p.accel_bias_tau, p.accel_random_walk)
        assert accel == pytest.approx(expected, rel=0.10)
    assert variances[40][0] / variances[10][0] == pytest.approx(4.0, rel=0.10)


def _fly(suite: SensorSuite, fleet: Fleet, seconds: float, velocity=(3.0, -2.0, 1.0)):
    """Move the vehicles at a constant velocity (no dynamics: kinematics written into the
    state) and update the sensors every physics step; yields the time."""
    fleet.state[:, L.VEL] = velocity
    suite.update(fleet.time, fleet.state, fleet.params, fleet.contact, fleet.air_velocity)
    for _ in range(round(seconds / fleet.dt)):
        fleet.time += fleet.dt
        fleet.state[:, L.POS] += fleet.dt * np.asarray(velocity)
        suite.update(fleet.time, fleet.state, fleet.params, fleet.contact, fleet.air_velocity)
        suite.sample_due()  # a reader at every step
        yield fleet.time


def test_gps_lags_truth_by_its_latency_and_updates_at_its_rate():
    params = SensorParams(gps=GpsParams(rate=5.0, latency=0.15))
    suite = SensorSuite(2, params=params, noise_scale=0.0)
    fleet = Fleet(2, dt=0.001)
    start = fleet.state[:, L.POS].copy()
    deliveries = []
    last = suite.gps.samples
    for t in _fly(suite, fleet, 2.0):
        if suite.gps.samples != last:
            last = suite.gps.samples
            fix = suite.gps.fix
            deliveries.append(t)
            assert t - fix.measured_at == pytest.approx(0.15, abs=1e-9)
            truth_then = start + np.array([3.0, -2.0, 1.0]) * fix.measured_at
            np.testing.assert_allclose(fix.position, truth_then, atol=1e-9)
            np.testing.assert_allclose(fix.velocity, [[3.0, -2.0, 1.0]] * 2)
    assert np.diff(deliveries) == pytest.approx([0.2] * (len(deliveries) - 1), abs=1e-9)
    assert deliveries[0] == pytest.approx(0.15, abs=1e-9)


def test_gps_accuracy_and_satellites_settle_after_the_fix_and_the_noise_matches_them():
    p = GpsParams(time_to_fix=2.0, settle_tau=5.0)
    suite = SensorSuite(400, params=SensorParams(gps=p), seed=3)
    fleet = Fleet(400, dt=0.01)
    seen: dict[float, tuple] = {}
    for t in _fly(suite, fleet, 40.0, velocity=(0.0, 0.0, 0.0)):
        key = round(t, 2)
        if key in (1.5, 2.5, 40.0):
            fix = suite.gps.fix
            error = fix.position - fleet.state[:, L.POS]  # the truth did not move
            seen[key] = (fix.fix_type[0], fix.eph[0], fix.satellites[0], np.std(error[:, 0]))
    assert seen[1.5][0] != FIX_3D and seen[1.5][2] == 0  # before the fix
    fix_type, eph, satellites, std = seen[2.5]
    assert fix_type == FIX_3D and eph > 3 * p.horizontal_sigma and satellites < 9
    fix_type, eph, satellites, std = seen[40.0]
    assert eph == pytest.approx(p.horizontal_sigma, rel=0.01)  # settled: 7.6 time constants
    assert satellites == p.satellites
    assert std == pytest.approx(eph, rel=0.15)  # the reported accuracy is the real one


def test_barometer_altitude_noise_and_drift_match_the_parameters():
    p = BarometerParams()
    suite = SensorSuite(500, altitude_offset=488.0, params=SensorParams(barometer=p), seed=5)
    fleet = Fleet(500, dt=0.01)
    fleet.state[:, L.I_PZ] = 10.0
    for _ in _fly(suite, fleet, 60.0, velocity=(0.0, 0.0, 0.0)):
        pass
    truth = E.isa_pressure(np.array([498.0]))[0]
    error = suite.barometer.pressure - truth
    expected = math.sqrt(p.noise**2 + gauss_markov_variance(60.0, p.drift_tau, p.drift_random_walk))
    assert np.std(error) == pytest.approx(expected, rel=0.10)
    # 1 Pa is about 8.7 cm here: the pressure altitude scatters by the same in metres.
    metres_per_pa = 1.0 / (
        E.isa_pressure(np.array([498.0]))[0] - E.isa_pressure(np.array([499.0]))[0]
    )
    altitude_error = suite.barometer.altitude - 498.0
    assert np.std(altitude_error) == pytest.approx(expected * metres_per_pa, rel=0.10)
    assert abs(np.mean(altitude_error)) < 0.2


def test_the_isa_matches_its_table_values():
    assert E.isa_pressure(np.array([0.0]))[0] == pytest.approx(101_325.0)
    assert E.isa_pressure(np.array([1000.0]))[0] == pytest.approx(89_874.6, rel=1e-4)
    assert E.isa_temperature(np.array([1000.0]))[0] == pytest.approx(281.65)
    assert E.pressure_altitude(E.isa_pressure(np.array([488.0])))[0] == pytest.approx(488.0)
    # 1 Pa is 8.7 cm at 500 m (docs/physics.md).
    per_pa = 1.0 / (E.isa_pressure(np.array([499.5]))[0] - E.isa_pressure(np.array([500.5]))[0])
    assert per_pa == pytest.approx(0.087, abs=0.0005)


def test_the_magnetic_grid_is_px4s_and_the_field_at_home_is_the_wmm():
    # The grid's own summary, as PX4 states it beside the tables (a transcription check).
    assert E.DECLINATION_GRID.min() == pytest.approx(-3.118, abs=1e-3)
    assert E.DECLINATION_GRID.max() == pytest.approx(3.120, abs=1e-3)
    assert E.INCLINATION_GRID.min() == pytest.approx(-1.526, abs=1e-3)
    assert E.INCLINATION_GRID.max() == pytest.approx(1.543, abs=1e-3)
    assert 1e2 * E.STRENGTH_GRID.mean() == pytest.approx(46.4, abs=0.05)  # µT
    assert 1e2 * np.median(E.STRENGTH_GRID) == pytest.approx(48.8, abs=0.05)
    # Zurich, the default home: WMM-2020 gives D = 3.3° E, I = 63.3°, F = 48.2 µT there.
    declination, inclination, strength = E.magnetic_elements(47.397742, 8.545594)
    assert math.degrees(declination) == pytest.approx(3.3, abs=1.0)
    assert math.degrees(inclination) == pytest.approx(63.3, abs=1.0)
    assert strength == pytest.approx(0.482, abs=0.01)
    # A grid point is returned as it is.
    assert E.magnetic_elements(40.0, -100.0)[0] == pytest.approx(847e-4)


def test_magnetometer_reads_the_home_field_in_the_body_frame():
    suite = SensorSuite(1, latitude=47.397742, longitude=8.545594, noise_scale=0.0)
    fleet = Fleet(1, dt=0.001)
    yaw = math.radians(30.0)  # nose 30° left of east (ENU yaw)
    fleet.state[0, L.QUAT] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    list(_fly(suite, fleet, 0.05, velocity=(0.0, 0.0, 0.0)))
    field = suite.magnetometer.field[0]
    declination, inclination, strength = E.magnetic_elements(47.397742, 8.545594)
    assert np.linalg.norm(field) == pytest.approx(strength)
    assert math.degrees(math.atan2(-field[2], math.hypot(field[0], field[1]))) == pytest.approx(
        math.degrees(inclination)
    )
    # Magnetic north, seen from the body: at 90° + declination − yaw from the nose (left +).
    bearing = math.degrees(math.atan2(field[1], field[0]))
    assert bearing == pytest.approx(90.0 - math.degrees(declination) - 30.0)


def test_specific_force_is_the_physics_acceleration_minus_gravity():
    fleet = Fleet(3, dt=0.001, ground_z=-math.inf, backend="reference")
    fleet.set_wind(Wind(speed=6.0, from_deg=250.0, turbulence="moderate"), seed=2)
    rng = np.random.default_rng(0)
    for _ in range(50):
        fleet.step(fleet.hover_rotor_speed[:, None] * rng.uniform(0.9, 1.1, (3, 4)))
    air = np.zeros((3, 6))
    air[:, :3] = fleet.air_velocity
    accel = reference.derivative(fleet.state, fleet.params, np.zeros((3, 4)), air)[:, L.VEL]
    accel[:, 2] += fleet.params[:, L.P_GRAVITY]

    expected = np.einsum("nji,nj->ni", quat_to_matrix(fleet.state[:, L.QUAT]), accel)
    got = specific_force(fleet.state, fleet.params, fleet.contact, fleet.air_velocity)
    np.testing.assert_allclose(got, expected, atol=1e-12)
    level = Fleet(1, dt=0.001)
    level.contact[:] = L.ON_GROUND
    grounded = specific_force(level.state, level.params, level.contact, level.air_velocity)
    np.testing.assert_allclose(grounded, [[0.0, 0.0, 9.81]])


def test_noise_scale_zero_is_the_truth_and_three_is_three_times():
    spreads = []
    for scale in (0.0, 1.0, 3.0):
        suite = SensorSuite(300, noise_scale=scale, seed=11)
        fleet = Fleet(300, dt=0.001)
        list(_fly(suite, fleet, 0.3, velocity=(0.0, 0.0, 0.0)))
        spreads.append(np.std(suite.imu.gyro - fleet.state[:, L.RATES]))
    assert spreads[0] == 0.0
    assert spreads[2] / spreads[1] == pytest.approx(3.0, rel=1e-9)  # same seed, same draws


def test_same_seed_same_readings():
    readings = []
    for _ in range(2):
        suite = SensorSuite(2, seed=42)
        fleet = Fleet(2, dt=0.001)
        list(_fly(suite, fleet, 0.5))
        readings.append((suite.imu.accel.copy(), suite.gps.fix.position.copy()))
    np.testing.assert_array_equal(readings[0][0], readings[1][0])
    np.testing.assert_array_equal(readings[0][1], readings[1][1])


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: ImuParams(gyro_noise_density=-1.0), "IMU gyro_noise_density"),
        (lambda: ImuParams(accel_random_walk=math.nan), "IMU accel_random_walk"),
        (lambda: ImuParams(rate=0.0), "IMU rate"),
        (lambda: BarometerParams(noise=math.inf), "barometer noise"),
        (lambda: MagnetometerParams(bias_tau=-5.0), "magnetometer bias_tau"),
        (lambda: GpsParams(latency=-0.1), "GPS latency"),
        (lambda: GpsParams(satellites=2.5), "GPS satellites"),
        (lambda: SensorSuite(1, noise_scale=-1.0), "sensor noise scale"),
        (lambda: SensorSuite(1, noise_scale=math.nan), "sensor noise scale"),
    ],
)
def test_bad_parameters_get_a_one_line_error(make, message):
    with pytest.raises(ValueError, match=message) as caught:
        make()
    assert "\n" not in str(caught.value)


def test_a_stuck_sensor_holds_its_reading_one_that_is_off_stops_and_a_reset_heals():
    """Vehicle 0's barometer STUCK and magnetometer OFF while the vehicles climb and
    turn: its pressure and field stay what they were, the other vehicle's move; the
    magnetometer that is off is not fresh; an unknown sensor is a one-line error; a
    reset heals every sensor."""
    from quadsitl.physics import Fleet
    from quadsitl.physics.sensors import SensorSlot, SensorSuite
    from quadsitl.physics.sensors import failures as FL

    fleet = Fleet(2, dt=0.004, ground_z=-np.inf)
    suite = SensorSuite(2, seed=3)
    slots = [SensorSlot(suite, i) for i in range(2)]

    def fly(steps: int) -> None:
        command = np.tile([420.0, 380.0, 420.0, 380.0], (2, 1))  # climb and yaw
        for _ in range(steps):
            fleet.step(command)
            suite.update(fleet.time, fleet.state, fleet.params, fleet.contact, fleet.air_velocity)
            suite.sample_due()

    fly(50)
    slots[0].fresh()
    before = [(s.pressure, s.magnetic_field.copy()) for s in slots]
    suite.fail(0, "baro", FL.STUCK)
    slots[0].fail("mag", FL.OFF)
    fly(250)
    assert slots[0].pressure == before[0][0]
    np.testing.assert_array_equal(slots[0].magnetic_field, before[0][1])
    assert slots[1].pressure != before[1][0]
    assert not np.allclose(slots[1].magnetic_field, before[1][1])
    imu, mag, baro, _ = slots[0].fresh()
    assert imu and baro and not mag and slots[0].off("mag") and not slots[0].off("baro")
    with pytest.raises(ValueError, match="unknown sensor 'lidar'"):
        suite.fail(0, "lidar", FL.OFF)
    suite.reset()
    assert not suite.failed.any()
    fly(50)
    assert slots[0].pressure != before[0][0]
