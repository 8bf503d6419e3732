"""Stepping is written once: a lone vehicle is a batch of one, stepped as a group's
vehicles are (:mod:`quadsitl.flight_software.stepping`)."""

from __future__ import annotations

import numpy as np
import pytest

from quadsitl.flight_software.group import VehicleGroup
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.physics import layout as L
from quadsitl.simulator.motor_path import MotorPath
from quadsitl.simulator.motor_slot import MotorSlot
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


def _round(path: MotorPath, seq: int, controls: float) -> None:
    """One lockstep HIL_ACTUATOR_CONTROLS of ``controls`` on all four motors, armed (a
    new frame, sequence number ``seq``, not a resend)."""
    reply = path.hil_command((255, 190, seq % 256), 0, LOCKSTEP_FLAG, [controls] * 16, ARMED_FLAG)
    assert reply.rows == [0] and reply.warnings == []  # answered, nothing to warn of


def test_lockstep_rounds_of_a_simulators_lone_vehicle_move_its_sensors():
    """The simulator's vehicle is a group of one; its lockstep rounds step the group's
    sensors too, so that the IMU reads the free fall and then the ground."""
    vehicle = VehicleGroup(1, sensor_noise=0.0).vehicles[0]
    slot = MotorSlot(vehicle)
    path = MotorPath(vehicle.batch, [slot], lockstep=True)
    assert vehicle.arm().ok
    assert slot.stage_motion([0.0] * 6 + [0.0]).ok  # at rest, rotors stopped
    assert slot.reset([0.0, 0.0, -20.0, 1.0, 0.0, 0.0, 0.0]).ok  # 20 m up
    for seq in range(25):
        _round(path, seq, 0.0)
    assert vehicle.time == pytest.approx(0.1)
    assert vehicle.state[L.I_VZ] == pytest.approx(-GRAVITY * 0.1, rel=0.05)  # falling
    np.testing.assert_allclose(vehicle.sensors.accel, 0.0, atol=0.2)  # weightless
    assert slot.reset([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).ok  # on the ground
    for seq in range(25):
        _round(path, seq, 0.0)
    np.testing.assert_allclose(vehicle.sensors.accel, [0.0, 0.0, GRAVITY], atol=0.2)
