"""The figure-eight task, added as docs/tasks.md says a task is added: its module and
its name in the task list. Everything else (the gym id, the env classes, the vector env,
the docstring, the evaluators' tables) must follow from those two."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quadsitl  # noqa: F401  (registers the ids)
from quadsitl.flight_software.controller import CascadedController, Setpoint
from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.tasks import figure_eight as FE
from tests.conftest import step_as_singles

ENV_ID = "QuadSITL/FigureEight-v0"
pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def test_it_registers_and_passes_gymnasiums_checker():
    env = gym.make(ENV_ID)
    assert type(env.unwrapped).__name__ == "FigureEightEnv"
    assert env.observation_space.shape == (41,)  # target following's observation
    check_env(env.unwrapped, skip_render_check=True)
    doc = type(env.unwrapped).__doc__
    assert doc.startswith(f"# {ENV_ID}") and f"within {FE.TRACK_RADIUS:g} m" in doc


def test_derived_tables_know_it():
    from policies.config import FAST_STEPS, STARTS, make_config
    from policies.evaluate import TASK_METRICS, success_rule

    assert TASK_METRICS["figure_eight"][0] == "time_within_threshold"
    assert STARTS["figure_eight"] == {"init_attitude_noise": 0.1}
    assert make_config("figure_eight", "ppo", "fast").total_steps == FAST_STEPS["figure_eight"]
    assert success_rule("figure_eight").startswith("timed_out")


def test_the_point_flies_a_closed_figure_eight_at_under_one_metre_per_second():
    env = gym.make(ENV_ID)
    env.reset(seed=4)
    engine = env.unwrapped.engine
    points = [engine.goal[0, 0:3].copy()]
    for _ in range(engine.max_steps - 1):
        env.step(np.zeros(4))
        points.append(engine.goal[0, 0:3].copy())
    points = np.array(points)
    speeds = np.linalg.norm(np.diff(points, axis=0), axis=1) / 0.05
    assert speeds.mean() > 0.3 and speeds.max() <= FE.MAX_SPEED + 1e-6 < 1.0
    assert np.allclose(points[:, 2], 0.0)  # level
    assert np.linalg.norm(points, axis=1).max() <= FE.AMPLITUDE * math.hypot(1, 0.5)
    # It crosses itself at the origin half-way and closes the lap at the end.
    half = len(points) // 2
    assert np.linalg.norm(points[half]) < 1e-9 and np.linalg.norm(points[-1]) < 0.1
    # Its two lobes lie on either side of the crossing.
    lobes = points[1:half].mean(axis=0), points[half + 1 :].mean(axis=0)
    assert np.dot(*lobes) < 0


def test_the_heading_is_drawn_per_episode_from_the_seed():
    env = gym.make(ENV_ID)
    headings = []
    for seed in (0, 1, 0):
        env.reset(seed=seed)
        env.step(np.zeros(4))
        headings.append(env.unwrapped.engine.goal[0, 0:2].copy())
    np.testing.assert_array_equal(headings[0], headings[2])
    assert not np.allclose(headings[0], headings[1])


def test_vector_env_equals_single_envs():
    """Step for step, while no episode ends (tests/test_envs.py also checks autoreset
    for every id in the task list, this one included)."""
    vector = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point")
    assert type(vector.unwrapped).__name__ == "FigureEightVectorEnv"
    singles = [gym.make(ENV_ID) for _ in range(3)]
    actions = np.random.default_rng(0).normal(0.0, 0.05, (40, 3, 4)).astype(np.float32)
    step_as_singles(vector, singles, 7, actions)


def _fly(track: bool, seed: int = 2) -> tuple[float, dict]:
    """An episode under the cascaded controller: at the moving point (its position and
    velocity as the setpoint) or holding the origin. Returns (return, final info)."""
    env = gym.make(ENV_ID)
    env.reset(seed=seed)
    engine = env.unwrapped.engine
    controller = CascadedController(PAPER)
    total = 0.0
    while True:
        goal = engine.goal[0]
        setpoint = (
            Setpoint(position=goal[0:3].copy(), velocity=goal[3:6].copy(), yaw=0.0)
            if track
            else Setpoint(position=np.zeros(3), yaw=0.0)
        )
        omega = controller.rotor_command(engine.fleet.state[0], setpoint, engine.control_period)
        action = (omega - PAPER.hover_rotor_speed) / engine.options.beta
        _, reward, terminated, truncated, info = env.step(action.astype(np.float32))
        total += reward
        if terminated or truncated:
            return total, info


def test_tracking_the_point_scores_better_than_staying_still():
    tracked, info = _fly(track=True)
    still, still_info = _fly(track=False)
    assert info["outcome"] == still_info["outcome"] == "timed_out"
    assert info["success"] and not still_info["success"]
    assert info["time_within_threshold"] >= FE.TRACK_FRACTION * FE.EPISODE_SECONDS
    assert tracked > still + 500  # the bonus of ≥ 100 more steps within range


def test_leaving_the_region_ends_the_episode_with_a_penalty():
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    env.unwrapped.engine.fleet.state[0, L.I_PZ] = FE.BOUND_BOX + 0.5
    _, reward, terminated, _, info = env.step(np.zeros(4, np.float32))
    assert terminated and info["outcome"] == "out_of_bounds" and not info["success"]
    assert reward < -FE.EXIT_PENALTY / 2
