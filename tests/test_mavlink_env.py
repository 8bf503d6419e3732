"""The Gymnasium envs with backend="mavlink": parity with the in-process physics for
every task, the env checker, faults (a killed simulator, a busy port), no orphans."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.envs.parallel import mavlink_vector_env
from quadsitl.lockstep_client.motor_client import SimulatorError
from quadsitl.registration import ENV_IDS
from quadsitl.wire.dialect import mavlink
from tests.conftest import OBS_TOLERANCE, REWARD_TOLERANCE, fly_both


def _episode(env: gym.Env, seed: int, actions: np.ndarray) -> tuple[list, list, list, dict]:
    obs, _ = env.reset(seed=seed)
    observations, rewards, ends = [obs], [], []
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        rewards.append(reward)
        ends.append((terminated, truncated))
        if terminated or truncated:
            return observations, rewards, ends, info
    raise AssertionError("episode longer than the actions given")


@pytest.mark.parametrize("name", sorted(ENV_IDS))
def test_parity_with_in_process_env_over_whole_episodes(name):
    env_id = ENV_IDS[name]
    local = gym.make(env_id, init_position_noise=0.2, init_attitude_noise=0.1)
    remote = gym.make(env_id, backend="mavlink", init_position_noise=0.2, init_attitude_noise=0.1)
    try:
        rng = np.random.default_rng(7)
        actions = rng.normal(0.0, 0.05, (600, 4)).astype(np.float32)
        for seed in (1, 2):
            a = _episode(local, seed, actions)
            b = _episode(remote, seed, actions)
            assert len(a[1]) == len(b[1]) > 10
            np.testing.assert_allclose(np.array(b[0]), np.array(a[0]), atol=OBS_TOLERANCE)
            np.testing.assert_allclose(b[1], a[1], atol=REWARD_TOLERANCE)
            assert a[2] == b[2]
            assert a[3]["outcome"] == b[3]["outcome"]
    finally:
        local.close()
        remote.close()


def test_env_checker_passes():
    env = gym.make("QuadSITL/Land-v0", backend="mavlink")
    try:
        check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()


def test_killed_simulator_raises_and_reset_restarts_it():
    env = gym.make("QuadSITL/Hover-v0", backend="mavlink", timeout=1.0)
    try:
        env.reset(seed=0)
        env.step(np.zeros(4, np.float32))
        process = env.unwrapped.backend.processes[0]
        process.process.kill()
        # The death is named as such (not taken for a slow simulator's silence).
        with pytest.raises(SimulatorError, match="exited with code"):
            env.step(np.zeros(4, np.float32))
        with pytest.warns(RuntimeWarning, match="starting new ones"):
            env.reset(seed=0)
        assert env.unwrapped.backend.processes[0] is not process
        env.step(np.zeros(4, np.float32))
    finally:
        env.close()


def test_close_leaves_nothing_running_and_releases_the_port():
    env = gym.make("QuadSITL/Hover-v0", backend="mavlink")
    env.reset(seed=0)
    sim = env.unwrapped.backend.processes[0]
    port = sim.port
    env.close()
    assert sim.process.poll() is not None
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", port))  # free again


def test_busy_ground_station_port_gives_a_clear_error():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        url = f"udpin:127.0.0.1:{busy.getsockname()[1]}"
        with pytest.raises(SimulatorError, match="Address already in use"):
            gym.make("QuadSITL/Hover-v0", backend="mavlink", gcs=url)


def test_ground_station_watches_a_training_run():
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    listener.settimeout(0.1)
    url = f"udpout:127.0.0.1:{listener.getsockname()[1]}"
    env = gym.make("QuadSITL/Hover-v0", backend="mavlink", gcs=url)
    parser = mavlink.MAVLink(None)
    seen: set[str] = set()
    try:
        env.reset(seed=0)
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and not {"HEARTBEAT", "ATTITUDE"} <= seen:
            _, _, terminated, truncated, _ = env.step(np.zeros(4, np.float32))
            if terminated or truncated:
                env.reset()
            try:
                data = listener.recv(65535)
            except TimeoutError:
                continue
            seen |= {m.get_type() for m in parser.parse_buffer(data) or []}
    finally:
        env.close()
        listener.close()
    assert {"HEARTBEAT", "ATTITUDE"} <= seen


def test_vector_env_over_two_processes_and_no_orphans():
    before = set(_live_simulators())  # simulators of anyone else on this machine
    envs = mavlink_vector_env("QuadSITL/Hover-v0", 2)
    try:
        obs, _ = envs.reset(seed=[1, 2])
        assert obs.shape == (2, 34)
        for _ in range(150):  # past an autoreset (100-step episodes)
            obs, reward, *_ = envs.step(np.zeros((2, 4), np.float32))
        assert np.isfinite(obs).all() and np.isfinite(reward).all()
    finally:
        envs.close()
    deadline = time.monotonic() + 5  # the workers' simulators stop as the workers exit
    while time.monotonic() < deadline and set(_live_simulators()) - before:
        time.sleep(0.1)
    assert not set(_live_simulators()) - before


def test_a_killed_parent_takes_its_simulator_down():
    code = (
        "import gymnasium as gym, quadsitl, sys, time\n"
        "env = gym.make('QuadSITL/Hover-v0', backend='mavlink')\n"
        "print(env.unwrapped.backend.processes[0].process.pid, flush=True)\n"
        "time.sleep(60)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    sim_pid = int(parent.stdout.readline())
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and _running(sim_pid):
        time.sleep(0.1)
    assert not _running(sim_pid)


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _live_simulators() -> list[int]:
    """Live ``quadsitl.cli sim`` processes started by this test process (its children:
    another test run on the same machine has simulators of its own)."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/cmdline", "rb") as f:
                cmdline = f.read().split(b"\0")
            with open(f"/proc/{entry}/stat") as f:
                parent = int(f.read().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if parent != os.getpid():
            continue
        if b"quadsitl.cli" in cmdline and b"sim" in cmdline and _running(int(entry)):
            found.append(int(entry))
    return found


def test_native_vector_env_over_two_simulators_matches_in_process():
    kwargs = {"init_position_noise": 0.3}
    local = gym.make_vec("QuadSITL/RandomWaypoint-v0", 2, "vector_entry_point", **kwargs)
    remote = gym.make_vec(
        "QuadSITL/RandomWaypoint-v0", 2, "vector_entry_point", backend="mavlink", **kwargs
    )
    try:
        assert len(remote.unwrapped.backend.processes) == 2
        a, _ = local.reset(seed=4)
        b, _ = remote.reset(seed=4)
        np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
        rng = np.random.default_rng(1)
        fly_both(local, remote, rng, 160, 0.05)  # through episode ends and autoresets
    finally:
        local.close()
        remote.close()


@pytest.mark.parametrize(
    ("task", "fleet"),
    [("Land", {"vehicles_per_sim": 3}), ("TargetFollow", {"simulators": 2})],
)
def test_fleets_in_one_process_match_in_process_through_autoresets(task, fleet):
    """Five envs as a fleet of 3 + 2 vehicles (or 3 + 2 over two processes): the same
    observations, rewards and endings as in-process, through episode ends."""
    kwargs = {"init_position_noise": 0.3, "init_attitude_noise": 0.1}
    env_id = f"QuadSITL/{task}-v0"
    local = gym.make_vec(env_id, 5, "vector_entry_point", **kwargs)
    remote = gym.make_vec(env_id, 5, "vector_entry_point", backend="mavlink", **fleet, **kwargs)
    try:
        assert remote.unwrapped.backend.sizes == [3, 2]
        assert len(remote.unwrapped.backend.processes) == 2
        a, _ = local.reset(seed=11)
        b, _ = remote.reset(seed=11)
        np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
        rng = np.random.default_rng(3)
        ended = fly_both(local, remote, rng, 150, 0.3)
        assert ended >= 5  # the comparison went through autoresets
    finally:
        local.close()
        remote.close()


def test_fleet_options_are_checked():
    for bad, match in (
        ({"vehicles_per_sim": 0}, "vehicles_per_sim must be a positive integer"),
        ({"simulators": 9}, "9 simulators for 4 envs"),
        ({"simulators": 2, "vehicles_per_sim": 2}, "not both"),
        ({"system_id": 252, "vehicles_per_sim": 4}, "must lie in 1..254"),
    ):
        with pytest.raises(ValueError, match=match):
            gym.make_vec("QuadSITL/Hover-v0", 4, "vector_entry_point", backend="mavlink", **bad)


def test_backend_options_are_checked():
    with pytest.raises(ValueError, match="unknown backend"):
        gym.make("QuadSITL/Hover-v0", backend="gazebo")
    with pytest.raises(ValueError, match="need backend='mavlink'"):
        gym.make("QuadSITL/Hover-v0", gcs="udpout:127.0.0.1:14550")
    with pytest.raises(ValueError, match="steps whole control periods"):
        gym.make("QuadSITL/Hover-v0", backend="mavlink", delay={"action": 0.01})
