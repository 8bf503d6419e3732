"""The task envs, every id of the task list: checkers, seeding, vector equivalence, rewards
and outcomes."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quadsitl  # noqa: F401  (registers the ids)
from quadsitl.physics import PAPER
from quadsitl.physics import layout as L
from quadsitl.registration import ENV_IDS
from quadsitl.tasks import features as F

IDS = list(ENV_IDS.values())
pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_check_env(env_id):
    check_env(gym.make(env_id).unwrapped, skip_render_check=True)


@pytest.mark.parametrize("env_id", IDS)
def test_sb3_check_env(env_id):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    sb3_check_env(gym.make(env_id).unwrapped, warn=False)


def _rollout(env, seed: int, actions: np.ndarray):
    obs, _ = env.reset(seed=seed)
    trace = [obs]
    for a in actions:
        obs, reward, terminated, truncated, _info = env.step(a)
        trace.append(np.r_[obs, reward, terminated, truncated])
        if terminated or truncated:
            break
    return np.concatenate(trace)


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_same_episode(env_id):
    actions = np.random.default_rng(5).normal(0, 1.0, (60, 4))
    first = _rollout(gym.make(env_id), 7, actions)
    second = _rollout(gym.make(env_id), 7, actions)
    np.testing.assert_array_equal(first, second)
    if env_id not in ("QuadSITL/Hover-v0", "QuadSITL/StaticWaypoint-v0"):  # random starts
        assert not np.array_equal(first[:34], _rollout(gym.make(env_id), 8, actions)[:34])


@pytest.mark.parametrize("env_id", IDS)
def test_vector_env_equals_n_single_envs_exactly(env_id):
    n, steps, seed = 4, 70, 11
    options = {"episode_seconds": 0.75, "init_position_noise": 0.3, "init_attitude_noise": 0.2}
    vec = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **options)
    singles = [gym.make(env_id, **options) for _ in range(n)]
    actions = np.random.default_rng(3).normal(0, 1.5, (steps, n, 4)).astype(np.float32)
    obs, _ = vec.reset(seed=seed)
    single_obs = [env.reset(seed=seed + i)[0] for i, env in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack(single_obs))
    needs_reset = [False] * n
    episodes_ended = 0
    for t in range(steps):
        obs, reward, terminated, truncated, info = vec.step(actions[t])
        for i, env in enumerate(singles):
            if needs_reset[i]:  # NEXT_STEP autoreset: this step is the reset
                expected_obs, _ = env.reset()
                expected = (expected_obs, 0.0, False, False)
                needs_reset[i] = False
            else:
                o, r, te, tr, single_info = env.step(actions[t, i])
                expected = (o, r, te, tr)
                if te or tr:
                    needs_reset[i] = True
                    episodes_ended += 1
                    assert info["_outcome"][i]
                    assert info["outcome"][i] == single_info["outcome"]
                    assert info["episode_return"][i] == single_info["episode_return"]
            np.testing.assert_array_equal(obs[i], expected[0])
            assert reward[i] == expected[1]
            assert (terminated[i], truncated[i]) == expected[2:]
    assert episodes_ended >= n  # autoreset was exercised


def test_first_reward_after_reset_has_no_carry_over():
    env = gym.make("QuadSITL/Hover-v0")
    env.reset(seed=0)
    for _ in range(30):  # drift far from the goal
        env.step(np.array([1.0, 1.0, 1.0, 1.0]))
    env.reset(seed=0)
    _, reward, *_ = env.step(np.zeros(4))
    fresh = gym.make("QuadSITL/Hover-v0")
    fresh.reset(seed=0)
    _, fresh_reward, *_ = fresh.step(np.zeros(4))
    assert reward == fresh_reward
    assert reward == pytest.approx(10.0, abs=1e-6)  # at the goal, hover thrust: time term only


def test_rotor_slots_mean_the_same_at_reset_and_after_a_step():
    env = gym.make("QuadSITL/Hover-v0")
    obs, _ = env.reset(seed=0)
    hover_fraction = PAPER.hover_rotor_speed / PAPER.max_rotor_speed  # ≈ 0.707
    np.testing.assert_allclose(obs[F.OBS_ROTORS], hover_fraction, rtol=1e-6)
    obs, *_ = env.step(np.zeros(4))
    np.testing.assert_allclose(obs[F.OBS_ROTORS], hover_fraction, rtol=1e-6)
    obs, *_ = env.step(np.full(4, 100.0))  # clipped to Ω_max, approached through motor lag
    assert np.all(obs[F.OBS_ROTORS] > hover_fraction)
    assert np.all(obs[F.OBS_ROTORS] <= 1.0)


def _episode_return(env, policy, seed=0):
    obs, _ = env.reset(seed=seed)
    total = 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        total += reward
        if terminated or truncated:
            return total, info


def test_hover_thrust_earns_positive_return_and_random_actions_fall():
    env = gym.make("QuadSITL/Hover-v0")
    hold, info = _episode_return(env, lambda obs: np.zeros(4))
    assert hold == pytest.approx(1000.0, rel=1e-3)
    assert info["success"] and info["outcome"] == "timed_out"
    rng = np.random.default_rng(0)
    random_returns, outcomes = [], []
    for seed in range(5):
        total, info = _episode_return(env, lambda obs: rng.normal(0, 3.0, 4), seed)
        random_returns.append(total)
        outcomes.append(info["outcome"])
    assert max(random_returns) < 0.5 * hold
    assert any(o in ("out_of_bounds", "flipped") for o in outcomes)


def _descent_policy(rate: float):
    """Level vertical descent at ``rate`` m/s: equal rotor speeds from a P loop on v_z."""

    def policy(obs):
        vz_world = obs[F.OBS_BODY_VEL][2]  # level flight: body z = world z
        accel = 3.0 * (-rate - vz_world)
        omega = np.sqrt(PAPER.mass * (PAPER.gravity + accel) / (4 * PAPER.thrust_coeff))
        return np.full(4, (omega - PAPER.hover_rotor_speed) / 35.0)

    return policy


def _land(policy, roll: float = 0.0):
    env = gym.make("QuadSITL/Land-v0")
    env.reset(seed=1)
    engine = env.unwrapped.engine
    engine.fleet.state[0, 0:2] = 0.2  # over the pad
    if roll:
        engine.fleet.state[0, L.QUAT] = [np.cos(roll / 2), np.sin(roll / 2), 0, 0]
    obs = engine.obs[0]
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        if terminated or truncated:
            return reward, info


def test_slow_vertical_descent_onto_the_pad_lands():
    reward, info = _land(_descent_policy(0.7))  # 0.5 m/s would need all of the 6 s
    assert info["outcome"] == "landed" and info["success"]
    assert info["touchdown_speed"] == pytest.approx(0.7, abs=0.1)
    assert reward > 400


def test_touchdown_faster_than_the_airframe_allows_crashes():
    reward, info = _land(_descent_policy(1.5))  # above 1 m/s, below the vortex-ring 2 m/s
    assert info["outcome"] == "crashed" and info["crashed"] and not info["success"]
    assert info["touchdown_speed"] == pytest.approx(1.5, abs=0.1)  # it did touch down,
    assert info["final_distance"] == pytest.approx(np.hypot(0.2, 0.2), abs=0.02)  # on the pad
    assert reward < -400


def test_falling_faster_than_2_m_s_crashes_in_the_air():
    reward, info = _land(lambda obs: np.full(4, -6.0))  # rotors nearly off: falls
    assert info["outcome"] == "crashed" and not info["success"]
    assert np.isnan(info["touchdown_speed"]) and info["final_distance"] > 2.0  # in the air
    assert reward < -400


def test_tilted_touchdown_crashes():
    tilt = np.radians(25)  # rotor discs reach the ground first
    _reward, info = _land(lambda obs: np.full(4, -0.3), roll=tilt)
    assert info["outcome"] == "crashed" and info["crashed"]


def test_target_moves_at_about_one_metre_per_second():
    env = gym.make("QuadSITL/TargetFollow-v0")
    env.reset(seed=3)
    positions = []
    for _ in range(200):
        obs, *_ = env.step(np.zeros(4))
        positions.append(env.unwrapped.engine.goal[0, 0:3].copy())
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1) / 0.05
    assert steps.mean() == pytest.approx(1.0, rel=0.1)
    assert np.abs(np.array(positions)).max() <= 2.0 + 1e-9
    np.testing.assert_allclose(obs[37], np.linalg.norm(obs[34:37]), rtol=1e-5)


def test_random_waypoint_goal_is_drawn_from_wherever_the_episode_starts():
    """1 to 2.5 m from the start in every direction, for starts spread over a 3 m box:
    the goal moves with the start (drawn around the origin it would be up to 5 m away)."""
    env = gym.make("QuadSITL/RandomWaypoint-v0", init_position_noise=1.5)
    starts, offsets = [], []
    for seed in range(200):
        env.reset(seed=seed)
        engine = env.unwrapped.engine
        start = engine.fleet.state[0, L.POS].copy()
        starts.append(start)
        offsets.append(engine.goal[0, 0:3] - start)
    starts, offsets = np.array(starts), np.array(offsets)
    assert np.abs(starts).max() <= 1.5 and np.abs(starts).max(axis=0).min() > 1.2
    distances = np.linalg.norm(offsets, axis=1)
    assert distances.min() >= 1.0 - 1e-9 and distances.max() <= 2.5 + 1e-9
    assert (offsets[:, 2] > 0).mean() == pytest.approx(0.5, abs=0.1)  # up as often as down
    # Without start noise the task is the paper's: from the origin.
    env = gym.make("QuadSITL/RandomWaypoint-v0")
    env.reset(seed=0)
    np.testing.assert_array_equal(env.unwrapped.engine.fleet.state[0, L.POS], 0.0)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_actions_raise(bad):
    env = gym.make("QuadSITL/Hover-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="not finite"):
        env.step(np.array([0.0, bad, 0.0, 0.0]))
    vec = gym.make_vec("QuadSITL/Hover-v0", num_envs=3, vectorization_mode="vector_entry_point")
    vec.reset(seed=0)
    actions = np.zeros((3, 4))
    actions[2, 0] = bad
    with pytest.raises(ValueError, match="env 2 is not finite"):
        vec.step(actions)


def test_wrong_action_shape_and_unknown_options_raise():
    env = gym.make("QuadSITL/Hover-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError, match=r"unknown task option.*'episode_lenght'"):
        gym.make("QuadSITL/Hover-v0", episode_lenght=3)
    with pytest.raises(ValueError, match="cannot randomise 'colour'"):
        gym.make("QuadSITL/Hover-v0", param_randomization={"colour": 0.1})
    with pytest.raises(ValueError, match="whole number"):
        gym.make("QuadSITL/Hover-v0", control_period=0.025, physics_dt=0.01)
    with pytest.raises(ValueError, match="unknown airframe"):
        gym.make("QuadSITL/Hover-v0", airframe="bogus")


def test_options_change_the_episode():
    env = gym.make(
        "QuadSITL/Hover-v0",
        episode_seconds=1.0,
        init_position_noise=0.5,
        airframe="paper-x",
        param_randomization={"mass": 0.2},
    )
    obs, _ = env.reset(seed=0)
    assert np.abs(obs[F.OBS_POS]).max() > 0.01  # the start was randomised
    masses = set()
    for seed in range(5):
        env.reset(seed=seed)
        masses.add(env.unwrapped.engine.fleet.params[0, L.P_MASS])
    assert len(masses) == 5 and all(0.52 <= m <= 0.78 for m in masses)
    length = 0
    while True:
        *_, terminated, truncated, _ = env.step(np.zeros(4))
        length += 1
        if terminated or truncated:
            break
    assert length <= 20
    # The X airframe is the one flown: rotor 1 (front right) alone rolls and pitches it
    # about as much; on the plus airframe (rotor 1 in front) it only pitches it.
    rotor_1 = np.array([2.0, 0.0, 0.0, 0.0])
    env.reset(seed=0)
    roll, pitch, _ = env.step(rotor_1)[0][F.OBS_RATES]  # rad/s, body
    assert roll < -0.05 and pitch < -0.05 and roll == pytest.approx(pitch, rel=0.05)
    plus = gym.make("QuadSITL/Hover-v0")
    plus.reset(seed=0)
    roll, pitch, _ = plus.step(rotor_1)[0][F.OBS_RATES]
    assert abs(roll) < 1e-3 and pitch < -0.05


@pytest.mark.parametrize("delay", [None, {"observation": 0.02, "action": 0.0}])
def test_observe_position_false_zeroes_the_position_slots_and_nothing_else(delay):
    """The same flight, step for step; only the absolute position is hidden (also in a
    delayed observation, and in the last observation of an episode and the first of the
    next)."""
    common = {"init_position_noise": 1.5, "delay": delay}
    shown = gym.make_vec(
        "QuadSITL/RandomWaypoint-v0", num_envs=3, vectorization_mode="vector_entry_point", **common
    )
    hidden = gym.make_vec(
        "QuadSITL/RandomWaypoint-v0",
        num_envs=3,
        vectorization_mode="vector_entry_point",
        observe_position=False,
        **common,
    )
    a, _ = shown.reset(seed=4)
    b, _ = hidden.reset(seed=4)
    rng = np.random.default_rng(0)
    ended = False
    for _ in range(80):  # past the 3.5 s (70-step) episodes
        assert np.abs(a[:, F.OBS_POS]).max() > 0.05 and not b[:, F.OBS_POS].any()
        np.testing.assert_array_equal(b[:, 3:], a[:, 3:])
        action = rng.normal(0.0, 0.1, (3, 4))
        a, ra, *_ = shown.step(action)
        b, rb, terminated, truncated, _ = hidden.step(action)
        np.testing.assert_array_equal(rb, ra)  # rewards read the truth
        ended |= bool((terminated | truncated).any())  # its last observation is checked next
    assert ended
    with pytest.raises(ValueError, match="observe_position must be True or False"):
        gym.make("QuadSITL/RandomWaypoint-v0", observe_position="no")


def test_sb3_adapter_semantics_and_ppo_trains(tmp_path):
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import configure

    from quadsitl.envs.sb3 import QuadSB3VecEnv

    venv = QuadSB3VecEnv("hover", num_envs=8, seed=0, episode_seconds=0.5)
    obs = venv.reset()
    assert obs.shape == (8, 34)
    for _ in range(10):
        obs, _reward, done, infos = venv.step(np.zeros((8, 4), np.float32))
        if done.any():
            break
    assert done.all()  # 10 steps of 0.05 s: every episode timed out together
    assert all(info["TimeLimit.truncated"] for info in infos)
    assert infos[0]["terminal_observation"].shape == (34,)
    assert infos[0]["episode_metrics"]["outcome"] == "timed_out"
    np.testing.assert_array_equal(obs, venv.reset())  # reset in the same step, same seeds
    model = PPO(
        "MlpPolicy",
        QuadSB3VecEnv("hover", num_envs=8, seed=1),
        n_steps=32,
        batch_size=64,
        seed=0,
        device="cpu",
    )
    model.set_logger(configure(str(tmp_path), []))  # SB3's default is a new folder in /tmp
    model.learn(total_timesteps=512)
    assert model.num_timesteps >= 512
