"""The motor path over real UDP: lockstep, state answers, reset, bad motor commands."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from pymavlink import mavutil

from quadsitl.lockstep_client.fleet_client import FleetClient
from quadsitl.lockstep_client.motor_client import MotorClient, SimulatorError
from quadsitl.physics import Fleet, get_airframe
from quadsitl.physics import layout as L
from quadsitl.wire.state import WireState
from tests.conftest import MotorSim

AIRFRAME = get_airframe("paper")
HOVER = AIRFRAME.hover_rotor_speed / AIRFRAME.max_rotor_speed


@pytest.fixture
def lockstep_sim() -> Iterator[MotorSim]:
    sim = MotorSim("--lockstep")
    yield sim
    sim.stop()


def _as_float32(state: WireState) -> np.ndarray:
    return np.concatenate(
        [
            state.position_ned,
            state.q_ned_frd,
            state.velocity_frd,
            state.rates_frd,
            state.rotor_speeds,
        ]
    ).astype(np.float32)


def test_lockstep_n_commands_make_n_steps_matching_in_process_physics(lockstep_sim):
    client = lockstep_sim.client()
    q = np.array([0.9, 0.1, -0.2, 0.3])  # some attitude (FRD -> NED); normalised by reset
    start = client.reset([1.0, -2.0, -6.0], q / np.linalg.norm(q), [0.5, 0.0, -0.25])
    client.arm()
    period_us = 4000  # default: 250 Hz control, 1 kHz physics -> 4 physics steps each
    fleet = Fleet(1, AIRFRAME, dt=0.001)
    fleet.reset(start.to_physics(AIRFRAME.gear_height))
    rng = np.random.default_rng(0)
    n = 300
    for i in range(n):
        controls = np.clip(HOVER + rng.normal(0, 0.05, 4), 0, 1).astype(np.float32)
        answer = client.step(controls)
        assert answer.time_usec == start.time_usec + (i + 1) * period_us
        fleet.step(controls.astype(np.float64) * AIRFRAME.max_rotor_speed, n_substeps=4)
        expected = WireState.from_physics(
            fleet.state[0], AIRFRAME.gear_height, answer.time_usec, 0, 0.0
        )
        got, want = _as_float32(answer), _as_float32(expected)
        # The simulator started from the float32 state it answered the reset with.
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
    assert answer.contact == L.AIRBORNE
    assert client.statustexts.count("external motor control") == 1


def test_bad_motor_commands_change_nothing_and_are_answered(lockstep_sim):
    client = lockstep_sim.client()
    client.reset([0.0, 0.0, -5.0])
    client.arm()
    client.step([HOVER] * 4)
    before = client.step([HOVER] * 4)  # stamped with the time of the answer before it
    for bad in (
        [float("nan"), 0.5, 0.5, 0.5],
        [float("inf")] * 4,
        [1.5, 0.5, 0.5, 0.5],
        [-0.1, 0.5, 0.5, 0.5],
    ):
        answer = client.step(bad)
        assert answer.time_usec == before.time_usec  # rejected: time did not move
        np.testing.assert_array_equal(answer.position_ned, before.position_ned)
    assert any("motor command rejected" in t for t in client.statustexts)
    # Time going backwards: stamp the command before the last accepted one (4000 µs).
    client.state = WireState(**{**before.__dict__, "time_usec": 3999})
    assert client.step([HOVER] * 4).time_usec == before.time_usec
    assert "before the last command" in "".join(client.statustexts)  # chunked: > 50 chars
    # Still flying on good commands.
    client.state = before
    assert client.step([HOVER] * 4).time_usec == before.time_usec + 4000


def test_disarmed_vehicle_ignores_motor_commands(lockstep_sim):
    client = lockstep_sim.client()
    client.reset([0.0, 0.0, -20.0])  # hovering rotor speed, not armed
    answers = [client.step([1.0] * 4) for _ in range(100)]
    assert answers[-1].time_usec == answers[0].time_usec + 99 * 4000  # time moves
    assert answers[-1].rotor_speeds.max() < 0.5 * answers[0].rotor_speeds.max()  # spin down
    assert answers[-1].velocity_frd[2] > 1.0  # falling
    assert any("disarmed" in t for t in client.statustexts)
    # The armed flag clear also stops the motors, even when armed.
    client.reset([0.0, 0.0, -20.0])
    client.arm()
    answer = [client.step([1.0] * 4, armed=False) for _ in range(100)][-1]
    assert answer.rotor_speeds.max() < 100


def test_reset_is_checked_and_acknowledged(lockstep_sim):
    client = lockstep_sim.client()
    with pytest.raises(SimulatorError, match="below the ground"):
        client.reset([0.0, 0.0, 1.0])
    with pytest.raises(SimulatorError, match="NaN"):
        client.reset([0.0, float("nan"), -1.0])
    with pytest.raises(SimulatorError, match="quaternion is zero"):
        client.reset([0.0, 0.0, -1.0], [0.0, 0.0, 0.0, 0.0])
    state = client.reset([3.0, 4.0, -5.0], rates_frd=[0.1, 0.0, 0.0], rotor_speed=300.0)
    np.testing.assert_allclose(state.position_ned, [3.0, 4.0, -5.0], atol=1e-6)
    np.testing.assert_allclose(state.rates_frd, [0.1, 0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(state.rotor_speeds, 300.0)
    assert state.contact == L.AIRBORNE
    on_ground = client.reset([0.0, 0.0, 0.0])
    assert on_ground.contact == L.ON_GROUND
    assert on_ground.rotor_speeds.max() == 0.0


def test_silent_lockstep_client_costs_no_cpu_and_gcs_keeps_heartbeat(lockstep_sim):
    client = lockstep_sim.client()
    client.reset([0.0, 0.0, -5.0])
    client.arm()
    for _ in range(50):
        client.step([HOVER] * 4)
    gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{lockstep_sim.gcs_port}")
    try:
        gcs.mav.heartbeat_send(
            mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0
        )
        cpu_before = _cpu_seconds(lockstep_sim.process.pid)
        started = time.monotonic()
        beats = 0
        while time.monotonic() - started < 3.0:
            if gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5):
                beats += 1
        cpu = (_cpu_seconds(lockstep_sim.process.pid) - cpu_before) / 3.0
    finally:
        gcs.close()
    assert beats >= 2
    assert cpu < 0.2  # waiting, not spinning
    assert client.step([HOVER] * 4).time_usec == 51 * 4000  # resumes where it stopped


def test_motor_control_ends_safely_when_commands_stop():
    sim = MotorSim("--speed", "1")
    gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{sim.gcs_port}")
    try:
        client = sim.client()
        client.reset([0.0, 0.0, -5.0])
        client.arm()
        gcs.mav.heartbeat_send(
            mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0
        )
        for _ in range(50):  # real time: each answer is the current state
            client.step([HOVER] * 4, lockstep=False)
            time.sleep(0.01)
        # The heartbeat says so (the first one may be the greeting the station got before
        # the commands began; a change of state is sent at once).
        hil = f"HEARTBEAT.base_mode & {mavutil.mavlink.MAV_MODE_FLAG_HIL_ENABLED}"
        beat = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=5, condition=hil)
        assert beat is not None, "no heartbeat says motor control (HIL) is on"
        # Commands stop: after 0.5 s the onboard controller takes over and holds.
        text = gcs.recv_match(
            type="STATUSTEXT",
            blocking=True,
            timeout=5,
            condition="'motor control ended' in STATUSTEXT.text",
        )
        assert text is not None and "no motor commands" in text.text
        # 2 s of simulated time later (a busy machine may take longer), it holds.
        ended = gcs.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=5)
        position = ended
        deadline = time.monotonic() + 30
        while position.time_boot_ms < ended.time_boot_ms + 2000:
            assert time.monotonic() < deadline, "2 s of simulated time took over 30 s"
            position = gcs.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=5)
            assert position is not None, "no position for 5 s"
        assert abs(position.z + 5.0) < 0.5 and abs(position.x) < 0.5
        beat = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
        assert not beat.base_mode & mavutil.mavlink.MAV_MODE_FLAG_HIL_ENABLED
        assert beat.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    finally:
        gcs.close()
        sim.stop()


def _cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / 100.0  # utime + stime, clock ticks


def test_wire_state_round_trip_is_exact_to_float64_rounding():
    rng = np.random.default_rng(3)
    state = np.zeros(L.STATE_SIZE)
    state[L.POS] = rng.normal(0, 10, 3) + np.array([0.0, 0.0, 20.0])
    state[L.VEL] = rng.normal(0, 3, 3)
    q = rng.normal(size=4)
    state[L.QUAT] = q / np.linalg.norm(q)
    state[L.RATES] = rng.normal(0, 2, 3)
    state[L.ROTORS] = rng.uniform(0, 800, 4)
    wire = WireState.from_physics(state, 0.1, 0, L.AIRBORNE, 0.0)
    np.testing.assert_allclose(wire.to_physics(0.1), state, rtol=0, atol=1e-12)


def test_answers_carry_hil_state_quaternion_unless_turned_off(lockstep_sim):
    full = MotorClient("127.0.0.1", lockstep_sim.hil_port)
    lockstep_sim.client().close()  # wait until the simulator is up
    full.connect(hil_state=True)
    full.reset([0.0, 0.0, -5.0], [1.0, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0])
    answer = full.step([HOVER] * 4)
    hil = full.hil_state
    assert hil is not None and hil.time_usec == answer.time_usec
    assert abs(hil.vx - 200) <= 1  # cm/s, NED: the staged 2 m/s north
    assert abs(hil.alt - (488_000 + 5_000)) <= 10  # mm above sea level at 5 m
    lean = lockstep_sim.client()  # connect() turns it off for its own link
    lean.step([HOVER] * 4)
    assert lean.hil_state is None
    full.close()
    lean.close()


def test_the_motor_client_is_the_fleet_client_of_one_vehicle_and_flies_alike(lockstep_sim):
    """A lone vehicle flown with HIL_ACTUATOR_CONTROLS (a round of one) and with rounds
    of SET_ACTUATOR_CONTROL_TARGET: the same client, the same flight."""
    rng = np.random.default_rng(5)
    controls = np.clip(HOVER + rng.normal(0, 0.05, (20, 4)), 0, 1)
    motor = lockstep_sim.client()
    assert isinstance(motor, FleetClient) and motor.n == 1 and motor.target_system == 1
    motor.arm()
    motor.reset([1.0, 2.0, -8.0], velocity_ned=[0.5, 0.0, 0.0], rotor_speed=300.0)
    by_hil = [_as_float32(motor.step(row)) for row in controls]
    motor.close()  # hands the motor link to the next client
    fleet = FleetClient("127.0.0.1", lockstep_sim.hil_port, 1, timeout=5.0)
    fleet.connect()
    pose = WireState(
        time_usec=0,
        position_ned=np.array([[1.0, 2.0, -8.0]]),
        q_ned_frd=np.array([[1.0, 0.0, 0.0, 0.0]]),
        velocity_frd=np.zeros((1, 3)),  # the reset takes the velocity NED
        rates_frd=np.zeros((1, 3)),
        rotor_speeds=np.full((1, 4), 300.0),
        contact=None,
        touchdown_speed=None,
    )
    fleet.reset([0], pose, np.array([[0.5, 0.0, 0.0]]))
    by_round = [_as_float32(fleet.step(row[np.newaxis]).row(0)) for row in controls]
    fleet.close()
    np.testing.assert_array_equal(by_round, by_hil)


def test_round_answers_on_a_logged_link_are_logged(tmp_path):
    """Every frame on a link other than the motor link goes to the telemetry log, the
    answers of rounds flown through it too."""
    sim = MotorSim("--lockstep", "--logs", str(tmp_path))
    try:
        client = FleetClient("127.0.0.1", sim.gcs_port, 1, timeout=5.0)
        for _ in range(60):  # the process needs a moment to start
            try:
                client.connect()
                break
            except SimulatorError:
                assert sim.process.poll() is None
        state = np.zeros((1, L.STATE_SIZE))
        state[0, L.I_PZ], state[0, L.QUAT.start] = 10.0, 1.0
        wire = WireState.from_physics(state, AIRFRAME.gear_height, 0, None, None)
        client.reset([0], wire, np.zeros((1, 3)))
        times = {int(client.step(np.full((1, 4), HOVER)).time_usec) for _ in range(20)}
        client.close()
    finally:
        sim.stop()
    (log,) = Path(tmp_path).glob("*.tlog")
    reader = mavutil.mavlink_connection(str(log))
    logged = set()
    while (msg := reader.recv_match(type="ACTUATOR_OUTPUT_STATUS")) is not None:
        logged.add(msg.time_usec)
    assert times <= logged
