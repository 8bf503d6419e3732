"""A simulator process's start: the backend waits as long as a live simulator takes to
open its link (a loaded machine stretches imports and kernel loads past any fixed
deadline), then for its heartbeats; a simulator that dies while starting is named."""

from __future__ import annotations

import os
import signal
import socket
import threading

import gymnasium as gym
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.envs import mavlink_backend
from quadsitl.envs.sim_process import SimProcess, udp_port_bound

STALL = 3.0  # s a simulator is held stopped right after it is started


def test_a_bound_udp_port_is_seen_and_a_free_one_is_not():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
        assert udp_port_bound(port) is True
    assert udp_port_bound(port) is False


class StalledAtStart(SimProcess):
    """A simulator stopped (SIGSTOP) as soon as it is started and let go STALL s later,
    as a machine too busy to run it would."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        os.kill(self.process.pid, signal.SIGSTOP)
        self.resume = threading.Timer(STALL, os.kill, (self.process.pid, signal.SIGCONT))
        self.resume.start()


def test_a_simulator_slower_to_start_than_the_start_timeout_is_still_connected(monkeypatch):
    # Before, the start had START_TIMEOUT in all: here 1 s against a 3 s stall.
    monkeypatch.setattr(mavlink_backend, "START_TIMEOUT", 1.0)
    monkeypatch.setattr(mavlink_backend, "SimProcess", StalledAtStart)
    env = gym.make("QuadSITL/Hover-v0", backend="mavlink", timeout=1.0)
    try:
        obs, _ = env.reset(seed=0)
        obs, *_ = env.step(np.zeros(4, np.float32))
        assert np.all(np.isfinite(obs))
    finally:
        env.close()


class DiesAtStart(SimProcess):
    def __init__(self, args, *rest, **kwargs) -> None:
        super().__init__([*args, "--airframe", "no-such-airframe"], *rest, **kwargs)


def test_a_simulator_that_dies_while_starting_is_named(monkeypatch):
    monkeypatch.setattr(mavlink_backend, "SimProcess", DiesAtStart)
    with pytest.raises(mavlink_backend.SimulatorError, match="quadsitl sim exited with code"):
        gym.make("QuadSITL/Hover-v0", backend="mavlink")
