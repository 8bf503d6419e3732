"""A simulator process's start: the backend, and the tests' own simulators
(tests/conftest.py: wait_until_listening), wait as long as a live simulator takes to
open its links (a loaded machine stretches imports and kernel loads past any fixed
deadline), then for its heartbeats; a simulator that dies while starting is named. The
demo (gcs_tools/demo.py) likewise waits for its simulator's heartbeat while it lives."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import threading

import gymnasium as gym
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from gcs_tools import demo
from gcs_tools.client import ClientError, VehicleClient
from quadsitl.envs import mavlink_backend
from quadsitl.envs.sim_process import SimProcess, udp_port_bound
from quadsitl.wire.dialect import mavlink
from tests import conftest
from tests.conftest import cli, free_udp_port, socket_addresses, wait_until_listening

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


# --- the tests' own simulators -----------------------------------------------------------
def _stalled(words: str) -> tuple[subprocess.Popen[str], threading.Timer]:
    """``quadsitl sim WORDS`` stopped (SIGSTOP) as soon as it is started, and the timer
    that lets it go STALL s later, as a machine too busy to run it would."""
    process = subprocess.Popen(
        cli(f"sim --logs none {words}"), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    os.kill(process.pid, signal.SIGSTOP)
    resume = threading.Timer(STALL, os.kill, (process.pid, signal.SIGCONT))
    resume.start()
    return process, resume


@pytest.mark.parametrize("link", ["udpin", "udpout"])
def test_a_stalled_simulator_is_waited_for_until_its_link_is_open_then_it_answers(link):
    """udpin: until its port is bound; udpout (no port it binds can be named): until it
    has bound a UDP socket of its own. Its heartbeat then comes within a short wait."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as station:
        station.bind(("127.0.0.1", 0))
        station.settimeout(10)
        if link == "udpin":
            port = free_udp_port()
            process, resume = _stalled(f"--gcs udpin:127.0.0.1:{port} --api none")
        else:
            url = f"udpout:127.0.0.1:{station.getsockname()[1]}"
            process, resume = _stalled(f"--gcs {url} --api none")
        try:
            wait_until_listening(process, *([port] if link == "udpin" else []))
            assert process.poll() is None
            assert socket_addresses(process.pid, ("udp",))  # its link, bound
            if link == "udpin":  # it answers a station it has heard from
                assert udp_port_bound(port)
                encoder = mavlink.MAVLink(None, srcSystem=250, srcComponent=190)
                beat = encoder.heartbeat_encode(mavlink.MAV_TYPE_GCS, 8, 0, 0, 0)
                station.sendto(beat.pack(encoder), ("127.0.0.1", port))
            parser = mavlink.MAVLink(None)
            while not any(
                m.get_type() == "HEARTBEAT" for m in parser.parse_buffer(station.recv(65535)) or []
            ):
                pass  # telemetry before the heartbeat (each recv waits up to 10 s)
        finally:
            resume.cancel()
            process.kill()
            process.communicate(timeout=30)


def test_a_simulator_that_exits_while_starting_fails_at_once_with_its_error():
    process = subprocess.Popen(
        cli("sim --logs none --airframe no-such-airframe"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    with pytest.raises(pytest.fail.Exception, match=r"(?s)exited with code 2 .*unknown airframe"):
        wait_until_listening(process, free_udp_port())


def test_a_simulator_that_never_opens_its_link_is_killed_and_fails(monkeypatch):
    monkeypatch.setattr(conftest, "START_LIMIT", 1.0)
    port = free_udp_port()
    process = subprocess.Popen(
        cli(f"sim --logs none --gcs udpin:127.0.0.1:{port} --api none"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    os.kill(process.pid, signal.SIGSTOP)  # hung
    with pytest.raises(pytest.fail.Exception, match="did not open its links within 1 s"):
        wait_until_listening(process, port)
    assert process.returncode == -signal.SIGKILL


# --- the demo's simulator (gcs_tools/demo.py) ------------------------------------------
def test_the_demo_waits_for_a_simulator_slower_to_start_than_its_heartbeat_wait(monkeypatch):
    # Before, the demo gave up after 30 s without a heartbeat ("no heartbeat from system
    # 1"), though the simulator was alive, compiling: here 0.5 s against a 3 s stall.
    monkeypatch.setattr(demo, "HEARD_WITHIN", 0.5)
    port = free_udp_port()
    client = VehicleClient(f"udpin:127.0.0.1:{port}")
    process, resume = _stalled(f"--api udpout:127.0.0.1:{port} --gcs none --speed 4")
    try:
        demo.connect_while_starting(client, process)
        assert client.latest["HEARTBEAT"] is not None
    finally:
        resume.cancel()
        client.close()
        conftest.stop_process(process)


def test_the_demo_names_a_simulator_that_ends_while_starting():
    client = VehicleClient(f"udpin:127.0.0.1:{free_udp_port()}")
    process = subprocess.Popen(
        cli("sim --logs none --airframe no-such-airframe"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        with pytest.raises(ClientError, match=r"ended while starting \(exit code 2\)"):
            demo.connect_while_starting(client, process, limit=120)
    finally:
        client.close()
        conftest.stop_process(process)
