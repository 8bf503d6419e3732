"""Simulators as Ray actors: a two-node Ray cluster on this machine (a head that takes no
work and a second node), the envs' simulators placed on the second node, stepped over
UDP with the same results as in-process; a killed actor gives a clear error and reset
places a new one."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.lockstep_client.motor_client import SimulatorError
from tests.conftest import OBS_TOLERANCE, cli, fly_both

ray = pytest.importorskip("ray")

pytestmark = pytest.mark.xdist_group("ray")  # one Ray at a time (Makefile)


def test_simulators_on_the_second_node_fly_as_in_process_and_survive_a_lost_actor(two_ray_nodes):
    _, worker = two_ray_nodes
    kwargs = {"init_position_noise": 0.3}
    env_id = "QuadSITL/RandomWaypoint-v0"
    local = gym.make_vec(env_id, 4, "vector_entry_point", **kwargs)
    # A long timeout for the flights: a loaded machine running two Ray nodes on two cores
    # paused a first reset past 5 s (one core kept busy); the lost actor is waited for
    # with a short one below, so that it is found out quickly.
    wire = {"backend": "mavlink", "vehicles_per_sim": 2, "ray": True, "timeout": 30.0}
    remote = gym.make_vec(env_id, 4, "vector_entry_point", **wire, **kwargs)
    backend = remote.unwrapped.backend
    addresses = []
    try:
        assert len(backend.processes) == 2
        assert {sim.node_id for sim in backend.processes} == {worker.node_id}
        assert backend.signing_key is not None  # a network-facing simulator is signed
        a, _ = local.reset(seed=4)
        b, _ = remote.reset(seed=4)
        np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
        rng = np.random.default_rng(1)
        fly_both(local, remote, rng, 40, 0.05)

        lost = backend.processes[0]
        ray.kill(lost.actor)  # asynchronous: wait until its simulator has gone with it
        assert _released(lost.address)
        # Named as the actor's loss, not a hang or a timeout's silence.
        for client in backend.clients:
            client.timeout = 5.0
        with pytest.raises(SimulatorError, match="lost with its Ray actor"):
            remote.step(np.zeros((4, 4), np.float32))

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            a, _ = local.reset(seed=5)
            b, _ = remote.reset(seed=5)
        assert any("starting new ones" in str(w.message) for w in caught)
        assert lost not in backend.processes
        assert {sim.node_id for sim in backend.processes} == {worker.node_id}
        np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
        fly_both(local, remote, rng, 10, 0.05)
        addresses = [sim.address for sim in backend.processes]
    finally:
        local.close()
        remote.close()
    assert addresses and all(_released(address) for address in addresses)  # close stopped them


def _released(address: tuple[str, int], wait: float = 120.0) -> bool:
    """Whether the UDP port a simulator listened on is free again within ``wait`` s (a
    hang guard: a loaded machine is slow to end a process)."""
    deadline = time.monotonic() + wait
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            try:
                probe.bind(address)
                return True
            except OSError:
                if time.monotonic() > deadline:
                    return False
        time.sleep(0.1)


def test_ray_options_are_checked(two_ray_nodes):
    for bad, match in (
        ({"ray": ""}, "ray must be True or a Ray cluster address"),
        ({"ray": 3}, "ray must be True or a Ray cluster address"),
        ({"ray": True, "sim_address": ["127.0.0.1:9"]}, "not both"),
    ):
        with pytest.raises(ValueError, match=match):
            gym.make_vec("QuadSITL/Hover-v0", 1, "vector_entry_point", backend="mavlink", **bad)


@pytest.mark.slow  # a Ray of its own starts (15-30 s on two loaded cores)
def test_train_on_ray_starts_a_private_ray_despite_a_dead_clusters_address_file(tmp_path):
    # Ray's default ray.init() joins the cluster named in ray_current_cluster, even a
    # dead one (it hung); joining must be explicit: --ray ADDR or RAY_ADDRESS.
    folder = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # short: Ray's sockets go here
    Path(folder, "ray").mkdir()  # Ray's temporary folder is RAY_TMPDIR/ray
    Path(folder, "ray", "ray_current_cluster").write_text("127.0.0.1:9\n")  # nothing listens
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"} | {"RAY_TMPDIR": folder}
    tiny = "--num-envs 2 --vehicles-per-sim 2 --steps 64 --quiet --runs"
    try:
        done = subprocess.run(
            [
                *cli(f"train --task hover --algo ppo --preset fast --backend mavlink --ray {tiny}"),
                str(tmp_path),
            ],
            capture_output=True,
            text=True,
            timeout=240,
            env=env,
        )
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "quadsitl train: simulators on a private local Ray" in done.stderr, done.stderr
    assert (tmp_path / "hover-ppo-fast-seed0-mavlink" / "checkpoints" / "last.pt").is_file()
