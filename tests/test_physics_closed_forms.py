"""The physics against closed-form results (free fall, terminal velocity, hover, ...)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl.frames import quat_from_euler, quat_rotate
from quadsitl.physics import PAPER, PAPER_X, Fleet
from quadsitl.physics import layout as L
from quadsitl.physics.reference import derivative

NO_GROUND = -math.inf


def test_derived_values_match_the_paper():
    assert PAPER.hover_rotor_speed == pytest.approx(225.7, abs=0.05)
    assert PAPER.max_rotor_speed == pytest.approx(319.2, abs=0.05)
    assert PAPER.terminal_velocity == pytest.approx(26.6, abs=0.05)
    assert PAPER_X.hover_rotor_speed == PAPER.hover_rotor_speed


def test_free_fall_without_drag_follows_half_g_t_squared():
    frame = PAPER.replace(drag_coeff=0.0)
    fleet = Fleet(1, airframe=frame, dt=0.01, ground_z=NO_GROUND)
    fleet.reset(np.r_[0, 0, 100.0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    for _ in range(200):
        fleet.step(np.zeros(4))
    t = fleet.time
    assert t == pytest.approx(2.0)
    assert fleet.position[0, 2] == pytest.approx(100.0 - 0.5 * 9.81 * t * t, abs=1e-9)
    assert fleet.velocity[0, 2] == pytest.approx(-9.81 * t, abs=1e-9)


def test_terminal_velocity_with_quadratic_drag():
    fleet = Fleet(1, dt=0.01, ground_z=NO_GROUND)
    fleet.reset(np.r_[0, 0, 0.0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    fleet.step(np.zeros(4), n_substeps=6000)  # 60 s: many time constants
    assert -fleet.velocity[0, 2] == pytest.approx(PAPER.terminal_velocity, rel=1e-6)


@pytest.mark.parametrize("airframe", [PAPER, PAPER_X])
def test_hover_rotor_speed_holds_position(airframe):
    fleet = Fleet(1, airframe=airframe, dt=0.01, ground_z=NO_GROUND)
    fleet.reset(
        np.r_[1.0, 2.0, 3.0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, [airframe.hover_rotor_speed] * 4]
    )
    fleet.step(np.full(4, airframe.hover_rotor_speed), n_substeps=500)
    np.testing.assert_allclose(fleet.position[0], [1.0, 2.0, 3.0], atol=1e-9)
    np.testing.assert_allclose(fleet.body_rates[0], 0.0, atol=1e-12)


@pytest.mark.parametrize("airframe", [PAPER, PAPER_X])
@pytest.mark.parametrize("rotor", range(4))
def test_moments_equal_sum_of_r_cross_f_plus_reaction(airframe, rotor):
    """One rotor spinning alone: J ω̇ must equal r_i × F_i + s_i kq Ω² e_z."""
    omega = 250.0
    state = np.zeros((1, L.STATE_SIZE))
    state[0, L.I_QW] = 1.0
    state[0, L.I_ROTOR0 + rotor] = omega
    params = airframe.to_params()[None, :]
    rotor_cmd = state[:, L.ROTORS]
    dstate = derivative(state, params, rotor_cmd)
    torque = np.asarray(airframe.inertia) * dstate[0, L.RATES]
    force = np.array([0.0, 0.0, airframe.thrust_coeff * omega**2])
    expected = np.cross(airframe.rotor_positions()[rotor], force)
    expected[2] += airframe.rotor_yaw_sign[rotor] * airframe.torque_coeff * omega**2
    np.testing.assert_allclose(torque, expected, rtol=1e-12, atol=1e-15)


def test_pitch_moment_sign_is_the_codes_not_eq6():
    """Plus layout: My = l·kt·(Ω3² − Ω1²). The front rotor alone pitches the nose up."""
    fleet = Fleet(1, dt=0.001, ground_z=NO_GROUND)
    state = fleet.state[0].copy()
    state[L.ROTORS] = [300.0, 0.0, 0.0, 0.0]
    fleet.reset(state)
    params = fleet.params
    dstate = derivative(fleet.state, params, fleet.rotor_speeds)
    my = PAPER.inertia[1] * dstate[0, L.I_WY]
    assert my == pytest.approx(PAPER.arm_length * PAPER.thrust_coeff * (0.0 - 300.0**2))
    fleet.step(state[L.ROTORS], n_substeps=50)
    nose = quat_rotate(fleet.quaternion[0], [1.0, 0.0, 0.0])
    assert nose[2] > 0.0  # nose is up


def test_yaw_torque_sign_follows_the_reaction_torques():
    """Rotors 2 and 4 faster than 1 and 3: Mz = kq(−Ω1² + Ω2² − Ω3² + Ω4²) > 0, yaw left."""
    hover = PAPER.hover_rotor_speed
    fleet = Fleet(1, dt=0.01, ground_z=NO_GROUND)
    cmd = np.array([hover - 10, hover + 10, hover - 10, hover + 10])
    fleet.reset(np.r_[0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, cmd])
    fleet.step(cmd, n_substeps=20)
    assert fleet.body_rates[0, 2] > 0.1
    np.testing.assert_allclose(fleet.body_rates[0, :2], 0.0, atol=1e-9)


def _tumbling_fleet(dt: float) -> tuple[Fleet, np.ndarray]:
    fleet = Fleet(1, dt=dt, ground_z=NO_GROUND)
    q = quat_from_euler(0.3, -0.2, 1.0)
    fleet.reset(np.r_[0, 0, 0, 1.0, -2.0, 0.5, q, 2.0, -1.0, 3.0, 200, 240, 210, 230])
    return fleet, np.array([250.0, 180.0, 300.0, 150.0])


def test_rk4_global_error_shrinks_sixteen_fold_when_dt_halves():
    duration = 0.8
    truth, cmd = _tumbling_fleet(1e-4)
    truth.step(cmd, n_substeps=round(duration / 1e-4))
    errors = []
    for dt in (0.02, 0.01, 0.005):
        fleet, cmd = _tumbling_fleet(dt)
        fleet.step(cmd, n_substeps=round(duration / dt))
        errors.append(np.abs(fleet.state[0] - truth.state[0]).max())
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    for ratio in ratios:
        assert 12.0 < ratio < 20.0, (errors, ratios)


def test_quaternion_stays_unit_while_tumbling():
    fleet, cmd = _tumbling_fleet(0.01)
    for _ in range(300):
        fleet.step(cmd)
        assert np.linalg.norm(fleet.quaternion[0]) == pytest.approx(1.0, abs=1e-14)


def test_torque_free_spin_conserves_angular_momentum_and_energy():
    frame = PAPER.replace(inertia=(6e-3, 9e-3, 1.3e-2), aero_moment_coeff=0.0, drag_coeff=0.0)
    fleet = Fleet(1, airframe=frame, dt=1e-3, ground_z=NO_GROUND)
    fleet.reset(np.r_[0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1.0, 0.5, 3.0, 0, 0, 0, 0])
    inertia = np.asarray(frame.inertia)

    def momentum_and_energy():
        rates = fleet.body_rates[0]
        return quat_rotate(fleet.quaternion[0], inertia * rates), 0.5 * rates @ (inertia * rates)

    momentum0, energy0 = momentum_and_energy()
    fleet.step(np.zeros(4), n_substeps=3000)
    momentum, energy = momentum_and_energy()
    assert not np.allclose(fleet.body_rates[0], [1.0, 0.5, 3.0], atol=1e-2)  # it did precess
    np.testing.assert_allclose(momentum, momentum0, rtol=0, atol=1e-9)
    assert energy == pytest.approx(energy0, rel=1e-9)


def test_motor_lag_reaches_63_percent_in_one_time_constant():
    fleet = Fleet(1, dt=1e-3, ground_z=NO_GROUND)
    fleet.reset(np.r_[0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    target = PAPER.max_rotor_speed
    fleet.step(np.full(4, target), n_substeps=180)  # 1/k_Ω = 0.18 s
    np.testing.assert_allclose(fleet.rotor_speeds[0], (1 - math.exp(-1)) * target, rtol=1e-9)


def test_rotor_speeds_stay_within_limits():
    fleet = Fleet(1, dt=0.01, ground_z=NO_GROUND)
    fleet.step(np.full(4, 1e6), n_substeps=300)
    assert fleet.rotor_speeds.max() <= PAPER.max_rotor_speed
    assert fleet.rotor_speeds[0] == pytest.approx([PAPER.max_rotor_speed] * 4, rel=1e-6)
    fleet.step(np.full(4, -1e6), n_substeps=300)
    assert fleet.rotor_speeds.min() >= 0.0
