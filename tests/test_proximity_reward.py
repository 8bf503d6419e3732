"""The task option proximity_reward: every step also earns w·max(0, 1 − d/r) for its
distance d to the goal, on top of the task's own reward, in the env's rewards and in each
episode's return; the flight itself is the same."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from tests.conftest import vector_env

# Radii that a random flight from each task's start both enters and stays out of.
RADIUS = {"Hover": 0.3, "RandomWaypoint": 2.0, "Land": 3.0}


@pytest.mark.parametrize("task", ["Hover", "RandomWaypoint", "Land"])
def test_each_step_earns_the_closeness_to_the_goal(task):
    """The same flight with and without the option: the rewards differ by exactly
    w·max(0, 1 − d/r) for the distance d from the vehicle to its goal after the step,
    the flights not at all, and the returns reported at each episode's end by the sum of
    those. Near and far steps both occur."""
    common = {"init_position_noise": 0.3, "episode_seconds": 1.0}
    proximity = {"weight": 15.0, "radius": RADIUS[task]}
    plain = vector_env(task, **common)
    rewarded = vector_env(task, proximity_reward=proximity, **common)
    a, _ = plain.reset(seed=5)
    b, _ = rewarded.reset(seed=5)
    engine = rewarded.unwrapped.engine  # type: ignore[attr-defined]
    rng = np.random.default_rng(1)
    paid = np.zeros(3)
    ends = near = far = 0
    for _ in range(45):  # 2 episodes of 20 steps and a bit
        action = rng.normal(0.0, 0.3, (3, 4))
        a, r_plain, term_a, _, info_a = plain.step(action)
        b, r_pen, term_b, trunc_b, info_b = rewarded.step(action)
        # The compiled evaluate's own distance column, checked against the state where
        # the episode goes on; an ended one is already reset, its info has the distance.
        ended = term_b | trunc_b
        live = ~ended
        distance = engine.dist[:, 0].copy()
        if ended.any():
            distance[ended] = info_b["final_info"]["final_distance"][ended]
        state, goal = engine.fleet.state, engine.goal
        expected = np.linalg.norm(goal[live, :3] - state[live, :3], axis=1)
        np.testing.assert_allclose(distance[live], expected, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(a, b)  # the penalty changes no flight
        np.testing.assert_array_equal(term_a, term_b)
        assert distance.min() > 0.0
        earned = proximity["weight"] * np.maximum(0.0, 1.0 - distance / proximity["radius"])
        np.testing.assert_allclose(r_pen - r_plain, earned, rtol=1e-9, atol=1e-9)
        near += int((distance < proximity["radius"]).sum())
        far += int((distance > proximity["radius"]).sum())
        paid += earned
        if ended.any():
            ends += int(ended.sum())
            np.testing.assert_allclose(
                info_b["final_info"]["episode_return"][ended]
                - info_a["final_info"]["episode_return"][ended],
                paid[ended],
                rtol=1e-9,
            )
            paid[ended] = 0.0
    assert ends >= 3 and near > 0 and far > 0


def test_none_is_the_papers_reward():
    """The default, None, leaves every reward as the task's own."""
    assert gym.make("QuadSITL/Hover-v0").unwrapped.engine.options.proximity_reward is None
    plain = vector_env("Hover", init_position_noise=0.3)
    zero = vector_env("Hover", init_position_noise=0.3, proximity_reward=None)
    plain.reset(seed=2)
    zero.reset(seed=2)
    action = np.full((3, 4), 0.2)
    for _ in range(5):
        np.testing.assert_array_equal(plain.step(action)[1], zero.step(action)[1])


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (15.0, "must be None or a dict"),
        ({"weight": 15.0}, "must be None or a dict"),
        ({"weight": 15.0, "radius": 0.5, "power": 2}, "must be None or a dict"),
        ({"weight": -1.0, "radius": 0.5}, r"weight must be in \(0, 1000\]"),
        ({"weight": math.nan, "radius": 0.5}, r"weight must be in \(0, 1000\]"),
        ({"weight": True, "radius": 0.5}, r"weight must be in \(0, 1000\]"),
        ({"weight": 15.0, "radius": 0.0}, r"radius must be in \(0, 100\] m"),
        ({"weight": 15.0, "radius": math.inf}, r"radius must be in \(0, 100\] m"),
        ({"weight": 15.0, "radius": "0.5"}, r"radius must be in \(0, 100\] m"),
    ],
)
def test_a_malformed_option_is_refused_in_one_line(value, message):
    with pytest.raises(ValueError, match=message):
        gym.make("QuadSITL/Hover-v0", proximity_reward=value)
