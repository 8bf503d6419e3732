"""ArduPilot's JSON physics interface without sockets: packets, motor order, the reply's
units and frames, lockstep bookkeeping, the parameter files, and a closed-loop hover.

The wire (real UDP, a real ``quadsitl sim`` process, bad input) is tests/test_ardupilot_udp.py.
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from quadsitl import frames
from quadsitl.bridges.ardupilot_json import (
    ARDUPILOT_QUAD_FRAMES,
    MAX_STEP,
    PACKET_SIZES,
    PWM_MAX_US,
    PWM_MIN_US,
    REPLY_LIMIT,
    SERVO_MAGIC_16,
    SERVO_MAGIC_32,
    JsonPhysics,
    PacketError,
    ServoFrame,
    encode_servo_packet,
    kinematics_line,
    motor_channels,
    parse_servo_packet,
)
from quadsitl.bridges.ardupilot_udp import PARAMETER_FOLDER, parameter_file
from quadsitl.bridges.fake_ardupilot import (
    HoverController,
    ReplyError,
    parse_kinematics,
)
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import AIRFRAMES, get_airframe
from quadsitl.physics.fleet import Fleet

RATE = 1200  # Hz


def frame(count: int, pwm: list[int] | tuple[int, ...], rate: int = RATE) -> ServoFrame:
    return ServoFrame(rate, count, tuple(pwm) + (0,) * (16 - len(pwm)))


def test_servo_packets_of_16_and_32_channels_round_trip_with_their_sizes() -> None:
    for channels, magic in ((16, SERVO_MAGIC_16), (32, SERVO_MAGIC_32)):
        sent = ServoFrame(400, 123456, tuple(range(1000, 1000 + channels)))
        data = encode_servo_packet(sent)
        assert len(data) == PACKET_SIZES[magic] == 8 + 2 * channels
        assert int.from_bytes(data[:2], "little") == magic
        assert parse_servo_packet(data) == sent


@pytest.mark.parametrize(
    ("data", "says"),
    [
        (b"\x1aH", "too short"),
        (b"\x00\x00" + bytes(38), "magic 0 is not a servo frame's"),
        (encode_servo_packet(frame(0, [1000]))[:-2], "has 40 bytes, got 38"),
        (encode_servo_packet(frame(0, [1000])) + b"\x00\x00", "has 40 bytes, got 42"),
        (b"\x1aH\x00\x00" + bytes(36), "frame_rate 0"),
    ],
)
def test_a_datagram_that_is_not_a_servo_frame_is_refused_in_one_line(
    data: bytes, says: str
) -> None:
    with pytest.raises(PacketError, match=says) as error:
        parse_servo_packet(data)
    assert "\n" not in str(error.value)


def test_motor_order_matches_ardupilots_frames() -> None:
    """X presets: motors 1..4 are rotors 1..4 (PX4 order); the paper's plus is PlusRev,
    whose channels 3, 2, 4, 1 drive rotors 1..4 (front, left, back, right)."""
    assert motor_channels(AIRFRAMES["paper-x"]) == (1, (0, 1, 2, 3))
    assert motor_channels(AIRFRAMES["paper-x-fast"]) == (1, (0, 1, 2, 3))
    assert motor_channels(AIRFRAMES["iris"]) == (1, (0, 1, 2, 3))
    assert motor_channels(AIRFRAMES["paper"]) == (6, (2, 1, 3, 0))
    mirrored = AIRFRAMES["paper-x"].replace(name="mirrored", rotor_yaw_sign=(1, 1, -1, -1))
    with pytest.raises(ValueError, match="matches no ArduPilot quad frame"):
        motor_channels(mirrored)


@pytest.mark.parametrize("airframe", ["paper", "paper-x-fast", "iris"])
def test_each_ardupilot_motor_turns_the_vehicle_as_its_frame_table_says(airframe: str) -> None:
    """Motor k pushed above hover: the body rates (FRD, from the reply) turn away from its
    side (roll −sin θ, pitch +cos θ for bearing θ clockwise from the nose) and yaw with its
    spin (counter-clockwise motors yaw the nose right)."""
    frame_type, _ = motor_channels(get_airframe(airframe))
    _, motors = ARDUPILOT_QUAD_FRAMES[frame_type]
    hover = round(PWM_MIN_US + 1000 * math.sqrt(get_airframe(airframe).hover_thrust_fraction))
    for k, (bearing, spin) in enumerate(motors):
        physics = JsonPhysics(Fleet(1, airframe, dt=1 / RATE, ground_z=-math.inf))
        pwm = [hover] * 4
        for count in range(RATE // 4):  # spin up to hover
            physics.answer({0: frame(count, pwm)})
        pwm[k] += 150
        for count in range(RATE // 4, RATE // 4 + 60):  # 50 ms
            reply = physics.answer({0: frame(count, pwm)})[0]
        p, q, r = parse_kinematics(reply).gyro
        theta = math.radians(bearing)
        expected = (-math.sin(theta), math.cos(theta))
        largest = max(abs(p), abs(q))
        assert largest > 0.05  # rad/s after 50 ms
        for rate, sign in zip((p, q), expected, strict=True):
            if abs(sign) < 1e-6:  # a motor on this axis
                assert abs(rate) < 0.01 * largest
            else:
                assert np.sign(rate) == np.sign(sign)
        assert np.sign(r) == spin


def test_the_reply_has_ardupilots_units_and_frames() -> None:
    """Against quadsitl.frames: NED position from the start point on the ground, NED
    velocity, FRD rates, the FRD->NED attitude and the specific force in FRD."""
    rng = np.random.default_rng(4)
    gear, g, dt = 0.1, 9.81, 1 / RATE
    for _ in range(20):
        state = np.zeros(L.STATE_SIZE)
        state[L.POS] = rng.normal(0, 10, 3)
        state[L.VEL] = rng.normal(0, 3, 3)
        state[L.QUAT] = frames.quat_normalize(rng.normal(size=4))
        state[L.RATES] = rng.normal(0, 2, 3)
        before = state[L.VEL] - rng.normal(0, 0.01, 3)
        line, replaced = kinematics_line(7.5, state.tolist(), tuple(before), dt, g, gear)
        k = parse_kinematics(line)
        assert not replaced
        accel_enu = (state[L.VEL] - before) / dt - np.array([0.0, 0.0, -g])
        accel_flu = frames.quat_rotate(frames.quat_conjugate(state[L.QUAT]), accel_enu)
        np.testing.assert_allclose(
            k.position, frames.enu_to_ned(state[L.POS] - [0, 0, gear]), atol=1e-6
        )
        np.testing.assert_allclose(k.velocity, frames.enu_to_ned(state[L.VEL]), atol=1e-6)
        np.testing.assert_allclose(k.gyro, frames.flu_to_frd(state[L.RATES]), atol=1e-7)
        np.testing.assert_allclose(k.accel_body, frames.flu_to_frd(accel_flu), atol=1e-5)
        q = frames.quat_enu_flu_to_ned_frd(state[L.QUAT])
        np.testing.assert_allclose(k.quaternion, q, atol=1e-8)
        assert k.timestamp == 7.5


def test_the_reply_is_one_compact_line_between_newlines_as_ardupilots_parser_needs() -> None:
    physics = JsonPhysics(Fleet(1, "iris", dt=1 / RATE))
    reply = physics.answer({0: frame(0, [1000] * 4)})[0]
    assert reply.startswith(b"\n{") and reply.endswith(b"}\n") and reply.count(b"\n") == 2
    assert not re.search(rb"\s", reply.strip()), "whitespace breaks ArduPilot's sscanf"
    k = parse_kinematics(reply)
    # At rest on the ground: level, nose north, the ground holding it up.
    np.testing.assert_allclose(k.accel_body, (0, 0, -9.81), atol=1e-6)
    np.testing.assert_allclose(k.quaternion, (1, 0, 0, 0), atol=1e-8)
    assert k.position == (0, 0, 0) and k.timestamp == pytest.approx(1 / RATE)


def test_the_fake_reads_replies_with_ardupilots_strict_rules() -> None:
    good = b'\n{"timestamp":1.5,"imu":{"gyro":[1,2,3],"accel_body":[4,5,6]},'
    good += b'"position":[7,8,9],"velocity":[1,1,1],"quaternion":[1,0,0,0]}\n'
    assert parse_kinematics(good).gyro == (1, 2, 3)
    assert parse_kinematics(good.replace(b",", b", ")).accel_body == (4, 5, 6)  # sscanf's ", "
    with pytest.raises(ReplyError, match="Vector3f for imu/gyro"):
        parse_kinematics(good.replace(b'"gyro":', b'"gyro": '))  # a space after the colon
    with pytest.raises(ReplyError, match="between two newlines"):
        parse_kinematics(good.lstrip(b"\n"))
    with pytest.raises(ReplyError, match="key /quaternion"):
        parse_kinematics(good.replace(b"quaternion", b"attitude"))


def test_a_repeated_frame_is_answered_again_without_a_step() -> None:
    physics = JsonPhysics(Fleet(1, "paper-x-fast", dt=1 / RATE))
    for count in range(600):
        first = physics.answer({0: frame(count, [1900] * 4)})[0]
    again = physics.answer({0: frame(599, [1000] * 4)})[0]
    assert again == first and physics.peers[0].frames == 600
    after = parse_kinematics(physics.answer({0: frame(600, [1900] * 4)})[0])
    assert after.timestamp == pytest.approx(601 / RATE) and after.position[2] < -0.1


def test_a_frame_count_that_goes_back_puts_the_vehicle_back_at_its_start() -> None:
    said: list[str] = []
    physics = JsonPhysics(Fleet(1, "paper-x-fast", dt=1 / RATE), notice=said.append)
    for count in range(1200):
        k = parse_kinematics(physics.answer({0: frame(count, [1900] * 4)})[0])
    assert k.position[2] < -1.0
    k = parse_kinematics(physics.answer({0: frame(0, [1000] * 4)})[0])
    assert k.timestamp == pytest.approx(1 / RATE) and k.position == (0, 0, 0)
    assert k.velocity == (0, 0, 0) and said == [
        "vehicle 0: ArduPilot restarted (frame 0 after 1199); the vehicle is back at its start"
    ]


def test_a_frame_rate_change_mid_flight_is_said_and_followed() -> None:
    said: list[str] = []
    physics = JsonPhysics(Fleet(1, "iris", dt=1 / RATE), notice=said.append)
    physics.answer({0: frame(0, [1000] * 4)})
    k = parse_kinematics(physics.answer({0: frame(1, [1000] * 4, rate=400)})[0])
    assert k.timestamp == pytest.approx(1 / RATE + 1 / 400)
    assert said == [
        "vehicle 0: ArduPilot's frame rate changed mid-flight from 1200 to 400 Hz "
        "(SIM_RATE_HZ); stepping 1/400 s per frame from now on"
    ]


def test_a_reply_never_carries_a_number_that_is_not_finite_or_out_of_range() -> None:
    """NaN becomes 0 and the rest is clamped to ±REPLY_LIMIT (ArduPilot reads floats: a
    NaN or an overflow there spreads through its EKF); the timestamp is kept."""
    state = np.zeros(L.STATE_SIZE)
    state[L.QUAT] = (1.0, 0.0, 0.0, 0.0)
    state[L.I_PX], state[L.I_PY], state[L.I_PZ] = math.nan, 1e300, -math.inf
    state[L.I_VX] = 3.0
    line, replaced = kinematics_line(1e7, state.tolist(), (0.0, 0.0, 0.0), 1 / RATE, 9.81, 0.1)
    k = parse_kinematics(line)
    assert replaced and b"nan" not in line.lower() and b"inf" not in line.lower()
    assert k.position == (REPLY_LIMIT, 0.0, REPLY_LIMIT)  # NED: north = y, east = x
    assert k.velocity[1] == 3.0 and k.timestamp == 1e7
    values = [*k.gyro, *k.accel_body, *k.position, *k.velocity, *k.quaternion]
    assert all(math.isfinite(v) and abs(v) <= REPLY_LIMIT for v in values)
    assert len(line) < 400


def test_a_vehicle_whose_physics_failed_is_answered_in_range_and_said_once() -> None:
    said: list[str] = []
    physics = JsonPhysics(Fleet(1, "iris", dt=1 / RATE), notice=said.append)
    physics.answer({0: frame(0, [1000] * 4)})
    physics.fleet.state[0, L.I_VX] = math.nan  # as a physics that failed would leave it
    for count in range(1, 50):
        reply = physics.answer({0: frame(count, [1500] * 4)})[0]
        assert b"nan" not in reply.lower() and b"inf" not in reply.lower()
        parse_kinematics(reply)
    assert len(said) == 1 and "not finite or beyond" in said[0]


@pytest.mark.parametrize("rate", [1, 2, 5])
def test_a_long_frame_is_flown_in_physics_steps_and_ends_where_short_frames_do(rate: int) -> None:
    """SIM_RATE_HZ 1..5: each frame is sub-stepped at 400 Hz, so the vehicle ends exactly
    where 400 Hz frames with the same outputs leave it, and every reply is finite (one RK4
    step of 1 s took the position to 1e115 m, then NaN)."""
    assert MAX_STEP == 1 / 400
    slow = JsonPhysics(Fleet(1, "iris", dt=1 / RATE))
    fast = JsonPhysics(Fleet(1, "iris", dt=1 / RATE))
    seconds, pwm = 3, [1000 + round(1000 * math.sqrt(0.6))] * 4  # climbs
    for count in range(seconds * rate):
        k = parse_kinematics(slow.answer({0: frame(count, pwm, rate=rate)})[0])
        values = [*k.gyro, *k.accel_body, *k.position, *k.velocity, *k.quaternion]
        assert all(math.isfinite(v) for v in values)
    for count in range(seconds * 400):
        k_fast = parse_kinematics(fast.answer({0: frame(count, pwm, rate=400)})[0])
    np.testing.assert_allclose(slow.fleet.state, fast.fleet.state, rtol=1e-9, atol=1e-9)
    assert k.timestamp == pytest.approx(seconds) and k.position == k_fast.position
    assert 1.0 < -k.position[2] < 100.0


def test_vehicles_step_only_with_their_own_frames() -> None:
    """Vehicle 1 sends nothing: it stays as it was while vehicle 0 climbs, then follows
    its own frames alone; a vehicle of the batch flies as a fleet of one does."""
    both = JsonPhysics(Fleet(2, "paper-x-fast", dt=1 / RATE))
    alone = JsonPhysics(Fleet(1, "paper-x-fast", dt=1 / RATE))
    for count in range(1200):
        replies = both.answer({0: frame(count, [1800] * 4)})
        assert replies.keys() == {0}
        assert replies[0] == alone.answer({0: frame(count, [1800] * 4)})[0]
    assert both.fleet.state[1, L.I_PZ] == pytest.approx(0.1) and both.peers[1].frames == 0
    for count in range(1200, 1300):
        replies = both.answer({0: frame(count, [1800] * 4), 1: frame(count - 1200, [1700] * 4)})
        assert replies[0] == alone.answer({0: frame(count, [1800] * 4)})[0]
    assert parse_kinematics(replies[1]).timestamp == pytest.approx(100 / RATE)


@pytest.mark.parametrize("airframe", ["paper-x-fast", "iris"])
def test_closed_loop_hover_through_the_adapter_matches_in_process_physics(airframe: str) -> None:
    """The fake's controller flies the vehicle through the adapter (leaning first, so that
    the motor order matters) and, separately, against the Fleet in-process with the
    conversions of quadsitl.frames; both settle at 2 m, on the same path, at the hover
    throttle the airframe implies (thrust ∝ throttle²)."""
    spec = get_airframe(airframe)
    physics = JsonPhysics(Fleet(1, airframe, dt=1 / RATE))
    through = HoverController(spec.hover_thrust_fraction, lean=(0.1, -0.1), lean_until=1.0)
    local = HoverController(spec.hover_thrust_fraction, lean=(0.1, -0.1), lean_until=1.0)
    fleet = Fleet(1, airframe, dt=1 / RATE)
    fleet.reset(physics.fleet.state[0], contact=L.ON_GROUND)
    pwm_through = pwm_local = [1000] * 4
    for count in range(10 * RATE):
        k = parse_kinematics(physics.answer({0: frame(count, pwm_through)})[0])
        pwm_through = through(k)
        velocity = fleet.velocity[0].copy()
        omega = [
            spec.max_rotor_speed * (p - PWM_MIN_US) / (PWM_MAX_US - PWM_MIN_US) for p in pwm_local
        ]
        fleet.step(np.array(omega))
        s = fleet.state[0]
        accel = (s[L.VEL] - velocity) / fleet.dt + [0.0, 0.0, spec.gravity]
        mine = (
            frames.enu_to_ned(s[L.POS] - [0, 0, spec.gear_height]),
            frames.quat_enu_flu_to_ned_frd(s[L.QUAT]),
            frames.flu_to_frd(s[L.RATES]),
        )
        # Height held the same to millimetres; the lean's drift (~1 m/s, unchecked by
        # this controller) integrates the replies' rounding, so allow 1 %.
        assert abs(k.position[2] - mine[0][2]) < 3e-3, (count, k.position, mine[0])
        assert np.allclose(k.position[:2], mine[0][:2], rtol=0.01, atol=0.01)
        local_k = k.__class__(
            timestamp=(count + 1) / RATE,
            gyro=tuple(mine[2]),
            accel_body=tuple(
                frames.flu_to_frd(frames.quat_rotate(frames.quat_conjugate(s[L.QUAT]), accel))
            ),
            position=tuple(mine[0]),
            velocity=tuple(frames.enu_to_ned(s[L.VEL])),
            quaternion=tuple(mine[1]),
        )
        pwm_local = local(local_k)
    assert k.position[2] == pytest.approx(-2.0, abs=0.05)
    assert max(abs(v) for v in k.velocity) < 0.05 and max(abs(v) for v in k.gyro) < 0.01
    hover_pwm = PWM_MIN_US + 1000 * math.sqrt(spec.hover_thrust_fraction)
    assert np.allclose(pwm_through, hover_pwm, atol=3)


@pytest.mark.parametrize("airframe", sorted(AIRFRAMES))
def test_the_parameter_file_of_each_preset_agrees_with_its_airframe(airframe: str) -> None:
    path = parameter_file(airframe)
    if airframe in ("paper", "paper-x"):  # the 0.18 s motor: ArduPilot's gains do not fly it
        assert path is None
        return
    assert path is not None and path.parent == PARAMETER_FOLDER
    params = {}
    for line in path.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, value = line.split()
            params[name] = float(value)
    frame_type, _ = motor_channels(get_airframe(airframe))
    assert (params["FRAME_CLASS"], params["FRAME_TYPE"]) == (1, frame_type)
    assert (params["MOT_PWM_MIN"], params["MOT_PWM_MAX"]) == (PWM_MIN_US, PWM_MAX_US)
    assert params["MOT_THST_EXPO"] == 1.0
    assert params["MOT_THST_HOVER"] == pytest.approx(
        get_airframe(airframe).hover_thrust_fraction, abs=0.005
    )
