"""N autopilots on one batched physics behind one vector env, against the in-repository
fake PX4: each env flies its own setpoints on its own clock, one dead autopilot never
holds the others, and both of Gymnasium's autoreset modes keep their promises."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from quadsitl.envs.offboard_vector import OffboardVectorEnv
from quadsitl.physics import layout as L
from tests.conftest import free_px4_instances

pytestmark = pytest.mark.xdist_group("offboard")
N = 3


@pytest.fixture
def make_vector():
    made: list[OffboardVectorEnv] = []

    def make(n: int = N, **kwargs) -> OffboardVectorEnv:
        env = OffboardVectorEnv(n, first_instance=free_px4_instances(n), **kwargs)
        made.append(env)
        return env

    yield make
    for env in made:
        env.close()


def test_each_env_flies_its_own_setpoint_on_its_own_autopilot(make_vector):
    env = make_vector(task="hover", action_level="velocity", episode_seconds=30.0)
    obs, info = env.reset(seed=10)
    assert obs.shape == (N, env.single_observation_space.shape[0])
    assert env.observation_space.contains(obs)
    assert all(r["reached"] and r["restarted"] is None for r in info["reset"])  # new ones
    processes = [pilot.process for pilot in env.offboard.autopilots.pilots]
    assert len({p.pid for p in processes}) == N
    actions = np.zeros((N, 4), np.float32)
    actions[:, 0] = [0.5, 0.0, -0.5]  # east at 1 m/s, hold, west at 1 m/s
    autopilots = env.offboard.autopilots
    before = [autopilots.time_us(row) for row in range(N)]  # each settled in its own time
    for _ in range(50):  # a simulated second
        obs, _, terminated, truncated, _ = env.step(actions)
        assert not (terminated.any() or truncated.any())
    velocity_east = autopilots.fleet.state[:, L.I_VX]
    assert velocity_east[0] > 0.4 and abs(velocity_east[1]) < 0.2 and velocity_east[2] < -0.4
    flown = [autopilots.time_us(row) - before[row] for row in range(N)]
    assert flown == [1_000_000] * N  # each a fixed span of simulated time per step


def test_a_dead_autopilot_is_reported_restarted_and_never_holds_the_others(make_vector):
    env = make_vector(task="hover", action_level="velocity", episode_seconds=30.0)
    env.reset(seed=20)
    autopilots = env.offboard.autopilots
    dead = autopilots.pilots[1].process
    dead.kill()
    dead.wait()
    before = [autopilots.time_us(row) for row in range(N)]
    _, reward, terminated, truncated, info = env.step(np.zeros((N, 4), np.float32))
    assert truncated.tolist() == [False, True, False] and not terminated.any()
    assert info["_autopilot_failure"].tolist() == [False, True, False]
    assert "exited" in info["autopilot_failure"][1]
    after = [autopilots.time_us(row) for row in range(N)]
    assert after[0] - before[0] == after[2] - before[2] == 20_000  # they flew on
    # NEXT_STEP: the next step resets env 1 with a new autopilot, the others step
    _, reward, terminated, truncated, info = env.step(np.zeros((N, 4), np.float32))
    assert autopilots.pilots[1].process is not dead and autopilots.pilots[1].process.poll() is None
    report = env.fleet.reports[1]
    assert "exited" in report["restarted"] and report["reached"]
    assert reward[1] == 0.0 and not truncated.any()
    _, _, terminated, truncated, info = env.step(np.zeros((N, 4), np.float32))
    assert not (terminated.any() or truncated.any()) and "autopilot_failure" not in info


def test_same_step_autoreset_returns_the_last_observation_and_the_episode(make_vector):
    env = make_vector(
        n=2, task="hover", action_level="velocity", episode_seconds=0.2,
        autoreset_mode=AutoresetMode.SAME_STEP,
    )  # fmt: skip
    env.reset(seed=30)
    for _ in range(9):
        _, _, terminated, truncated, info = env.step(np.zeros((2, 4), np.float32))
        assert not (terminated.any() or truncated.any())
    obs, _, _, truncated, info = env.step(np.zeros((2, 4), np.float32))  # the 10th: 0.2 s
    assert truncated.all()
    assert info["_final_obs"].all() and info["final_obs"].shape == obs.shape
    assert not np.allclose(info["final_obs"], obs)  # the new episodes' first observations
    assert info["final_info"]["_success"].all()
    assert all(r["restarted"] is None and r["reached"] for r in env.fleet.reports)


def test_a_seeded_reset_is_reproducible_and_seeds_env_i_with_s_plus_i(make_vector):
    env = make_vector(n=2, task="hover", action_level="velocity", init_position_noise=0.3)
    first, _ = env.reset(seed=40)
    again, info = env.reset(seed=40)
    assert all(r["restarted"].startswith("seeded") for r in info["reset"])
    assert np.array_equal(first, again)
    assert not np.allclose(first[0], first[1])  # env 1 drew with seed 41
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full((2, 4), np.nan))
