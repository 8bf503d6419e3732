"""Lockstep through a link that loses and delays datagrams: rounds are resent, answered
once, matched by time, and the flight is the same as without loss."""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
import pytest

import quadsitl  # noqa: F401  (registers the envs)
from gcs_tools.relay import LossyRelay
from quadsitl.envs.sim_process import SimProcess
from quadsitl.lockstep_client.fleet_client import FleetClient
from quadsitl.lockstep_client.motor_client import MotorClient, SimulatorError
from quadsitl.physics import PAPER, Fleet
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import RESET_STATE
from quadsitl.wire.state import WireState
from tests.conftest import MotorSim, fly_both, reset_both

RATES = ["--physics-rate", "100", "--control-rate", "20", "--gcs", "none", "--api", "none"]


@pytest.fixture
def fleet_sim():
    sim = SimProcess(["--vehicles", "4", *RATES])
    yield sim
    sim.stop()


def test_ten_percent_loss_both_ways_changes_nothing_but_the_resend_count(fleet_sim):
    kwargs = {"init_position_noise": 0.3}
    local = gym.make_vec("QuadSITL/Hover-v0", 4, "vector_entry_point", **kwargs)
    with LossyRelay(("127.0.0.1", fleet_sim.port), drop=0.1, delay=0.001, seed=5) as relay:
        remote = gym.make_vec(
            "QuadSITL/Hover-v0",
            4,
            "vector_entry_point",
            backend="mavlink",
            sim_address=f"127.0.0.1:{relay.port}",
            vehicles_per_sim=4,
            timeout=10.0,
            **kwargs,
        )
        try:
            reset_both(local, remote, seed=2)
            fly_both(local, remote, np.random.default_rng(0), 150, 0.3)
            client = remote.unwrapped.backend.clients[0]
            assert relay.dropped > 20  # the relay did lose datagrams ...
            assert client.resent > 10  # ... the client resent, and nothing went wrong
        finally:
            remote.close()
            local.close()


def test_a_lost_answer_is_answered_again_not_stepped_twice(fleet_sim):
    client, _, hover = _hovering(fleet_sim)
    first = client.step(hover).time_usec
    # The same round again (as after a lost answer): answered, same time. (A
    # resend under load may bring older repeats too, counted in ``late``: not asserted.)
    client.time_usec = 0
    again = client.step(hover)
    assert first == again.time_usec == 50_000
    client.time_usec = first
    assert client.step(hover).time_usec == 100_000  # and the next round steps once
    client.close()


def test_answers_keep_the_order_of_what_they_answer(fleet_sim):
    """A repeat of the last round and a reset in one datagram (a resent round followed by
    an autoreset, as a loaded learner sends them): the repeat's cached answer comes back
    before the reset's acknowledgement, so the reset's answer is the one after it, and
    the client takes that one: the vehicle where the reset put it."""
    client, state, hover = _hovering(fleet_sim)
    stamp = client.time_usec
    client.step(hover)
    repeat = [client._actuator_frame(stamp, i, row) for i, row in enumerate(hover.tolist())]
    state[0, :3] = [3.0, -2.0, 25.0]  # vehicle 0 goes elsewhere
    moved = WireState.from_physics(state[:1], PAPER.gear_height, 0, None, None)
    client.sock.sendto(b"".join(repeat), client.address)
    answer = client.reset([0], moved, np.zeros((1, 3)))
    np.testing.assert_allclose(answer.position_ned[0], moved.position_ned[0], atol=1e-4)
    _answered_so_far(client)
    # And on the wire: the repeat's answer, then the reset's ACK and the new state.
    client.sock.sendto(b"".join(repeat[:1]), client.address)
    client._send([client._command_frame(RESET_STATE, 0, *moved.position_ned[0], 1, 0, 0, 0)])
    seen = []
    deadline = time.monotonic() + 5
    while len([f for f in seen if f.msgid == mav.MAVLINK_MSG_ID_ODOMETRY]) < 2:
        assert time.monotonic() < deadline, seen
        seen += [f for f in client._receive(deadline) if f.sysid == 1]
    kinds = [
        f.msgid
        for f in seen
        if f.msgid in (mav.MAVLINK_MSG_ID_ODOMETRY, mav.MAVLINK_MSG_ID_COMMAND_ACK)
    ]
    assert kinds == [
        mav.MAVLINK_MSG_ID_ODOMETRY,  # the repeat, answered again
        mav.MAVLINK_MSG_ID_COMMAND_ACK,  # the reset
        mav.MAVLINK_MSG_ID_ODOMETRY,  # its state
    ]
    client.close()


def _answered_so_far(client: FleetClient) -> None:
    """Read until the simulator has answered everything sent to it so far. The client
    resends what is not answered within a few round trips (on a loaded machine, often),
    and the answers to the repeats may come after it has returned: one more request,
    answered after all of them (one socket each way, handled in order), fences them off."""
    interval = (mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, -1)  # as connect() sets it
    client._send([client._command_frame(mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0, *interval)])
    deadline = time.monotonic() + 5
    while True:
        assert time.monotonic() < deadline, "the simulator did not answer"
        for frame in client._receive(deadline):
            ack = frame.sysid == 1 and frame.msgid == mav.MAVLINK_MSG_ID_COMMAND_ACK
            if ack and frame.unpack()[0] == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
                return


def test_a_round_for_another_time_is_refused_and_a_silent_simulator_is_an_error(fleet_sim):
    client = FleetClient("127.0.0.1", fleet_sim.port, 4, timeout=0.5)
    _wait(client)
    client.time_usec = 12_345_000  # not where the simulator is
    with pytest.raises(SimulatorError, match=r"no state answer.*stamped 12345000 µs"):
        client.step(np.zeros((4, 4)))
    client.close()
    gone = FleetClient("127.0.0.1", fleet_sim.port, 5, timeout=2.5)  # system 5 is not there
    with pytest.raises(SimulatorError, match=r"heartbeat of system\(s\) \[5\]"):
        gone.connect()
    gone.close()


def _hovering(fleet_sim: SimProcess) -> tuple[FleetClient, np.ndarray, np.ndarray]:
    """A client of the 4-vehicle fixture, its vehicles reset to hover 20 m up; their
    states and the hover commands."""
    client = FleetClient("127.0.0.1", fleet_sim.port, 4, timeout=10.0)
    _wait(client)
    state = np.zeros((4, 17))
    state[:, 2], state[:, 6], state[:, 13:] = 20.0, 1.0, PAPER.hover_rotor_speed
    wire = WireState.from_physics(state, PAPER.gear_height, 0, None, None)
    client.reset([0, 1, 2, 3], wire, np.zeros((4, 3)))
    hover = np.full((4, 4), PAPER.hover_rotor_speed / PAPER.max_rotor_speed)
    return client, state, hover


def _wait(client: FleetClient) -> None:
    for _ in range(60):
        try:
            client.connect()
            return
        except SimulatorError:
            continue
    raise AssertionError("the simulator did not start")


def test_a_signed_fleet_matches_in_process():
    """With a signing key the round's frames are signed both ways (pymavlink signs; the
    simulator checks every command) and the flight is still the in-process one."""
    key = bytes(range(1, 33))
    local = gym.make_vec("QuadSITL/Hover-v0", 2, "vector_entry_point", init_position_noise=0.3)
    remote = gym.make_vec(
        "QuadSITL/Hover-v0",
        2,
        "vector_entry_point",
        backend="mavlink",
        vehicles_per_sim=2,
        signing_key=key,
        init_position_noise=0.3,
    )
    try:
        reset_both(local, remote, seed=5)
        fly_both(local, remote, np.random.default_rng(2), 30, 0.1)
        assert remote.unwrapped.backend.clients[0].signing
    finally:
        local.close()
        remote.close()


def test_motor_client_resends_through_ten_percent_loss_and_steps_each_command_once():
    """The single-vehicle client through a relay losing 10 % each way: it connects,
    resets, arms and steps 150 times; every step advances exactly one control period
    and the flight is the in-process physics' (a repeat is never stepped twice)."""
    sim = MotorSim("--lockstep")
    airframe = PAPER
    hover = airframe.hover_rotor_speed / airframe.max_rotor_speed
    try:
        with LossyRelay(("127.0.0.1", sim.hil_port), drop=0.1, seed=7) as relay:
            client = MotorClient("127.0.0.1", relay.port, timeout=5.0)
            deadline = time.monotonic() + 60
            while True:  # the process needs a moment to start
                try:
                    client.connect()
                    break
                except SimulatorError:
                    assert time.monotonic() < deadline and sim.process.poll() is None
            start = client.reset([0.0, 0.0, -6.0], velocity_ned=[0.3, 0.0, 0.0])
            client.arm()
            fleet = Fleet(1, airframe, dt=0.001)
            fleet.reset(start.to_physics(airframe.gear_height))
            rng = np.random.default_rng(1)
            for i in range(150):
                controls = np.clip(hover + rng.normal(0, 0.05, 4), 0, 1).astype(np.float32)
                answer = client.step(controls)
                assert answer.time_usec == start.time_usec + (i + 1) * 4000
                fleet.step(controls.astype(np.float64) * airframe.max_rotor_speed, n_substeps=4)
                expected = WireState.from_physics(
                    fleet.state[0], airframe.gear_height, answer.time_usec, 0, 0.0
                )
                np.testing.assert_allclose(answer.position_ned, expected.position_ned, atol=1e-4)
                np.testing.assert_allclose(answer.velocity_frd, expected.velocity_frd, atol=1e-4)
            assert relay.dropped > 10 and client.resent > 5
            client.close()
    finally:
        sim.stop()
