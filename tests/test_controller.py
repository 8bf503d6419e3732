"""The cascaded controller's arithmetic, checked against what the physics makes of its
commands: with the motor loop's boost off, the command is the rotor speed wanted, and
the allocation matrix (the physics' own moment model) turns it into thrust and moments."""

from __future__ import annotations

import numpy as np
import pytest

from quadsitl.flight_software.controller import (
    CascadedController,
    ControllerGains,
    Setpoint,
    allocation_matrix,
)
from quadsitl.frames import quat_from_euler
from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.physics.fleet import initial_state

DT = 0.004


def _controller() -> CascadedController:
    gains = ControllerGains.defaults()
    gains.motor_boost = 0.0  # the command is then the wanted rotor speed itself
    return CascadedController(PAPER, gains)


def _thrust_and_moments(command: np.ndarray) -> np.ndarray:
    return allocation_matrix(PAPER) @ (command**2)


def _hovering(position=(0.0, 0.0, 5.0), yaw: float = 0.0) -> np.ndarray:
    return initial_state(1, position=position, yaw=yaw, rotor_speed=PAPER.hover_rotor_speed)[0]


def test_on_its_setpoint_it_holds_the_weight_with_no_moment():
    controller = _controller()
    state = _hovering()
    command = controller.rotor_command(state, Setpoint(position=state[L.POS].copy()), DT)
    thrust, mx, my, mz = _thrust_and_moments(command)
    assert thrust == pytest.approx(PAPER.mass * PAPER.gravity, rel=1e-9)
    assert max(abs(mx), abs(my), abs(mz)) < 1e-12
    np.testing.assert_allclose(command, PAPER.hover_rotor_speed, rtol=1e-9)
    np.testing.assert_array_equal(controller.vel_integral, 0.0)


@pytest.mark.parametrize(("error", "moment", "sign"), [((1, 0, 0), 2, 1), ((0, 1, 0), 1, -1)])
def test_a_position_error_tilts_it_towards_the_setpoint(error, moment, sign):
    """East (+x, level, heading east) needs a positive pitch moment (+y, FLU); north
    (+y) a negative roll moment (about +x)."""
    controller = _controller()
    state = _hovering()
    target = state[L.POS] + np.array(error, dtype=float)
    thrust_and_moments = _thrust_and_moments(controller.rotor_command(state, Setpoint(target), DT))
    assert sign * thrust_and_moments[moment] > 1e-4
    other = 3 - moment  # the other tilt axis stays still
    assert abs(thrust_and_moments[other]) < 1e-9


def test_offboard_thrust_is_a_fraction_of_the_maximum():
    controller = _controller()
    state = _hovering()
    level = quat_from_euler(0.0, 0.0, 0.0)
    command = controller.rotor_command(state, Setpoint(attitude=level, thrust=0.5), DT)
    thrust, *moments = _thrust_and_moments(command)
    assert thrust == pytest.approx(0.5 * controller.max_thrust, rel=1e-9)
    assert np.abs(moments).max() < 1e-9
    # a thrust above 1 is the maximum; rotors at the limit of the airframe
    command = controller.rotor_command(state, Setpoint(attitude=level, thrust=1.7), DT)
    np.testing.assert_allclose(command, PAPER.max_rotor_speed, rtol=1e-9)


def test_the_velocity_integral_grows_bounded_and_idle_clears_it():
    controller = _controller()
    state = _hovering()
    state[L.I_VZ] = -1.0  # sinking while asked to hold still
    for _ in range(5000):
        controller.rotor_command(state, Setpoint(velocity=np.zeros(3)), DT)
    assert controller.vel_integral[2] == pytest.approx(3.0)  # bounded at 3 m/s²
    assert controller.vel_integral[:2].tolist() == [0.0, 0.0]
    idle = controller.rotor_command(state, Setpoint(idle=True), DT)
    np.testing.assert_allclose(idle, controller.gains.idle_fraction * PAPER.max_rotor_speed)
    np.testing.assert_array_equal(controller.vel_integral, 0.0)


def test_yaw_gives_way_when_the_motors_cannot_give_everything():
    controller = _controller()
    state = _hovering()
    state[L.ROTORS] = 0.0
    sp = Setpoint(attitude=quat_from_euler(0.0, 0.0, 0.0), thrust=1.0, body_rates=np.r_[0, 0, 9])
    thrust, mx, my, mz = _thrust_and_moments(controller.rotor_command(state, sp, DT))
    assert mz == pytest.approx(0.0, abs=1e-12)  # full thrust: no room for the yaw moment
    assert abs(mx) < 1e-12 and abs(my) < 1e-12  # nor was the attitude given up
    assert thrust == pytest.approx(controller.max_thrust, rel=1e-9)


def test_a_changed_gain_takes_effect_at_the_next_call():
    controller = _controller()
    state = _hovering()
    target = state[L.POS] + np.array([1.0, 0.0, 0.0])
    before = _thrust_and_moments(controller.rotor_command(state, Setpoint(target), DT))
    controller.gains.pos_xy = 0.0  # as MPC_XY_P = 0 would: no pull towards the position
    after = _thrust_and_moments(controller.rotor_command(state, Setpoint(target), DT))
    assert before[2] > 1e-4 and abs(after[2]) < 1e-12
