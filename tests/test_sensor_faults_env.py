"""Sensor faults as an env option: what the policy observes of a failed sensor holds,
the vehicle (and the reward, which reads the truth) flies on; each episode starts
healthy; bad faults are refused in one line."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.tasks import features as F

PERIOD = 0.01  # s, the tasks' control period


def fly(env, steps: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Observations of ``steps`` random steps (large actions: the vehicle moves)."""
    seen = []
    for _ in range(steps):
        obs, *_ = env.step(rng.uniform(-1, 1, 4).astype(np.float32) * 40)
        seen.append(obs.copy())
    return seen


@pytest.mark.parametrize(
    ("sensor", "held", "free"),
    [
        ("gps", [0, 1], [2]),  # x, y held; z (the barometer's) still moves
        ("baro", [2], [0, 1]),
        ("gyro", list(range(F.OBS_RATES.start, F.OBS_RATES.stop)), [0, 1, 2]),
    ],
)
def test_a_failed_sensor_holds_what_the_policy_sees_while_the_vehicle_flies_on(sensor, held, free):
    at = 0.2
    env = gym.make("QuadSITL/Hover-v0", faults={"sensor": sensor, "at": at})
    engine = env.unwrapped.engine
    env.reset(seed=3)
    seen = np.array(fly(env, 40, np.random.default_rng(0)))
    first = round(at / PERIOD)  # index of the first failed step's observation
    assert np.ptp(seen[first:, held], axis=0).max() == 0.0  # stuck
    assert np.ptp(seen[:first, held], axis=0).min() > 0.0  # moved before
    assert np.ptp(seen[first:, free], axis=0).min() > 0.0  # the others still move
    truth = engine.fleet.state[0, :3]
    assert not np.allclose(seen[-1, F.OBS_POS], truth) or sensor == "gyro"
    env.reset(seed=4)  # a new episode: healthy again
    again = np.array(fly(env, 10, np.random.default_rng(1)))
    assert np.ptp(again[:, held], axis=0).min() > 0.0
    env.close()


def test_a_stuck_magnetometer_holds_the_heading_only():
    env = gym.make("QuadSITL/Hover-v0", faults={"sensor": "mag", "mode": "off", "at": 0.0})
    env.reset(seed=0)
    seen = np.array(fly(env, 30, np.random.default_rng(2)))
    yaw_sin = F.OBS_SIN.start + 2
    roll_sin = F.OBS_SIN.start
    assert np.ptp(seen[:, yaw_sin]) == 0.0
    assert np.ptp(seen[:, roll_sin]) > 0.0
    env.close()


def test_the_reward_reads_the_truth_not_the_stuck_sensor():
    """Two envs flying the same actions from the same seed: one with its GPS stuck from
    the start sees a frozen position but earns the same rewards."""
    actions = np.random.default_rng(5).uniform(-1, 1, (30, 4)).astype(np.float32) * 30
    rewards = []
    for faults in (None, {"sensor": "gps"}):
        env = gym.make("QuadSITL/Hover-v0", faults=faults)
        env.reset(seed=7)
        rewards.append([env.step(a)[1] for a in actions])
        env.close()
    assert rewards[0] == rewards[1]


@pytest.mark.parametrize(
    ("faults", "says"),
    [
        ({"sensor": "lidar"}, "'sensor' must be one of"),
        ({"sensor": "gps", "mode": "broken"}, "'mode' must be one of"),
        ({"sensor": "gps", "at": -1.0}, "'at' must be a time"),
        ({"sensor": "gps", "efficiency": 0.5}, "a sensor fault may have"),
    ],
)
def test_bad_sensor_faults_are_refused_in_one_line(faults, says):
    with pytest.raises(ValueError, match=says) as error:
        gym.make("QuadSITL/Hover-v0", faults=faults)
    assert "\n" not in str(error.value)
