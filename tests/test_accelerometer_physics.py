"""The accelerometer feels what the physics does: a weak rotor, ground effect, drag in
the wind. The noise-free reading, rotated back into the world and less gravity, is the
acceleration of the physics' own velocity (finite differences of the integrated state),
with the compiled kernel and the numpy reference alike."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl.frames import quat_to_matrix
from quadsitl.physics import Fleet
from quadsitl.physics import layout as L
from quadsitl.physics.sensors import SensorSuite
from quadsitl.physics.wind import Wind

DT = 0.0005  # s: the finite differences' error is O(dt²) in a smooth motion


def _world(fleet: Fleet, case: str) -> None:
    """Put the fleet's vehicles in one of the worlds the physics models beyond the paper."""
    if case == "failed motor":  # motor 4 at half its thrust, high above the ground
        fleet.state[:, L.I_PZ] = 20.0
        fleet.set_motor_efficiency([1.0, 1.0, 1.0, 0.5])
    elif case == "ground effect":  # hubs 0.15 m above the ground (1.5 rotor radii)
        fleet.state[:, L.I_PZ] = 0.15
        fleet.set_ground_effect(True)
    elif case == "wind":  # a steady 8 m/s wind and a vehicle flying against it
        fleet.state[:, L.I_PZ] = 20.0
        fleet.state[:, L.VEL] = (2.0, -1.0, 0.5)
        fleet.set_wind(Wind(speed=8.0, from_deg=250.0), seed=1)


def _record(case: str, backend: str, steps: int = 40):
    """Step one hovering vehicle (rotors at hover speed, held there) in ``case``'s world;
    the noise-free accelerometer after each step, and the velocities."""
    fleet = Fleet(1, dt=DT, ground_z=0.0, backend=backend)
    _world(fleet, case)
    suite = SensorSuite(1, noise_scale=0.0)
    command = fleet.state[:, L.ROTORS].copy()  # rotors already there: no motor lag
    velocities, readings, quats, gravity = [], [], [], fleet.params[0, L.P_GRAVITY]
    for _ in range(steps):
        fleet.step(command)
        suite.update(fleet.time, fleet.state, fleet.params, fleet.contact, fleet.air_velocity)
        velocities.append(fleet.state[0, L.VEL].copy())
        readings.append(suite.sample_due().imu.accel[0].copy())
        quats.append(fleet.state[0, L.QUAT].copy())
        assert fleet.contact[0] == L.AIRBORNE
    return np.array(velocities), np.array(readings), np.array(quats), gravity


@pytest.mark.parametrize("backend", ["compiled", "reference"])
@pytest.mark.parametrize("case", ["failed motor", "ground effect", "wind"])
def test_the_noise_free_accelerometer_is_the_physics_acceleration_less_gravity(case, backend):
    velocities, readings, quats, gravity = _record(case, backend)
    fresh = [
        k for k in range(1, len(readings) - 1) if not np.array_equal(readings[k], readings[k - 1])
    ]
    assert len(fresh) >= 3  # the IMU sampled (250 Hz) several times within the record
    for k in fresh:
        measured = quat_to_matrix(quats[k][None])[0] @ readings[k]  # world ENU
        measured[2] -= gravity
        central = (velocities[k + 1] - velocities[k - 1]) / (2 * DT)
        np.testing.assert_allclose(measured, central, atol=1e-4, err_msg=f"{case}, step {k}")


def test_a_rotor_at_half_thrust_reads_8_58_and_ground_effect_at_0_15_m_reads_10_09():
    """Motor 4 at 50 %: the thrust is 3.5/4 of hover's, 8.58 m/s² where a level hover
    reads 9.81; hubs at 0.15 m with R = 0.1 m: G = 1/(1 − (0.1/0.6)²), 10.09 m/s²."""
    _, weak, _, g = _record("failed motor", "compiled", steps=9)
    assert weak[-1, 2] == pytest.approx(g * 3.5 / 4, abs=0.01)
    _, near, _, g = _record("ground effect", "compiled", steps=9)
    assert near[-1, 2] == pytest.approx(g / (1 - (0.1 / 0.6) ** 2), abs=0.01)
    assert math.isclose(near[-1, 2], 10.09, abs_tol=0.01)
