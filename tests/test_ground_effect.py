"""Ground effect: the Cheeseman–Bennett thrust ratio, through the reference and the
compiled kernel, for a batch and a single vehicle; off by default; never a NaN."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl.physics import PAPER, Fleet, reference
from quadsitl.physics import layout as L
from quadsitl.physics.ground_effect import MAX_THRUST_RATIO, thrust_ratio

R = PAPER.rotor_radius
OMEGA = 300.0  # rad/s: more thrust than weight, so that nothing touches the ground


def cheeseman_bennett(height_over_radius: float) -> float:
    return 1.0 / (1.0 - (1.0 / (4.0 * height_over_radius)) ** 2)


def _level_at(heights_over_r: list[float]) -> np.ndarray:
    """Level vehicles at rest, rotor hubs ``h/R`` rotor radii above the ground."""
    state = np.zeros((len(heights_over_r), L.STATE_SIZE))
    state[:, L.I_QW] = 1.0
    state[:, L.I_PZ] = np.asarray(heights_over_r) * R
    state[:, L.ROTORS] = OMEGA
    return state


HEIGHTS = [1.0, 2.0, 4.0]


@pytest.mark.parametrize("batch", [True, False])
def test_reference_thrust_ratio_at_h_over_r_1_2_4_is_cheeseman_bennett(batch):
    params = np.stack([PAPER.to_params(0.0)] * 3)
    params[:, L.P_GROUND_EFFECT] = 1.0
    state = _level_at(HEIGHTS)
    cmd = np.full((3, 4), OMEGA)
    free = params.copy()
    free[:, L.P_GROUND_Z] = -math.inf
    rows = [slice(0, 3)] if batch else [slice(i, i + 1) for i in range(3)]
    for r in rows:
        near = reference.derivative(state[r], params[r], cmd[r])[:, L.I_VZ] + PAPER.gravity
        far = reference.derivative(state[r], free[r], cmd[r])[:, L.I_VZ] + PAPER.gravity
        expected = [cheeseman_bennett(h) for h in np.asarray(HEIGHTS)[r]]
        np.testing.assert_allclose(near / far, expected, rtol=1e-12)


@pytest.mark.parametrize("n", [3, 1])
def test_kernel_thrust_ratio_at_h_over_r_1_2_4_is_cheeseman_bennett(n):
    """One tiny step from rest: the vertical acceleration is thrust / m − g, its thrust
    in ground effect over the same vehicle's far from the ground is the ratio (the height
    changes by 1e-10 m over the step)."""
    dt = 1e-5
    for start in range(0, 3, n):
        heights = HEIGHTS[start : start + n]
        accel = {}
        for ground in (True, False):
            fleet = Fleet(n, dt=dt, ground_z=0.0 if ground else -math.inf)
            fleet.set_ground_effect(True)
            fleet.reset(_level_at(heights))
            fleet.step(np.full((n, 4), OMEGA))
            accel[ground] = fleet.velocity[:, 2] / dt + PAPER.gravity
        expected = [cheeseman_bennett(h) for h in heights]
        np.testing.assert_allclose(accel[True] / accel[False], expected, rtol=1e-6)


def test_kernel_and_reference_agree_landing_in_ground_effect():
    """A batch descending through ground effect onto the ground, tilted and turning:
    the compiled world build and the reference stay within 1e-9."""
    rng = np.random.default_rng(3)
    n = 40
    state = _level_at(list(rng.uniform(1.0, 12.0, n)))
    state[:, L.VEL] = rng.uniform(-1, 1, (n, 3))
    state[:, L.RATES] = rng.uniform(-1, 1, (n, 3))
    fleets = [Fleet(n, dt=0.005, backend=b) for b in ("compiled", "reference")]
    for fleet in fleets:
        fleet.reset(state)
        fleet.set_ground_effect(True, mask=np.arange(n) % 3 != 0)
    cmd = rng.uniform(150, 260, (n, 4))
    for _ in range(60):
        for fleet in fleets:
            fleet.step(cmd, n_substeps=2)
    np.testing.assert_allclose(fleets[0].state, fleets[1].state, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fleets[0].contact, fleets[1].contact)


def test_ground_effect_is_off_by_default_and_off_is_the_plain_physics_bit_for_bit():
    n = 33
    rng = np.random.default_rng(4)
    state = _level_at(list(rng.uniform(0.5, 3.0, n)))
    plain, toggled = Fleet(n, dt=0.01), Fleet(n, dt=0.01)
    assert not plain.params[:, L.P_GROUND_EFFECT].any()
    for fleet in (plain, toggled):
        fleet.reset(state)
    toggled.set_ground_effect(True)
    toggled.set_ground_effect(False)  # back to the still-air build
    cmd = rng.uniform(150, 300, (n, 4))
    for _ in range(30):
        plain.step(cmd, n_substeps=2)
        toggled.step(cmd, n_substeps=2)
    np.testing.assert_array_equal(toggled.state, plain.state)


def test_ratio_is_held_below_half_a_radius_and_is_one_without_ground():
    heights = np.array([-1.0, 0.0, 0.01, 0.25 * R, 0.5 * R, 0.6 * R, math.inf])
    ratio = thrust_ratio(heights, R)
    assert np.isfinite(ratio).all()
    np.testing.assert_allclose(ratio[:5], MAX_THRUST_RATIO)
    assert pytest.approx(4 / 3) == MAX_THRUST_RATIO
    assert ratio[5] == pytest.approx(cheeseman_bennett(0.6)) and ratio[5] < MAX_THRUST_RATIO
    assert ratio[6] == 1.0


def test_no_nan_in_ground_effect_from_below_the_ground_to_far_above():
    n = 64
    rng = np.random.default_rng(5)
    state = _level_at(list(rng.uniform(-2.0, 50.0, n)))
    q = rng.normal(size=(n, 4))
    state[:, L.QUAT] = q / np.linalg.norm(q, axis=1, keepdims=True)
    fleet = Fleet(n, dt=0.01)
    fleet.set_ground_effect(True)
    fleet.reset(state)
    for _ in range(100):
        fleet.step(rng.uniform(0, 400, (n, 4)))
        assert np.isfinite(fleet.state).all()


def test_bad_ground_effect_values_are_refused_in_one_line():
    fleet = Fleet(2)
    for bad in (1, "yes", None, 0.5):
        with pytest.raises(ValueError, match="ground effect must be True or False") as error:
            fleet.set_ground_effect(bad)  # type: ignore[arg-type]
        assert "\n" not in str(error.value)
    with pytest.raises(ValueError, match="mask must have shape"):
        fleet.set_ground_effect(True, mask=[True])
