"""The envs' ``sensor_noise`` option: policies observe their state as the sensors would,
rewards and endings stay the truth's, a vector env sees what single envs see."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.physics.sensors import GpsParams
from quadsitl.tasks import features as F


def _episode(noise: float, steps: int = 40, seed: int = 4):
    env = gym.make("QuadSITL/Hover-v0", sensor_noise=noise)
    obs, _ = env.reset(seed=seed)
    observations, rewards = [obs], []
    actions = np.random.default_rng(0).normal(0, 0.05, (steps, 4)).astype(np.float32)
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        assert not (terminated or truncated)
    env.close()
    return np.array(observations), np.array(rewards)


def test_noisy_observations_keep_the_true_rewards_and_carry_the_sensor_noise():
    exact, exact_rewards = _episode(0.0)
    noisy, noisy_rewards = _episode(1.0)
    np.testing.assert_array_equal(noisy_rewards, exact_rewards)  # the truth flies
    error = noisy - exact
    assert np.abs(error).max() > 0
    np.testing.assert_array_equal(error[:, F.OBS_ROTORS], 0.0)  # not a sensor's
    position = error[:, F.OBS_POS]
    gps = GpsParams()
    assert 0.2 * gps.horizontal_sigma < np.std(position[:, :2]) < 3 * gps.horizontal_sigma
    np.testing.assert_allclose(error[:, F.OBS_GOAL_POS], -position, atol=1e-5)
    assert 0 < np.std(error[:, F.OBS_RATES]) < 0.02  # rad/s: the gyroscope's σ ≈ 0.003
    tilt = np.arcsin(np.clip(noisy[:, F.OBS_SIN], -1, 1)) - np.arcsin(exact[:, F.OBS_SIN])
    assert 0.1 < math.degrees(np.std(tilt)) < 2.0  # 0.5° attitude error
    louder, _ = _episode(3.0)
    assert np.std(louder[:, F.OBS_POS] - exact[:, F.OBS_POS]) > 2 * np.std(position)


def test_vector_env_with_sensor_noise_sees_what_single_envs_see():
    seeds = [11, 12, 13]
    vec = gym.make_vec(
        "QuadSITL/Hover-v0", num_envs=3, vectorization_mode="vector_entry_point", sensor_noise=1.0
    )
    singles = [gym.make("QuadSITL/Hover-v0", sensor_noise=1.0) for _ in seeds]
    vec_obs, _ = vec.reset(seed=seeds)
    single_obs = [env.reset(seed=s)[0] for env, s in zip(singles, seeds, strict=True)]
    np.testing.assert_allclose(vec_obs, np.array(single_obs), atol=1e-6)
    rng = np.random.default_rng(1)
    for _ in range(30):
        actions = rng.normal(0, 0.3, (3, 4)).astype(np.float32)
        vec_obs, *_ = vec.step(actions)
        single_obs = [env.step(a)[0] for env, a in zip(singles, actions, strict=True)]
        np.testing.assert_allclose(vec_obs, np.array(single_obs), atol=1e-6)
    vec.close()
    for env in singles:
        env.close()


@pytest.mark.parametrize("bad", [-1.0, math.nan, math.inf, "loud", True])
def test_bad_sensor_noise_is_a_one_line_error(bad):
    with pytest.raises(ValueError, match="sensor_noise") as caught:
        gym.make("QuadSITL/Hover-v0", sensor_noise=bad)
    assert "\n" not in str(caught.value)


def test_noisy_observations_are_delayed_like_exact_ones():
    """``sensor_noise`` with an observation delay of two control periods: each noisy
    observation is that of the state two steps earlier (its rotor speeds exactly, its
    position within the GPS noise), the rewards are those of the undelayed env, and a
    second run on the same seed repeats it."""

    def run(**options):
        env = gym.make("QuadSITL/Hover-v0", **options)
        obs, _ = env.reset(seed=7)
        out, rewards = [obs], []
        for action in np.random.default_rng(1).normal(0, 0.05, (30, 4)).astype(np.float32):
            obs, reward, *_ = env.step(action)
            out.append(obs)
            rewards.append(reward)
        env.close()
        return np.array(out), np.array(rewards)

    delay = {"observation": 0.1, "action": 0.0}  # two control periods of 0.05 s
    exact, exact_rewards = run()
    noisy, noisy_rewards = run(sensor_noise=1.0, delay=delay)
    again, _ = run(sensor_noise=1.0, delay=delay)
    np.testing.assert_array_equal(noisy, again)
    np.testing.assert_array_equal(noisy_rewards, exact_rewards)
    # The rotor speeds are not a sensor's: exactly those of two steps earlier.
    np.testing.assert_array_equal(noisy[3:, F.OBS_ROTORS], exact[1:-2, F.OBS_ROTORS])
    position_error = noisy[3:, F.OBS_POS] - exact[1:-2, F.OBS_POS]  # vs 2 steps earlier
    assert 0 < np.abs(position_error).max() < 5 * GpsParams().horizontal_sigma
