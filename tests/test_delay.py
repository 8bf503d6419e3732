"""Observation and actuation delay of the task envs (the ``delay`` option).

Each delayed env is compared with an undelayed one flown on the same seed: delays of
whole control periods against the undelayed env's own steps, delays shorter than a
control period against an env stepping every physics step (control_period = physics_dt).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quadsitl  # noqa: F401  (registers the ids)
from quadsitl.registration import ENV_IDS

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")
SUBSTEPS = 5  # physics steps per control period (0.05 s / 0.01 s, the defaults)
SEED = 3


def _actions(steps: int, seed: int = 1) -> np.ndarray:
    return np.random.default_rng(seed).normal(0, 0.4, (steps, 4)).astype(np.float32)


def _observations(actions: np.ndarray, env_id: str = "QuadSITL/Hover-v0", **options) -> np.ndarray:
    """First observation and the observation after each action (episodes long enough
    not to end on the way; the checker stays off: these envs fly on after a flip)."""
    env = gym.make(env_id, disable_env_checker=True, episode_seconds=60.0, **options)
    trace = [env.reset(seed=SEED)[0]]
    for action in actions:
        trace.append(env.step(action)[0])
    return np.array(trace)


@pytest.mark.parametrize("env_id", ["QuadSITL/Hover-v0", "QuadSITL/TargetFollow-v0"])
def test_observation_delayed_by_k_periods_is_the_undelayed_one_k_steps_earlier(env_id):
    actions = _actions(30)
    plain = _observations(actions, env_id)
    for k in (1, 3):
        delayed = _observations(actions, env_id, delay={"observation": k * 0.05})
        np.testing.assert_array_equal(delayed[k:], plain[:-k])
        np.testing.assert_array_equal(delayed[:k], np.repeat(plain[:1], k, axis=0))


def test_actuation_delayed_by_k_periods_flies_the_actions_k_steps_later():
    actions = _actions(30)
    for k in (1, 2):
        delayed = _observations(actions, delay={"action": k * 0.05})
        hover_first = np.concatenate([np.zeros((k, 4), np.float32), actions[:-k]])
        np.testing.assert_array_equal(delayed, _observations(hover_first))


def test_delays_shorter_than_a_period_act_at_their_physics_step():
    """0.02 s = 2 physics steps: compared with an env that steps every physics step."""
    actions = _actions(20)
    per_physics_step = np.repeat(actions, SUBSTEPS, axis=0)
    fine = _observations(per_physics_step, control_period=0.01)
    observed = _observations(actions, delay={"observation": 0.02})
    ends = SUBSTEPS * np.arange(1, len(actions) + 1)
    np.testing.assert_array_equal(observed[1:], fine[ends - 2])
    shifted = np.concatenate([np.zeros((2, 4), np.float32), per_physics_step[:-2]])
    fine_late = _observations(shifted, control_period=0.01)
    actuated = _observations(actions, delay={"action": 0.02})
    np.testing.assert_array_equal(actuated, fine_late[::SUBSTEPS])
    # Both at once: 0.07 s of actuation (one period and two steps), 0.03 s of observation.
    shifted = np.concatenate([np.zeros((7, 4), np.float32), per_physics_step[:-7]])
    fine_both = _observations(shifted, control_period=0.01)
    both = _observations(actions, delay={"action": 0.07, "observation": 0.03})
    np.testing.assert_array_equal(both[1:], fine_both[ends - 3])


def test_rewards_and_endings_stay_those_of_the_true_state():
    actions = _actions(40)
    runs = []
    for delay in (None, {"observation": 0.15}):
        env = gym.make("QuadSITL/Hover-v0", delay=delay)
        env.reset(seed=SEED)
        runs.append([env.step(a)[1:4] for a in actions[:10]])
    assert runs[0] == runs[1]


@pytest.mark.parametrize("env_id", list(ENV_IDS.values()))
def test_gymnasium_check_env_with_drawn_delays(env_id):
    delay = {"observation": (0.0, 0.1), "action": (0.0, 0.06)}
    check_env(gym.make(env_id, delay=delay).unwrapped, skip_render_check=True)


def test_drawn_delays_repeat_with_the_seed_and_differ_per_env_of_a_vector_env():
    delay = {"observation": (0.0, 0.04), "action": (0.01, 0.03)}
    vec = gym.make_vec(
        "QuadSITL/Hover-v0", num_envs=64, vectorization_mode="vector_entry_point", delay=delay
    )
    vec.reset(seed=10)
    line = vec.unwrapped.engine.delay
    drawn = (line.observation_steps.copy(), line.action_steps.copy())
    assert set(drawn[0]) == {0, 1, 2, 3, 4} and set(drawn[1]) == {1, 2, 3}
    vec.reset(seed=10)
    np.testing.assert_array_equal(drawn[0], line.observation_steps)
    np.testing.assert_array_equal(drawn[1], line.action_steps)
    # Env i of the vector env is the single env seeded 10 + i, delays and all.
    actions = _actions(12)
    batch = np.repeat(actions[:, None, :], 64, axis=1)
    vec.reset(seed=10)
    trace = [vec.step(a)[0] for a in batch]
    for i in (0, 5, 63):
        env = gym.make("QuadSITL/Hover-v0", delay=delay, disable_env_checker=True)
        env.reset(seed=10 + i)
        single = [env.step(a)[0] for a in actions]
        np.testing.assert_array_equal(np.array(trace)[:, i], np.array(single))


def test_a_new_episode_starts_with_its_own_first_observation_and_the_hover_command():
    """Autoreset (SAME_STEP) refills the buffers: nothing of the last episode leaks."""
    vec = gym.make_vec(
        "QuadSITL/Hover-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        autoreset_mode="SameStep",
        episode_seconds=0.2,
        delay={"observation": 0.1, "action": 0.1},
    )
    vec.reset(seed=0)
    full = np.full((2, 4), 2.0, np.float32)
    for _ in range(4):  # one episode: 4 steps
        obs, _, _, truncated, info = vec.step(full)
    assert truncated.all()
    assert not np.array_equal(info["final_obs"], obs)
    first = obs.copy()
    for _ in range(2):  # the first two observations of the new episode are its start
        np.testing.assert_array_equal(vec.step(full)[0], first)
    env = gym.make("QuadSITL/Hover-v0", disable_env_checker=True)
    engine = vec.unwrapped.engine
    np.testing.assert_allclose(engine.fleet.state[:, 13:17], env.unwrapped.engine.hover_speed)


@pytest.mark.parametrize(
    ("delay", "message"),
    [
        ({"observation": 6.0}, r"observation delay 6 s is not shorter than the episode \(5 s\)"),
        ({"action": (0.0, 5.0)}, "action delay 5 s is not shorter than the episode"),
        ({"action": -0.01}, "must be finite seconds with 0 <= low <= high"),
        ({"observation": float("nan")}, "must be finite seconds"),
        ({"observation": (0.04, 0.02)}, "low <= high"),
        ({"observation": "20ms"}, "must be seconds or a"),
        ({"sensor": 0.02}, r"unknown delay kind\(s\) \['sensor'\]"),
        (0.02, "delay must be a dict"),
    ],
)
def test_bad_delays_are_refused_with_one_line(delay, message):
    with pytest.raises(ValueError, match=message) as error:
        gym.make("QuadSITL/Hover-v0", delay=delay)
    assert "\n" not in str(error.value)


def test_no_delay_is_the_plain_env():
    env = gym.make("QuadSITL/Hover-v0", delay={"observation": 0, "action": 0.0})
    assert env.unwrapped.engine.delay is None
    with pytest.raises(ValueError, match="backend='mavlink' steps whole control periods"):
        gym.make("QuadSITL/Hover-v0", backend="mavlink", delay={"action": 0.02})
