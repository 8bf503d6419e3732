"""The RL ecosystem's conventions: Stable-Baselines3's ``make_vec_env`` one-liner on every
id, ``render_mode="rgb_array"`` frames, and the ``-v1`` ids (actions normalised to
[-1, 1] over the same physics, the task's evaluation start by default) beside an
unchanged ``-v0``."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv

import quadsitl  # noqa: F401  (registers the ids)
from quadsitl.registration import ENV_IDS
from quadsitl.tasks import TASKS
from tests.conftest import OBS_TOLERANCE, REWARD_TOLERANCE, step_as_singles

V0_IDS = list(ENV_IDS.values())
V1_IDS = [env_id.replace("-v0", "-v1") for env_id in V0_IDS]
TASK_OF = {env_id: task for env_id, task in zip(V1_IDS, TASKS.values(), strict=True)}
SYMMETRIC_BOX_ADVICE = "symmetric and normalized Box"
EPISODES = 20
pytestmark = pytest.mark.filterwarnings("ignore:.*Box observation space")


def _render_warnings(caught: list[warnings.WarningMessage]) -> list[str]:
    return [str(w.message) for w in caught if "render" in str(w.message).lower()]


def test_the_canonical_one_liner_with_eight_envs():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        vec = make_vec_env("QuadSITL/Hover-v0", n_envs=8)
    try:
        assert isinstance(vec, DummyVecEnv)
        assert _render_warnings(caught) == []
        obs = vec.reset()
        assert obs.shape == (8, 34)
        for _ in range(5):
            obs, reward, done, _infos = vec.step(np.zeros((8, 4), np.float32))
        assert reward.shape == done.shape == (8,) and np.isfinite(reward).all()
    finally:
        vec.close()


@pytest.mark.parametrize("env_id", V0_IDS + V1_IDS)
def test_make_vec_env_one_liner_on_every_id(env_id):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        vec = make_vec_env(env_id, n_envs=2, seed=0)
    try:
        assert _render_warnings(caught) == []
        assert vec.render_mode == "rgb_array"
        obs = vec.reset()
        for _ in range(3):
            actions = np.stack([vec.action_space.sample() for _ in range(2)])
            obs, reward, _done, _infos = vec.step(actions)
        assert obs.shape == (2, *vec.observation_space.shape)
        assert np.isfinite(obs).all() and np.isfinite(reward).all()
        frames = vec.get_images()
        assert len(frames) == 2 and all(f.dtype == np.uint8 and f.ndim == 3 for f in frames)
    finally:
        vec.close()


def test_rgb_array_frames_show_the_flight():
    env = gym.make("QuadSITL/Hover-v1", render_mode="rgb_array")
    env.reset(seed=1)
    first = env.render()
    assert isinstance(first, np.ndarray) and first.dtype == np.uint8
    assert first.ndim == 3 and first.shape[2] == 3 and min(first.shape[:2]) >= 200
    for _ in range(15):  # rotors at half speed: it falls
        env.step(np.zeros(4, np.float32))
    later = env.render()
    assert later.shape == first.shape and not np.array_equal(later, first)
    assert env.metadata["render_fps"] == 20  # one frame per 0.05 s step
    env.close()


def test_human_mode_is_gymnasiums_window_over_the_frames():
    env = gym.make("QuadSITL/Hover-v1", render_mode="human")  # pygame draws on reset
    assert env.render_mode == "human" and env.unwrapped.render_mode == "rgb_array"


def test_the_drawn_vehicle_is_where_the_vehicle_is():
    from quadsitl.viz import raster

    def vehicle_columns(east: float) -> float:
        env = gym.make("QuadSITL/Hover-v0", render_mode="rgb_array").unwrapped
        env.reset(seed=0)
        env.engine.fleet.state[0, 0] = east
        frame = env.render()
        top = frame[: raster.PANEL, : raster.PANEL]
        drawn = np.all(top == raster.ROTOR, axis=-1)
        env.close()
        return float(np.nonzero(drawn)[1].mean())

    shift = vehicle_columns(1.0) - vehicle_columns(-1.0)
    assert shift == pytest.approx(2.0 * raster.PX_PER_M, abs=1.0)


@pytest.mark.parametrize("env_id", V1_IDS)
def test_v1_spaces_pass_both_checkers_without_the_box_advice(env_id):
    env = gym.make(env_id, render_mode="rgb_array")
    space = env.action_space
    assert isinstance(space, gym.spaces.Box) and space.dtype == np.float32
    assert space.shape == (4,)
    np.testing.assert_array_equal(space.low, -np.ones(4, np.float32))
    np.testing.assert_array_equal(space.high, np.ones(4, np.float32))
    assert env.observation_space == gym.make(env_id.replace("-v1", "-v0")).observation_space
    check_env(env.unwrapped)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(gym.make(env_id, render_mode="rgb_array").unwrapped, warn=True)
    assert not [w for w in caught if SYMMETRIC_BOX_ADVICE in str(w.message)]


def test_v0_keeps_the_paper_action_and_start():
    for env_id in V0_IDS:
        env = gym.make(env_id).unwrapped
        assert env.action_space.low[0] == np.float32(env.engine.action_low) < -1
        assert env.action_space.high[0] == np.float32(env.engine.action_high) > 1
        assert env.engine.options.init_position_noise == 0.0
        assert env.engine.options.init_attitude_noise == 0.0


@pytest.mark.parametrize("env_id", V1_IDS)
def test_v1_defaults_are_the_evaluation_start_and_options_override_them(env_id):
    task = TASK_OF[env_id]
    options = gym.make(env_id).unwrapped.engine.options
    assert task.train_start
    for name, value in task.train_start.items():
        assert getattr(options, name) == value
    quiet = gym.make(env_id, init_attitude_noise=0.0).unwrapped.engine.options
    assert quiet.init_attitude_noise == 0.0


def _successes(env: gym.Env, action: np.ndarray) -> int:
    wins = 0
    for seed in range(EPISODES):
        env.reset(seed=seed)
        while True:
            _obs, _reward, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                wins += bool(info["success"])
                break
    return wins


def test_zero_action_no_longer_succeeds_from_the_default_start():
    v0, v1 = gym.make("QuadSITL/Hover-v0"), gym.make("QuadSITL/Hover-v1")
    assert _successes(v0, np.zeros(4, np.float32)) == EPISODES  # v0 unchanged
    assert _successes(v1, np.zeros(4, np.float32)) <= EPISODES // 4
    # Nor does holding hover speed (v0's zero action, as a v1 action).
    low, high = v1.unwrapped.engine.action_low, v1.unwrapped.engine.action_high
    hover = np.full(4, (low + high) / (low - high), np.float32)
    assert _successes(v1, hover) <= EPISODES // 4


def test_v1_bounds_map_onto_v0_bounds_exactly():
    env = gym.make("QuadSITL/Hover-v1").unwrapped
    engine = env.engine
    for action, bound in ((-1.0, engine.action_low), (1.0, engine.action_high)):
        env.reset(seed=0)
        env.step(np.full(4, action, np.float32))
        assert (engine.action == bound).all()
    env.step(np.full(4, 5.0, np.float32))  # beyond the box: clipped as v0 clips
    assert (engine.action == engine.action_high).all()


@pytest.mark.parametrize("env_id", ["QuadSITL/Hover-v1", "QuadSITL/TargetFollow-v1"])
def test_v1_is_v0_with_the_mapped_action(env_id):
    v1 = gym.make(env_id)
    task = TASK_OF[env_id]
    v0 = gym.make(env_id.replace("-v1", "-v0"), **task.train_start)
    low, high = v1.unwrapped.engine.action_low, v1.unwrapped.engine.action_high
    actions = np.random.default_rng(2).uniform(-1, 1, (40, 4)).astype(np.float32)
    a, _ = v1.reset(seed=3)
    b, _ = v0.reset(seed=3)
    np.testing.assert_array_equal(a, b)
    for action in actions:
        x = action.astype(np.float64)
        raw = ((1.0 - x) * low + (1.0 + x) * high) / 2.0
        a, ra, ta, ua, _ = v1.step(action)
        b, rb, tb, ub, _ = v0.step(raw)
        np.testing.assert_array_equal(a, b)
        assert (ra, ta, ua) == (rb, tb, ub)
        if ta or ua:
            break


def test_v1_vector_env_equals_single_envs():
    n, seed = 3, 5
    vec = gym.make_vec("QuadSITL/Hover-v1", num_envs=n, vectorization_mode="vector_entry_point")
    singles = [gym.make("QuadSITL/Hover-v1") for _ in range(n)]
    assert vec.single_action_space == singles[0].action_space
    # about hover speed (0.41): no episode ends
    actions = np.random.default_rng(0).uniform(0.3, 0.5, (10, n, 4)).astype(np.float32)
    step_as_singles(vec, singles, seed, actions)
    vec.close()


def test_v1_through_the_wire_matches_in_process():
    local = gym.make("QuadSITL/Hover-v1")
    remote = gym.make("QuadSITL/Hover-v1", backend="mavlink")
    try:
        assert remote.action_space == local.action_space
        a, _ = local.reset(seed=4)
        b, _ = remote.reset(seed=4)
        np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
        for action in np.random.default_rng(1).uniform(-0.2, 0.2, (10, 4)).astype(np.float32):
            a, ra, *_ = local.step(action)
            b, rb, *_ = remote.step(action)
            np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
            assert rb == pytest.approx(ra, abs=REWARD_TOLERANCE)
    finally:
        local.close()
        remote.close()


def test_sb3_adapter_of_v1():
    from quadsitl.envs.sb3 import QuadSB3VecEnv

    vec = QuadSB3VecEnv("hover", num_envs=2, seed=0, version=1)
    assert vec.action_space == gym.make("QuadSITL/Hover-v1").action_space
    assert (
        vec.engine.options.init_position_noise
        == TASK_OF["QuadSITL/Hover-v1"].train_start["init_position_noise"]
    )
    vec.reset()
    obs, reward, _done, _infos = vec.step(np.zeros((2, 4), np.float32))
    assert obs.shape == (2, 34) and np.isfinite(reward).all()
    vec.close()
    with pytest.raises(ValueError, match="version must be one of"):
        QuadSB3VecEnv("hover", version=2)


def test_the_trainers_fly_v0_without_gymnasiums_upgrade_notice():
    from policies.rollout import make_vector_env

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = make_vector_env("hover", 2)
    env.close()
    assert env.single_action_space.low[0] < -1  # v0, as the shipped checkpoints
    assert not [w for w in caught if "out of date" in str(w.message)]
