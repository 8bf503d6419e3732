"""Motor faults: a rotor's efficiency in the physics (closed form, kernel against the
reference), MAV_CMD_INJECT_FAILURE on real UDP against ``quadsitl sim`` (ACK, the thrust on
that arm dropping, the crash that follows, SYS_FAILURE_EN, a motor that does not exist),
``--fail-motor`` and bad values."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from pymavlink import mavutil

from gcs_tools.client import VehicleClient
from quadsitl.perturbations.motor_faults import MotorFaults
from quadsitl.physics import PAPER, Fleet
from quadsitl.physics import layout as L
from tests.conftest import refused_here, sim_with_client

mav = mavutil.mavlink
OMEGA = 250.0  # rad/s


def _level(n: int) -> np.ndarray:
    state = np.zeros((n, L.STATE_SIZE))
    state[:, L.I_QW] = 1.0
    state[:, L.I_PZ] = 10.0
    state[:, L.ROTORS] = OMEGA
    return state


@pytest.mark.parametrize("backend", ["compiled", "reference"])
@pytest.mark.parametrize("n", [1, 4])
def test_a_weak_rotor_loses_its_share_of_thrust_and_torque(backend, n):
    """η on rotor i: thrust Σ η_i kt Ω², roll and pitch moments Σ r_i × η_i T_i, yaw
    Σ s_i η_i kq Ω², to first order over one tiny step from rest (rotors held)."""
    dt = 1e-6
    efficiency = np.array([[0.0, 1.0, 1.0, 1.0], [0.6, 1.0, 1.0, 1.0],
                           [1.0, 0.8, 1.0, 0.6], [1.0, 1.0, 1.0, 1.0]])[:n]  # fmt: skip
    fleet = Fleet(n, dt=dt, ground_z=-math.inf, backend=backend)
    fleet.set_motor_efficiency(efficiency)
    fleet.reset(_level(n))
    fleet.step(np.full((n, 4), OMEGA))
    thrust = PAPER.thrust_coeff * OMEGA**2 * efficiency  # (n, 4) N
    xy = PAPER.rotor_positions()[:, :2]
    np.testing.assert_allclose(
        fleet.velocity[:, 2] / dt, thrust.sum(1) / PAPER.mass - PAPER.gravity, rtol=1e-5
    )
    jxx, jyy, jzz = PAPER.inertia
    yaw = PAPER.torque_coeff * OMEGA**2 * (efficiency * PAPER.rotor_yaw_sign).sum(1)
    rates = fleet.body_rates / dt
    np.testing.assert_allclose(rates[:, 0], (thrust * xy[:, 1]).sum(1) / jxx, atol=1e-2)
    np.testing.assert_allclose(rates[:, 1], -(thrust * xy[:, 0]).sum(1) / jyy, atol=1e-2)
    np.testing.assert_allclose(rates[:, 2], yaw / jzz, atol=1e-2)


def test_kernel_and_reference_agree_with_weak_rotors_and_ground_effect():
    rng = np.random.default_rng(7)
    n = 37
    state = _level(n)
    state[:, L.I_PZ] = rng.uniform(0.3, 3.0, n)
    fleets = [Fleet(n, dt=0.004, backend=b) for b in ("compiled", "reference")]
    efficiency = rng.choice([0.0, 0.6, 0.8, 1.0], (n, 4))
    for fleet in fleets:
        fleet.reset(state)
        fleet.set_motor_efficiency(efficiency)
        fleet.set_ground_effect(True)
    cmd = rng.uniform(200, 320, (n, 4))
    for _ in range(100):
        for fleet in fleets:
            fleet.step(cmd, n_substeps=2)
            assert np.isfinite(fleet.state).all()
    np.testing.assert_allclose(fleets[0].state, fleets[1].state, rtol=0, atol=1e-9)


def test_healthy_rotors_run_the_still_air_physics_bit_for_bit():
    rng = np.random.default_rng(8)
    n = 33
    plain, healed = Fleet(n, dt=0.01), Fleet(n, dt=0.01)
    for fleet in (plain, healed):
        fleet.reset(_level(n))
    healed.set_motor_efficiency((1.0, 0.5, 1.0, 1.0))
    healed.set_motor_efficiency((1.0, 1.0, 1.0, 1.0))
    assert not healed.world
    cmd = rng.uniform(200, 300, (n, 4))
    for _ in range(30):
        plain.step(cmd, n_substeps=2)
        healed.step(cmd, n_substeps=2)
    np.testing.assert_array_equal(healed.state, plain.state)


def test_bad_motor_efficiencies_are_refused_in_one_line():
    fleet = Fleet(2)
    for bad, match in (
        ((1.0, 1.0, 1.5, 1.0), r"in \[0, 1\]"),
        ((1.0, math.nan, 1.0, 1.0), r"in \[0, 1\]"),
        ((-0.1, 1.0, 1.0, 1.0), r"in \[0, 1\]"),
        ((1.0, 1.0, 1.0), "shape"),
        ("weak", "numbers|shape"),
    ):
        with pytest.raises(ValueError, match=match) as error:
            fleet.set_motor_efficiency(bad)  # type: ignore[arg-type]
        assert "\n" not in str(error.value)
    assert (fleet.motor_efficiency == 1.0).all()
    motors = MotorFaults(fleet)
    for motor in (7, -1, 2.5, True):
        with pytest.raises(ValueError, match="does not exist") as error:
            motors.inject(motor, 0.0)  # type: ignore[arg-type]
        assert "\n" not in str(error.value)


def test_sim_refuses_bad_fail_motor_options_in_one_line():
    for option, match in (
        ("7", "motor 7 does not exist"),
        ("2:1.5", r"in \[0, 1\]"),
        ("two", "--fail-motor must be N or N:EFFICIENCY"),
        ("2:nan", r"in \[0, 1\]"),
    ):
        result = refused_here("sim", "--logs", "none", "--fail-motor", option, "--duration", "1")
        assert result.returncode == 2, result.stderr
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and re.search(match, lines[0]), result.stderr


def _inject(client: VehicleClient, unit: int, kind: int, motor: float, param4: float = 0.0):
    """MAV_CMD_INJECT_FAILURE: the MAV_RESULT and the STATUSTEXTs that came with it."""
    before = len(client.texts)
    result = client.command(mav.MAV_CMD_INJECT_FAILURE, unit, kind, motor, param4, check=False)
    client.wait(lambda: len(client.texts) > before or result == 0, 5, "its STATUSTEXT")
    return result, " ".join(client.texts[before:])


def test_inject_failure_over_udp_stops_a_motor_and_the_vehicle_crashes():
    """Real UDP against ``quadsitl sim``: refused while SYS_FAILURE_EN = 0; then a motor
    that does not exist is refused with its reason, an airspeed sensor (there is none) is
    unsupported, and motor 1
    (front, plus layout) OFF is acknowledged: the front arm's thrust gone, the nose drops
    (pitch down, FRD), the vehicle flips and crashes (PX4's outcome on a quadrotor with
    default parameters), disarmed."""
    with sim_with_client("--speed 2 --logs none", connect_timeout=60) as (client, sim):
        result, text = _inject(client, mav.FAILURE_UNIT_SYSTEM_MOTOR, mav.FAILURE_TYPE_OFF, 1)
        assert result == mav.MAV_RESULT_DENIED and "SYS_FAILURE_EN" in text
        client.param_types["SYS_FAILURE_EN"] = mav.MAV_PARAM_TYPE_INT32
        assert client.set_param("SYS_FAILURE_EN", 1) == 1
        client.arm()
        client.takeoff(4.0)
        client.wait(lambda: client.position_enu()[2] > 3.9, 60, "take-off")
        result, text = _inject(client, mav.FAILURE_UNIT_SYSTEM_MOTOR, mav.FAILURE_TYPE_OFF, 7)
        assert result == mav.MAV_RESULT_DENIED
        assert "motor 7 does not exist" in text
        result, text = _inject(client, mav.FAILURE_UNIT_SENSOR_AIRSPEED, mav.FAILURE_TYPE_OFF, 0)
        assert result == mav.MAV_RESULT_UNSUPPORTED and "AIRSPEED" in text
        result, _ = _inject(client, mav.FAILURE_UNIT_SYSTEM_MOTOR, mav.FAILURE_TYPE_OFF, 1)
        assert result == mav.MAV_RESULT_ACCEPTED
        client.wait(lambda: any("motor 1 off" in t for t in client.texts), 5, "the report")
        nose_down = client.wait_message("ATTITUDE", 10, lambda m: m.pitch < math.radians(-20))
        assert nose_down is not None
        client.wait(lambda: any("crashed" in t for t in client.texts), 30, "the crash")
        client.wait(lambda: not client.armed, 10, "disarmed")
    assert "Traceback" not in sim.output


def test_inject_failure_over_udp_turns_the_gps_off_and_sticks_the_barometer():
    """Real UDP: the GPS OFF is acknowledged, GPS_RAW_INT then has no fix and no
    satellites and SYS_STATUS calls the GPS unhealthy; OK brings the fix back. The
    barometer STUCK keeps reporting one pressure while the vehicle climbs; a second
    barometer does not exist; GARBAGE is not simulated."""
    gps_bit = mav.MAV_SYS_STATUS_SENSOR_GPS
    with sim_with_client("--speed 2 --logs none", connect_timeout=60) as (client, sim):
        client.param_types["SYS_FAILURE_EN"] = mav.MAV_PARAM_TYPE_INT32
        assert client.set_param("SYS_FAILURE_EN", 1) == 1
        client.wait_message("GPS_RAW_INT", 10, lambda m: m.fix_type == 3)
        result, _ = _inject(client, mav.FAILURE_UNIT_SENSOR_GPS, mav.FAILURE_TYPE_OFF, 0)
        assert result == mav.MAV_RESULT_ACCEPTED
        client.wait(lambda: any("gps off" in t for t in client.texts), 5, "the report")
        client.wait_message(
            "GPS_RAW_INT", 10, lambda m: m.fix_type <= 1 and m.satellites_visible == 0
        )
        status = client.wait_message("SYS_STATUS", 10)
        assert status.onboard_control_sensors_present & gps_bit
        assert not status.onboard_control_sensors_health & gps_bit
        result, _ = _inject(client, mav.FAILURE_UNIT_SENSOR_GPS, mav.FAILURE_TYPE_OK, 0)
        assert result == mav.MAV_RESULT_ACCEPTED
        client.wait_message("GPS_RAW_INT", 10, lambda m: m.fix_type == 3)
        client.wait_message("SYS_STATUS", 10, lambda m: m.onboard_control_sensors_health & gps_bit)
        result, text = _inject(client, mav.FAILURE_UNIT_SENSOR_BARO, mav.FAILURE_TYPE_OFF, 2)
        assert result == mav.MAV_RESULT_DENIED and "baro 2 does not exist" in text
        result, text = _inject(client, mav.FAILURE_UNIT_SENSOR_BARO, mav.FAILURE_TYPE_GARBAGE, 0)
        assert result == mav.MAV_RESULT_UNSUPPORTED and "GARBAGE" in text
        result, _ = _inject(client, mav.FAILURE_UNIT_SENSOR_BARO, mav.FAILURE_TYPE_STUCK, 0)
        assert result == mav.MAV_RESULT_ACCEPTED
        client.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_HIGHRES_IMU, 50_000)
        stuck = client.wait_message("HIGHRES_IMU", 10).abs_pressure
        client.arm()
        client.takeoff(5.0)
        client.wait(lambda: client.position_enu()[2] > 4.5, 60, "take-off")
        # 5 m higher: about 0.6 hPa less air, and a barometer that still reads the same
        assert client.wait_message("HIGHRES_IMU", 10).abs_pressure == stuck
    assert "Traceback" not in sim.output


def test_fail_motor_fits_a_weak_motor_from_power_on_and_a_reboot_keeps_it():
    """``--fail-motor 3:0.8`` (SimConfig.motor_faults): the vehicle's physics has the weak
    motor from power-on and after a reboot; an injected failure does not outlive one."""
    from quadsitl.simulator.runner import SimConfig, Simulator

    sim = Simulator(
        SimConfig(
            gcs_url=None,
            api_url=None,
            extra_urls=["udpin:127.0.0.1:0"],
            log_dir=None,
            motor_faults={3: 0.8},
        )
    )
    try:
        np.testing.assert_array_equal(sim.vehicle.fleet.motor_efficiency[0], [1, 1, 0.8, 1])
        sim.vehicle.reboot()  # the hardware's: still weak after a reboot
        np.testing.assert_array_equal(sim.vehicle.fleet.motor_efficiency[0], [1, 1, 0.8, 1])
        sim.vehicle.motors.inject(1, 0.0)
        sim.vehicle.reboot()  # an injected failure is gone after one
        np.testing.assert_array_equal(sim.vehicle.fleet.motor_efficiency[0], [1, 1, 0.8, 1])
    finally:
        sim.close()


def test_env_fault_option_fails_the_motor_on_time_and_each_episode_starts_healthy():
    import gymnasium as gym

    env = gym.make(
        "QuadSITL/Hover-v0", faults={"motor": 2, "efficiency": 0.6, "at": 0.12}
    ).unwrapped
    fleet = env.engine.fleet
    env.reset(seed=1)
    efficiencies = []
    for _ in range(5):  # control period 0.05 s: steps start at 0, 0.05, 0.10, 0.15, 0.20 s
        env.step(np.zeros(4))
        efficiencies.append(fleet.motor_efficiency[0].copy())
    np.testing.assert_array_equal(efficiencies[2], [1, 1, 1, 1])
    np.testing.assert_array_equal(efficiencies[3], [1, 0.6, 1, 1])
    np.testing.assert_array_equal(efficiencies[4], [1, 0.6, 1, 1])
    env.reset(seed=2)
    np.testing.assert_array_equal(fleet.motor_efficiency[0], [1, 1, 1, 1])
    for _ in range(40):
        obs, *_ = env.step(np.zeros(4))
        assert np.isfinite(obs).all()
    env.close()


def test_env_fault_and_ground_effect_options_are_checked_in_one_line():
    import gymnasium as gym

    for options, match in (
        ({"faults": {"motor": 7}}, "motor 7 does not exist"),
        ({"faults": {"motor": 2, "efficiency": 1.5}}, r"in \[0, 1\]"),
        ({"faults": {"motor": 2, "at": -1}}, "'at' must be a time"),
        ({"faults": {"motor": 2, "at": math.nan}}, "'at' must be a time"),
        ({"faults": {"engine": 2}}, "a fault needs 'motor'"),
        ({"faults": "motor 2"}, "faults must be a dict"),
        ({"ground_effect": "yes"}, "ground_effect must be True or False"),
    ):
        with pytest.raises(ValueError, match=match) as error:
            gym.make("QuadSITL/Land-v0", **options)
        assert "\n" not in str(error.value)
