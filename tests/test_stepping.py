"""Stepping is written once: a lone vehicle is a batch of one, stepped as a group's
vehicles are (:mod:`quadsitl.vehicle.stepping`)."""

from __future__ import annotations

import numpy as np
import pytest

from quadsitl.mavlink import mavlink as mav
from quadsitl.mavlink.motor_path import MotorPath
from quadsitl.physics import layout as L
from quadsitl.vehicle.group import VehicleGroup
from quadsitl.vehicle.vehicle import Vehicle
from quadsitl.wire.lockstep import ARMED_FLAG, LOCKSTEP_FLAG

GRAVITY = 9.81


def test_a_lone_vehicle_flies_exactly_as_a_group_of_one():
    lone = Vehicle()
    group = VehicleGroup(1)
    member = group.vehicles[0]
    for v in (lone, member):
        assert v.takeoff(4.0).ok and v.arm().ok
    for second in range(12):
        for _ in range(1000):
            lone.step()
            group.step()
        assert lone.time == member.time
        np.testing.assert_array_equal(lone.state, member.state, err_msg=f"at {second + 1} s")
        assert lone.battery.remaining == member.battery.remaining
    assert lone.altitude == pytest.approx(4.0, abs=0.2)  # the flight went somewhere
    assert lone.battery.remaining < 1.0
    assert list(lone.events) == list(member.events)


def test_a_vehicle_of_a_group_of_several_is_stepped_with_its_group():
    group = VehicleGroup(2)
    with pytest.raises(RuntimeError, match="stepped with its group"):
        group.vehicles[0].step()
    with pytest.raises(RuntimeError, match="stepped with its group"):
        group.vehicles[1].advance()


def _round(path: MotorPath, encoder: mav.MAVLink, controls: float) -> None:
    """One lockstep HIL_ACTUATOR_CONTROLS of ``controls`` on all four motors, armed."""
    msg = encoder.hil_actuator_controls_encode(
        0, [controls] * 4 + [0.0] * 12, ARMED_FLAG, LOCKSTEP_FLAG
    )
    msg.pack(encoder)
    encoder.seq = (encoder.seq + 1) % 256  # as send() does: a new frame, not a resend
    assert path.command(msg) is None  # accepted, nothing to warn of


def test_lockstep_rounds_of_a_simulators_lone_vehicle_move_its_sensors():
    """The simulator's vehicle is a group of one; its lockstep rounds step the group's
    sensors too, so that the IMU reads the free fall and then the ground."""
    vehicle = VehicleGroup(1, sensor_noise=0.0).vehicles[0]
    path = MotorPath(vehicle, lockstep=True)
    encoder = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    assert vehicle.arm().ok
    assert path.stage_motion([0.0] * 6 + [0.0]).ok  # at rest, rotors stopped
    assert path.reset([0.0, 0.0, -20.0, 1.0, 0.0, 0.0, 0.0]).ok  # 20 m up
    for _ in range(25):
        _round(path, encoder, 0.0)
    assert vehicle.time == pytest.approx(0.1)
    assert vehicle.state[L.I_VZ] == pytest.approx(-GRAVITY * 0.1, rel=0.05)  # falling
    np.testing.assert_allclose(vehicle.sensors.accel, 0.0, atol=0.2)  # weightless
    assert path.reset([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).ok  # on the ground
    for _ in range(25):
        _round(path, encoder, 0.0)
    np.testing.assert_allclose(vehicle.sensors.accel, [0.0, 0.0, GRAVITY], atol=0.2)
