"""Flight-stack envs on Ray: a two-node Ray cluster on this machine (a head that takes no
work, and a second node); each actor owns an OffboardVectorEnv with its fake PX4s on the
second node. They fly as the same envs do in this process, a lost actor is a clear error,
and the next reset places a new one."""

from __future__ import annotations

import numpy as np
import pytest

from quadsitl.envs.autopilot_link import AutopilotError
from quadsitl.envs.offboard_vector import OffboardVectorEnv
from quadsitl.envs.ray_offboard import concat_infos
from tests.conftest import free_ardupilot_instances, free_px4_instances

ray = pytest.importorskip("ray")

pytestmark = pytest.mark.xdist_group("ray")  # one Ray at a time (Makefile)


def test_vector_infos_of_groups_are_joined_end_to_end_with_blanks_where_one_lacks_a_key():
    first = {"reset": [{"a": 1}], "outcome": np.array(["x"], dtype=object),
             "_outcome": np.array([True]), "final_info": {"r": np.array([1.5])}}  # fmt: skip
    second = {"reset": [{"a": 2}, {"a": 3}]}
    joined = concat_infos([first, second], [1, 2])
    assert joined["reset"] == [{"a": 1}, {"a": 2}, {"a": 3}]
    assert joined["outcome"].tolist() == ["x", None, None]
    assert joined["_outcome"].tolist() == [True, False, False]
    assert joined["final_info"]["r"].tolist() == [1.5, 0.0, 0.0]


def test_flight_stack_envs_on_the_second_node_fly_as_here_and_survive_a_lost_actor(two_ray_nodes):
    from quadsitl.envs.ray_offboard import RayOffboardVectorEnv

    _, worker = two_ray_nodes
    options = {"init_position_noise": 0.3, "sensor_noise": 0.0}
    here = OffboardVectorEnv(2, "hover", "velocity", first_instance=free_px4_instances(2),
                             **options)  # fmt: skip
    remote = RayOffboardVectorEnv(2, "hover", "velocity", first_instance=free_px4_instances(2),
                                  nodes=2, **options)  # fmt: skip
    try:
        assert set(remote.nodes) == {worker.node_id}  # the head takes no work
        a, _ = here.reset(seed=7)
        b, info_b = remote.reset(seed=7)
        assert len(info_b["reset"]) == 2 and all(r["reached"] for r in info_b["reset"])
        np.testing.assert_allclose(a, b, atol=1e-4)
        rng = np.random.default_rng(0)
        for _ in range(25):
            actions = rng.uniform(-0.3, 0.3, (2, 4)).astype(np.float32)
            a, reward_a, *_ = here.step(actions)
            b, reward_b, *_ = remote.step(actions)
            np.testing.assert_allclose(a, b, atol=1e-4)
            np.testing.assert_allclose(reward_a, reward_b, rtol=1e-5, atol=1e-6)
        ray.kill(remote.actors[1])
        with pytest.raises(AutopilotError, match=r"envs 1\.\.1 on Ray node .* were lost"):
            remote.step(np.zeros((2, 4), np.float32))
        b, _ = remote.reset()  # a new actor in the lost one's place
        assert b.shape == (2, here.single_observation_space.shape[0])
        b, *_ = remote.step(np.zeros((2, 4), np.float32))
        assert np.all(np.isfinite(b))
    finally:
        here.close()
        remote.close()


def test_arducopter_envs_fly_on_the_second_node(two_ray_nodes):
    from quadsitl.envs.ray_offboard import RayOffboardVectorEnv

    _, worker = two_ray_nodes
    remote = RayOffboardVectorEnv(2, "hover", "velocity", stack="ardupilot", nodes=1,
                                  first_instance=free_ardupilot_instances(2))  # fmt: skip
    try:
        assert remote.nodes == [worker.node_id]
        _, info = remote.reset(seed=3)
        assert all(r["reached"] for r in info["reset"]), info["reset"]
        before = [r["simulated_s"] for r in info["reset"]]
        obs, _, terminated, truncated, _ = remote.step(np.zeros((2, 4), np.float32))
        assert not (terminated.any() or truncated.any()) and np.all(np.isfinite(obs))
        assert all(s > 0 for s in before)  # each took off and flew to its start there
    finally:
        remote.close()


def test_a_training_run_through_the_flight_stack_on_ray_splits_its_envs_over_actors():
    from policies.config import flight_stack_options, make_config

    config = make_config("hover", "ppo", "fast", backend="px4", ray="local", num_envs=4,
                         vehicles_per_sim=2)  # fmt: skip
    options = flight_stack_options(config)
    assert options["ray"] == "local" and options["nodes"] == 2
    with pytest.raises(ValueError, match="must divide --num-envs"):
        make_config("hover", "ppo", "fast", backend="px4", ray="local", num_envs=4,
                    vehicles_per_sim=3)  # fmt: skip
    with pytest.raises(ValueError, match="needs backend 'mavlink', 'px4' or 'ardupilot'"):
        make_config("hover", "ppo", "fast", ray="local")
