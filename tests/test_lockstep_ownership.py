"""A lockstep simulator serves one client at a time and never runs out of step: a second
env is refused with the owner's address, a forger on the lockstep port changes nothing,
envs attach in turn to one running simulator, and after a stalled simulator the env
refuses to step until a reset puts it back in step (real processes, real sockets,
compared with the in-process env)."""

from __future__ import annotations

import os
import signal
import time

import gymnasium as gym
import numpy as np
import pytest
from pymavlink import mavutil

import quadsitl  # noqa: F401  (registers the envs)
from quadsitl.envs.sim_process import SimProcess
from quadsitl.lockstep_client.fleet_client import FleetClient
from quadsitl.lockstep_client.motor_client import SimulatorError
from quadsitl.simulator.ownership import Ownership
from quadsitl.simulator.runner import SimConfig
from quadsitl.wire.lockstep import OWNER_SILENCE, RESET_STATE, STAGE_MOTION
from tests.conftest import (
    OBS_TOLERANCE,
    REWARD_TOLERANCE,
    fly_both,
    refused_here,
    wait_until_listening,
)

RATES = ["--physics-rate", "100", "--control-rate", "20", "--gcs", "none", "--api", "none"]


def _started(vehicles: int) -> SimProcess:
    """A simulator of ``vehicles`` that is up (its link open, then a client has
    connected and closed, handing it back)."""
    sim = SimProcess(["--vehicles", str(vehicles), *RATES])
    wait_until_listening(sim.process, sim.port)
    probe = FleetClient("127.0.0.1", sim.port, vehicles)
    deadline = time.monotonic() + 90
    while True:
        try:
            probe.connect()
            break
        except SimulatorError:
            assert time.monotonic() < deadline and sim.alive, "the simulator did not start"
    probe.close()
    return sim


@pytest.fixture
def running_sim():
    sim = _started(1)
    yield sim
    sim.stop()


def _remote(sim: SimProcess, **options: object) -> gym.Env:
    options = {"timeout": 5.0, **options}
    return gym.make(
        "QuadSITL/Hover-v0",
        backend="mavlink",
        sim_address=f"127.0.0.1:{sim.port}",
        init_position_noise=0.3,
        **options,
    )


def _fly_both(local: gym.Env, remote: gym.Env, seed: int, steps: int) -> None:
    """The same seed and actions: the same observations and rewards at every step."""
    a, _ = local.reset(seed=seed)
    b, _ = remote.reset(seed=seed)
    np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        action = rng.normal(0, 0.1, 4).astype(np.float32)
        a, ra, ta, ua, _ = local.step(action)
        b, rb, tb, ub, _ = remote.step(action)
        np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
        assert abs(rb - ra) < REWARD_TOLERANCE and (ta, ua) == (tb, ub)
        if ta or ua:
            a, _ = local.reset(seed=seed)
            b, _ = remote.reset(seed=seed)


def test_three_envs_in_turn_on_one_running_simulator(running_sim):
    """Each env closes (handing the simulator back); the next attaches and flies the
    in-process flight from its very first reset and step."""
    local = gym.make("QuadSITL/Hover-v0", init_position_noise=0.3)
    try:
        for turn in range(3):
            remote = _remote(running_sim)
            try:
                _fly_both(local, remote, seed=turn, steps=20)
            finally:
                remote.close()
    finally:
        local.close()


def test_a_second_env_is_refused_with_the_owners_address(running_sim):
    local = gym.make("QuadSITL/Hover-v0", init_position_noise=0.3)
    first = _remote(running_sim)
    try:
        _fly_both(local, first, seed=1, steps=5)
        owner = first.unwrapped.backend.clients[0].sock.getsockname()
        # Told who owns it (a refusal), not timed out (which would say "no answer").
        with pytest.raises(SimulatorError, match=rf"lockstep in use by 127\.0\.0\.1:{owner[1]}"):
            _remote(running_sim, timeout=2.0)
        _fly_both(local, first, seed=2, steps=20)  # the owner flies on untouched
    finally:
        first.close()
        local.close()


def test_forged_resets_on_the_lockstep_port_change_nothing(running_sim):
    local = gym.make("QuadSITL/Hover-v0", init_position_noise=0.3)
    remote = _remote(running_sim)
    forger = mavutil.mavlink_connection(f"udpout:127.0.0.1:{running_sim.port}")
    try:
        a, _ = local.reset(seed=3)
        b, _ = remote.reset(seed=3)
        rng = np.random.default_rng(3)
        heard = []
        for _ in range(30):
            for command, params in ((STAGE_MOTION, [5.0] * 6 + [0.0]), (RESET_STATE, [9.0] * 7)):
                forger.mav.command_long_send(1, 1, command, 0, *params)
            action = rng.normal(0, 0.1, 4).astype(np.float32)
            a, *_ = local.step(action)
            b, *_ = remote.step(action)
            np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
            while (message := forger.recv_match(blocking=False)) is not None:
                heard.append(message)
        deadline = time.monotonic() + 2
        while not heard and time.monotonic() < deadline:
            message = forger.recv_match(blocking=True, timeout=0.1)
            heard += [message] if message is not None else []
        kinds = {m.get_type() for m in heard}
        assert "STATUSTEXT" in kinds and kinds <= {"STATUSTEXT"}, kinds  # told, nothing else
        assert any(m.text.startswith("lockstep in use by 127.0.0.1:") for m in heard)
    finally:
        forger.close()
        remote.close()
        local.close()


def test_after_a_stalled_simulator_the_env_refuses_to_step_until_reset_then_matches():
    """SIGSTOP past the timeout, SIGCONT: the simulator then applies the command the
    env gave up on. The env must not run one action behind: it refuses to step, and a
    reset puts both vehicles back in step with the in-process env."""
    sim = _started(2)
    local = gym.make_vec("QuadSITL/Hover-v0", 2, "vector_entry_point", init_position_noise=0.3)
    remote = gym.make_vec(
        "QuadSITL/Hover-v0",
        2,
        "vector_entry_point",
        backend="mavlink",
        sim_address=f"127.0.0.1:{sim.port}",
        vehicles_per_sim=2,
        timeout=10.0,  # the flights before and after the stall: a loaded machine's pauses
        init_position_noise=0.3,
    )
    pid = sim.process.pid
    clients = remote.unwrapped.backend.clients
    try:
        local.reset(seed=4)
        remote.reset(seed=4)
        rng = np.random.default_rng(4)
        fly_both(local, remote, rng, 10, 0.1)
        os.kill(pid, signal.SIGSTOP)
        try:
            for client in clients:  # the stall: past a short timeout
                client.timeout = 0.5
            with pytest.raises(SimulatorError, match="no state answer"):
                remote.step(np.zeros((2, 4), np.float32))
        finally:
            os.kill(pid, signal.SIGCONT)
            for client in clients:
                client.timeout = 10.0
        with pytest.raises(SimulatorError, match=r"call reset\(\)"):
            remote.step(np.zeros((2, 4), np.float32))
        a, _ = local.reset(seed=5)
        b, _ = remote.reset(seed=5)
        np.testing.assert_allclose(b, a, atol=OBS_TOLERANCE)
        fly_both(local, remote, rng, 40, 0.1)
    finally:
        remote.close()
        local.close()
        sim.stop()


def test_an_unsigned_lockstep_link_beyond_loopback_refuses_to_start():
    hil = "udpin:0.0.0.0:0"
    result = refused_here("sim", "--lockstep", "--hil", hil, "--gcs", "none", "--api", "none")
    assert result.returncode == 2
    assert "listens beyond this host" in result.stderr and "--signing-passphrase" in result.stderr
    assert "Traceback" not in result.stderr
    # With a key it is allowed; on loopback no key is needed.
    SimConfig(hil_url="udpin:0.0.0.0:4560", lockstep=True, signing_key=bytes(range(32))).validate()
    SimConfig(hil_url="udpin:127.0.0.1:4560", lockstep=True).validate()


def test_ownership_lapses_after_the_owners_silence_and_only_the_owner_releases():
    """The rule the simulator applies to every message on its motor link (wall times
    given, so the 10 s of silence need not be waited for)."""
    owner, other = ("127.0.0.1", 1000), ("127.0.0.1", 2000)
    link = Ownership()
    assert link.admit(other, "HEARTBEAT", 0.0) and link.owner is None  # hello takes nothing
    assert link.admit(owner, "COMMAND_LONG", 0.0) and link.owner == owner
    assert not link.admit(other, "COMMAND_LONG", 1.0)
    assert link.tell(other, 1.0) == "lockstep in use by 127.0.0.1:1000"
    assert link.tell(other, 1.1) is None  # not more often than every 0.5 s
    link.release(other)  # a stranger's release changes nothing
    assert link.owner == owner
    assert link.admit(owner, "SET_ACTUATOR_CONTROL_TARGET", 5.0)
    assert not link.admit(other, "COMMAND_LONG", 5.0 + OWNER_SILENCE - 0.1)
    assert link.admit(other, "COMMAND_LONG", 5.0 + OWNER_SILENCE + 0.1)  # silent: lapsed
    assert link.owner == other
    link.release(other)
    assert link.owner is None
    assert link.admit(owner, "COMMAND_LONG", 100.0, may_take=False)  # unsigned: handled
    assert link.owner is None  # on to the signature check, but takes nothing
