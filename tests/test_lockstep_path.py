"""One lockstep path: a fleet's round (SET_ACTUATOR_CONTROL_TARGET) and a lone vehicle's
HIL_ACTUATOR_CONTROLS (a round of one) go through the same rules of the one motor path
(:class:`~quadsitl.simulator.motor_path.MotorPath`), in process: pending commands, the
repeat rule, the lockstep clock and the answer."""

from __future__ import annotations

import time

import numpy as np
import pytest

from quadsitl.flight_software.group import VehicleGroup
from quadsitl.physics import get_airframe
from quadsitl.physics import layout as L
from quadsitl.simulator.links import Link
from quadsitl.simulator.motor_path import LOCKSTEP_IDLE, MotorPath
from quadsitl.simulator.motor_slot import MotorSlot
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.answer import AnswerReader, decode_answer
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import ARMED_FLAG, LOCKSTEP_FLAG
from quadsitl.wire.state import WireState
from quadsitl.wire.units import to_time_usec

AIRFRAME = get_airframe("paper")
HOVER = AIRFRAME.hover_rotor_speed / AIRFRAME.max_rotor_speed
PERIOD_US = 4000  # the default control period


def _path(n: int = 1, lockstep: bool = False) -> MotorPath:
    """The motor path of ``n`` armed vehicles, reset 20 m up."""
    group = VehicleGroup(n, sensor_noise=0.0)
    slots = [MotorSlot(v, system_id=1 + i) for i, v in enumerate(group.vehicles)]
    for vehicle, slot in zip(group.vehicles, slots, strict=True):
        assert vehicle.arm(force=True).ok
        assert slot.reset([0.0, 0.0, -20.0, 1.0, 0.0, 0.0, 0.0]).ok
    return MotorPath(group.batch, slots, lockstep)


def _time(path: MotorPath) -> int:
    return to_time_usec(path.slots[0].vehicle.time)


def _hil(path: MotorPath, seq: int, controls: list[float], stamp: int = 0, flags: int = 1):  # type: ignore[no-untyped-def]
    return path.hil_command((255, 190, seq), stamp, flags, controls + [0.0] * 12, ARMED_FLAG)


def test_a_hil_command_and_a_round_of_one_fly_the_same():
    by_hil, by_round = _path(), _path()
    rng = np.random.default_rng(4)
    for seq in range(40):
        controls = np.clip(HOVER + rng.normal(0, 0.05, 4), 0, 1).tolist()
        a = _hil(by_hil, seq % 256, controls, stamp=_time(by_hil))
        b = by_round.round_command(0, _time(by_round), controls)
        assert a == b == ([0], [])
        assert _time(by_hil) == _time(by_round) == (seq + 1) * PERIOD_US
    np.testing.assert_array_equal(by_hil.slots[0].vehicle.state, by_round.slots[0].vehicle.state)
    assert by_hil.rounds == by_round.rounds == 40


def test_a_repeat_is_answered_without_flying_again_for_both_messages_until_a_reset():
    path = _path()
    _hil(path, 7, [HOVER] * 4)
    assert _hil(path, 7, [HOVER] * 4).rows == [0]  # the same frame again: answered
    assert _time(path) == PERIOD_US  # ... and not flown again
    start = _time(path)
    path.round_command(0, start, [HOVER] * 4)
    assert path.round_command(0, start, [HOVER] * 4).rows == [0]  # the same round again
    assert _time(path) == start + PERIOD_US
    assert path.slots[0].counters["repeats"] == 2
    assert path.slots[0].reset([0.0, 0.0, -20.0, 1.0, 0.0, 0.0, 0.0]).ok
    _hil(path, 7, [HOVER] * 4)  # after a reset, never a repeat
    assert _time(path) == start + 2 * PERIOD_US


def test_a_round_flies_once_every_vehicle_has_its_command():
    path = _path(3)
    start = _time(path)
    assert path.round_command(0, start, [HOVER] * 4).rows == []
    assert path.round_command(2, start, [HOVER] * 4).rows == []
    assert _time(path) == start  # waiting for vehicle 1
    assert path.round_command(1, start, [HOVER] * 4).rows == [0, 1, 2]
    assert _time(path) == start + PERIOD_US and path.rounds == 1


def test_refused_commands_change_nothing_and_are_answered_with_a_reason():
    path = _path(2)
    start = _time(path)
    wrong = path.round_command(1, start + 1, [HOVER] * 4)
    assert wrong.rows == [1] and "stamped" in wrong.warnings[0][1]
    bad = path.round_command(0, start, [float("nan")] * 4)
    assert bad.rows == [0] and "control 0 is nan" in bad.warnings[0][1]
    assert path.pending == {} and _time(path) == start
    assert [slot.counters["rejected"] for slot in path.slots] == [1, 1]
    lone = _path()
    for seq in (1, 2):
        _hil(lone, seq, [HOVER] * 4, stamp=_time(lone))  # 0 (unstamped), then 4000 µs
    late = _hil(lone, 3, [HOVER] * 4, stamp=1)  # before the last command's time
    assert late.rows == [0] and "before the last command" in late.warnings[0][1]
    assert _time(lone) == 2 * PERIOD_US


def test_one_clock_for_both_messages_and_real_time_commands_do_not_step():
    path = _path()
    now = time.monotonic()
    assert not path.in_lockstep(now)
    _hil(path, 1, [HOVER] * 4, flags=0)  # real time: flown, not stepped
    assert _time(path) == 0 and not path.in_lockstep(time.monotonic())
    assert path.slots[0].vehicle.rotor_cmd[0] == pytest.approx(HOVER * AIRFRAME.max_rotor_speed)
    _hil(path, 2, [HOVER] * 4, flags=LOCKSTEP_FLAG)
    assert path.in_lockstep(time.monotonic())
    assert not path.in_lockstep(path.last_wall + LOCKSTEP_IDLE)
    path.round_command(0, _time(path), [HOVER] * 4)
    assert path.in_lockstep(time.monotonic())
    assert MotorPath(path.batch, path.slots, lockstep=True).in_lockstep(now + 1e6)


def test_answers_full_and_lean_carry_each_vehicles_state():
    path = _path(2)
    path.round_command(0, 0, [HOVER] * 4)
    path.round_command(1, 0, [1.0] * 4)
    link = Link("udpin:127.0.0.1:0", "hil", 1, 1)
    try:
        lean = path.answer(link, [0, 1], full=False)
        full = path.answer(link, [1], full=True, hil_state=[True])
    finally:
        link.close()
    ids = [[next(FC.parse(f)).msgid for f in frames] for frames in lean]
    assert ids[0] == [mav.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS, mav.MAVLINK_MSG_ID_ODOMETRY]
    full_ids = [next(FC.parse(f)).msgid for f in full[0]]
    assert full_ids[0] == mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION
    assert mav.MAVLINK_MSG_ID_NAMED_VALUE_INT in full_ids  # CONTACT, even airborne
    reader = AnswerReader()
    answers = []
    for i, frames in enumerate(lean):
        for frame in FC.parse(b"".join(frames)):
            assert frame.sysid == 1 + i
            got = reader.take(i, frame.msgid, frame.unpack())
            answers += [got] if got is not None else []
    decoded = decode_answer(answers)
    physics = path.batch.physics
    truth = WireState.from_physics(physics.state, AIRFRAME.gear_height, 0, None, None)
    assert decoded.time_usec == PERIOD_US
    np.testing.assert_allclose(decoded.position_ned, truth.position_ned, atol=1e-5)
    np.testing.assert_allclose(decoded.rotor_speeds, physics.state[:, L.ROTORS], rtol=1e-6)


def test_a_fleets_answers_built_at_once_are_the_frame_by_frame_bytes():
    """The lean answers of more than ROW_BY_ROW vehicles are built for all of them at once
    (:func:`lean_answer_frames`): byte for byte the frames of :func:`answer_parts`
    packed one by one, sequence numbers included, for vehicles in the air, on the ground
    and with values no field holds (fitted, as the frame-by-frame path fits them)."""
    from quadsitl.simulator.motor_slot import answer_parts, lean_answer_frames
    from quadsitl.wire import fast_codec as FC

    path = _path(12)
    rng = np.random.default_rng(7)
    for _ in range(3):
        for row in range(12):
            controls = np.clip(HOVER + rng.normal(0, 0.1, 4), 0, 1).tolist()
            path.round_command(row, _time(path), controls)
    state = path.batch.physics.state
    state[3, L.POS] = (0.0, 0.0, AIRFRAME.gear_height)  # on the ground
    state[3, L.VEL] = 0.0
    path.batch.physics.contact[3] = L.ON_GROUND
    state[5, L.POS] = (1e39, -1e39, 3.0)  # beyond float32: saturated
    state[6, L.VEL] = (np.nan, np.inf, -np.inf)
    path.slots[7].resets = 300  # a counter of one byte: wraps
    slots = path.slots
    seqs_a: dict[int, int] = {}
    seqs_b: dict[int, int] = {}

    def counter(seqs: dict[int, int]):  # type: ignore[no-untyped-def]
        def next_seq(system_id: int) -> int:
            seq = seqs.get(system_id, 250)  # (wrapping past 255 on the way)
            seqs[system_id] = (seq + 1) & 0xFF
            return seq

        return next_seq

    for _ in range(3):
        at_once = lean_answer_frames(slots, counter(seqs_a))
        next_seq = counter(seqs_b)
        one_by_one = [
            [FC.pack(cls, values, next_seq(s.system_id), s.system_id, s.component_id)
             for cls, values in parts]
            for s, parts in zip(slots, answer_parts(slots, full=False), strict=True)
        ]  # fmt: skip
        assert at_once == one_by_one
    assert len(at_once[3]) == 4 and len(at_once[0]) == 2  # on the ground: CONTACT, TD_SPEED


def test_a_fleets_commands_framed_at_once_are_the_frame_by_frame_bytes():
    from quadsitl.lockstep_client.fleet_client import FleetClient
    from quadsitl.wire.addresses import free_udp_port

    with FleetClient("127.0.0.1", free_udp_port(), 12) as client:
        controls = np.random.default_rng(3).random((12, 4))
        controls[2] = (np.nan, np.inf, 1e39, -0.5)  # what the simulator then refuses
        client.seq = 250  # (wrapping past 255 on the way)
        at_once = client._actuator_frames(123_456, controls)
        after = client.seq
        client.seq = 250
        one_by_one = [
            client._actuator_frame(123_456, i, row) for i, row in enumerate(controls.tolist())
        ]
        assert at_once == one_by_one and client.seq == after
