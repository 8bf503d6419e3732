"""Ground contact: resting, take-off, gentle touchdown, and the three kinds of crash."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl.frames import quat_from_euler
from quadsitl.physics import PAPER, Fleet
from quadsitl.physics import layout as L

HOVER = PAPER.hover_rotor_speed


def _fleet_at(
    z: float, vz: float = 0.0, roll: float = 0.0, rotors: float = HOVER, contact=L.AIRBORNE
):
    fleet = Fleet(1, dt=0.005, ground_z=0.0)
    fleet.reset(
        np.r_[0, 0, z, 0, 0, vz, quat_from_euler(roll, 0, 0), 0, 0, 0, [rotors] * 4],
        contact=contact,
    )
    return fleet


def test_a_vehicle_rests_on_the_ground_with_motors_off():
    fleet = _fleet_at(PAPER.gear_height, rotors=0.0, contact=L.ON_GROUND)
    fleet.step(np.zeros(4), n_substeps=400)
    assert fleet.contact[0] == L.ON_GROUND
    assert fleet.position[0, 2] == pytest.approx(PAPER.gear_height)
    np.testing.assert_array_equal(fleet.velocity[0], 0.0)


def test_take_off_from_the_ground():
    fleet = _fleet_at(PAPER.gear_height, rotors=0.0, contact=L.ON_GROUND)
    fleet.step(np.full(4, 1.2 * HOVER), n_substeps=400)  # 2 s at 44 % excess thrust
    assert fleet.contact[0] == L.AIRBORNE
    assert fleet.position[0, 2] > PAPER.gear_height + 1.0


def test_slow_vertical_touchdown_lands():
    fleet = _fleet_at(0.5, vz=-0.5)
    for _ in range(400):
        fleet.step(np.full(4, HOVER))  # hover thrust: keeps descending at ~0.5 m/s
        if fleet.contact[0] != L.AIRBORNE:
            break
    assert fleet.contact[0] == L.ON_GROUND
    assert fleet.touchdown_speed[0] == pytest.approx(0.5, abs=0.05)
    fleet.step(np.zeros(4), n_substeps=100)
    assert fleet.contact[0] == L.ON_GROUND


def test_fast_touchdown_crashes_and_the_crash_is_sticky():
    fleet = _fleet_at(0.5, vz=-3.0, rotors=0.0)
    fleet.step(np.zeros(4), n_substeps=100)
    assert fleet.contact[0] == L.CRASHED
    assert fleet.touchdown_speed[0] > PAPER.max_touchdown_speed
    position = fleet.position.copy()
    fleet.step(np.full(4, PAPER.max_rotor_speed), n_substeps=200)  # full throttle: stays down
    assert fleet.contact[0] == L.CRASHED
    np.testing.assert_array_equal(fleet.position, position)
    fleet.reset()
    assert fleet.contact[0] == L.AIRBORNE


def test_tilted_touchdown_crashes():
    # 16°: beyond the 15° touchdown limit while the rotor discs still clear the ground.
    tilt = math.radians(16)
    assert (PAPER.arm_length + PAPER.rotor_radius) * math.sin(tilt) < PAPER.gear_height
    fleet = _fleet_at(0.3, vz=-0.3, roll=tilt)
    for _ in range(200):
        fleet.step(np.full(4, HOVER))
        if fleet.contact[0] != L.AIRBORNE:
            break
    assert fleet.contact[0] == L.CRASHED
    assert fleet.touchdown_speed[0] < PAPER.max_touchdown_speed  # not too fast: too tilted


def test_rotor_disc_striking_the_ground_is_a_crash():
    # Body well above its gear height, but banked 60°: the low rotor disc hits first.
    fleet = _fleet_at(0.25, vz=-0.2, roll=math.radians(60), rotors=0.0)
    fleet.step(np.zeros(4))
    assert fleet.contact[0] == L.CRASHED
    assert fleet.position[0, 2] > PAPER.gear_height


def test_no_ground_when_ground_z_is_minus_infinity():
    fleet = Fleet(1, dt=0.01, ground_z=-math.inf)
    fleet.reset(np.r_[0, 0, 0.0, 0, 0, -5.0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    fleet.step(np.zeros(4), n_substeps=100)
    assert fleet.contact[0] == L.AIRBORNE
    assert fleet.position[0, 2] < -5.0
