"""PX4's simulator_mavlink interface without a PX4: the pure protocol (HilPhysics), the
parameter files, the stream reader, and a closed-loop hover that matches the physics
flown in-process. The wire (a real ``quadsitl sim`` on TCP) is tests/test_px4_tcp.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl import frames
from quadsitl.bridges.fake_px4 import HilState, Px4HoverController, state_from
from quadsitl.bridges.frame_reader import FrameReader
from quadsitl.bridges.notices import Notices
from quadsitl.bridges.px4_airframe import (
    SCRIPT_NAME,
    SHIPPED,
    parameter_folder,
    parameter_script,
    parameters,
)
from quadsitl.bridges.px4_hil import (
    FIELDS_BARO,
    FIELDS_MAG,
    LOCKSTEP_FLAG,
    ROUND_US,
    HilPhysics,
)
from quadsitl.geo import Home
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import AIRFRAMES, get_airframe
from quadsitl.physics.fleet import Fleet
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav


def actuators(controls: list[float], lockstep: bool = True, armed: bool = True) -> FC.Frame:
    values = (0, LOCKSTEP_FLAG if lockstep else 0, *controls, *[0.0] * (16 - len(controls)))
    packed = FC.pack(
        mav.MAVLink_hil_actuator_controls_message, (*values, 129 if armed else 1), 0, 1, 1
    )
    return next(FC.parse(packed))


def received(data: bytes) -> dict[int, list[tuple]]:
    out: dict[int, list[tuple]] = {}
    for frame in FrameReader().feed(data):
        out.setdefault(frame.msgid, []).append(frame.unpack())
    return out


@pytest.mark.parametrize("airframe", sorted(AIRFRAMES))
def test_the_parameter_files_are_the_airframes_geometry(airframe: str) -> None:
    """The shipped px4-rc.params is what the code derives from the preset (so that it
    cannot drift), and its geometry is the airframe's in PX4's frame and signs."""
    folder = parameter_folder(airframe)
    if airframe not in SHIPPED:  # 0.18 s motors: PX4's stock gains do not fly them
        assert folder is None
        return
    assert folder is not None
    assert (folder / SCRIPT_NAME).read_text() == parameter_script(airframe)
    spec = get_airframe(airframe)
    values = dict(parameters(spec))
    for i, ((x, y), spin) in enumerate(zip(spec.rotor_xy, spec.rotor_yaw_sign, strict=True)):
        assert values[f"CA_ROTOR{i}_PX"] == pytest.approx(x * spec.arm_length, abs=1e-4)
        assert values[f"CA_ROTOR{i}_PY"] == pytest.approx(-y * spec.arm_length, abs=1e-4)  # FRD
        assert math.copysign(1, values[f"CA_ROTOR{i}_KM"]) == -spin  # + counter-clockwise
    assert values["MPC_THR_HOVER"] == pytest.approx(spec.hover_thrust_fraction, abs=1e-3)
    assert values["THR_MDL_FAC"] == 1.0 and values["COM_CPU_MAX"] == -1


def test_iris_is_px4s_quad_x_motor_order() -> None:
    """PX4's quad X (none_iris): motor 0 front right CCW, 1 back left CCW, 2 front left
    CW, 3 back right CW."""
    values = dict(parameters(get_airframe("iris")))
    expected = [(1, 1, 1), (-1, -1, 1), (1, -1, -1), (-1, 1, -1)]  # sign of PX, PY, KM
    for i, signs in enumerate(expected):
        got = tuple(math.copysign(1, values[f"CA_ROTOR{i}_{k}"]) for k in ("PX", "PY", "KM"))
        assert got == signs


@pytest.mark.parametrize("motor", range(4))
def test_each_px4_motor_turns_the_vehicle_as_its_ca_rotor_geometry_says(motor: int) -> None:
    """Motor k above the others: the vehicle rolls and pitches away from rotor k's CA_ROTOR
    position (FRD) and yaws against its spin: PX4's moment is +KM·thrust about z down."""
    spec = get_airframe("iris")
    physics = HilPhysics(Fleet(1, "iris"), noise_scale=0.0)
    physics.connect(0)
    values = dict(parameters(spec))
    hover = math.sqrt(spec.hover_thrust_fraction)
    for _ in range(100):  # lift off
        physics.answer({0: [actuators([hover * 1.05] * 4)]})
    controls = [hover] * 4
    controls[motor] = hover * 1.1
    for _ in range(10):
        out = physics.answer({0: [actuators(controls)]})
    p, q, r = received(out[0])[mav.MAVLINK_MSG_ID_HIL_SENSOR][-1][4:7]  # gyro, FRD
    px, py, km = (values[f"CA_ROTOR{motor}_{k}"] for k in ("PX", "PY", "KM"))
    assert math.copysign(1, p) == -math.copysign(1, py)  # right rotor up: roll left (−)
    assert math.copysign(1, q) == math.copysign(1, px)  # front rotor up: pitch up (+)
    assert math.copysign(1, r) == math.copysign(1, km)  # CCW rotor: body yaws clockwise (+)


def test_lockstep_starts_with_the_flag_and_each_actuator_message_is_one_round() -> None:
    physics = HilPhysics(Fleet(2, "iris"), notice=lambda _: None)
    physics.connect(0)
    physics.connect(1)
    assert physics.waiting_for_clock() == [0, 1]
    physics.tick([0, 1])
    out = physics.answer({0: [actuators([0.0] * 4, lockstep=False)]})
    assert out == {} and physics.waiting_for_clock() == [0, 1]  # not lockstep: no round
    out = physics.answer({0: [actuators([0.0] * 4)], 1: []})
    assert list(out) == [0] and physics.waiting_for_clock() == [1]
    times = [v[0] for v in received(out[0])[mav.MAVLINK_MSG_ID_HIL_SENSOR]]
    assert times == [2 * ROUND_US]
    out = physics.answer({0: [actuators([0.0] * 4), actuators([0.0] * 4)]})  # two: two rounds
    times = [v[0] for v in received(out[0])[mav.MAVLINK_MSG_ID_HIL_SENSOR]]
    assert times == [3 * ROUND_US, 4 * ROUND_US]
    assert physics.peers[1].time_us == ROUND_US  # the other vehicle did not move


def test_set_message_interval_is_honoured_and_acknowledged() -> None:
    physics = HilPhysics(Fleet(1, "iris"), notice=lambda _: None)
    physics.connect(0)

    def command(msgid: int, interval: float) -> FC.Frame:
        values = (msgid, interval, 0, 0, 0, 0, 0, mav.MAV_CMD_SET_MESSAGE_INTERVAL, 0, 0, 0)
        return next(FC.parse(FC.pack(mav.MAVLink_command_long_message, values, 0, 1, 1)))

    def states_in(rounds: int) -> int:
        data = b"".join(physics.answer({0: [actuators([0.0] * 4)]})[0] for _ in range(rounds))
        return len(received(data).get(mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, []))

    out = physics.answer({0: [command(mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, 5000)]})
    assert received(out[0])[mav.MAVLINK_MSG_ID_COMMAND_ACK][0][:2] == (
        mav.MAV_CMD_SET_MESSAGE_INTERVAL,
        mav.MAV_RESULT_ACCEPTED,
    )
    assert states_in(250) == pytest.approx(200, abs=1)  # 1 s at 5 ms
    physics.answer({0: [command(mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, -1)]})
    assert states_in(250) == 0
    out = physics.answer({0: [command(mav.MAVLINK_MSG_ID_ATTITUDE, 5000)]})
    assert received(out[0])[mav.MAVLINK_MSG_ID_COMMAND_ACK][0][1] == mav.MAV_RESULT_UNSUPPORTED


def test_sensor_rates_and_fields_updated_follow_the_sensor_models() -> None:
    physics = HilPhysics(Fleet(1, "iris"), notice=lambda _: None)
    physics.connect(0)
    data = b"".join(physics.answer({0: [actuators([0.0] * 4)]})[0] for _ in range(2500))
    got = received(data)
    sensors = got[mav.MAVLINK_MSG_ID_HIL_SENSOR]
    mags = sum(v[14] & FIELDS_MAG == FIELDS_MAG for v in sensors)
    baros = sum(v[14] & FIELDS_BARO == FIELDS_BARO for v in sensors)
    assert len(sensors) == 2500  # 10 s at 250 Hz; in it, the magnetometer's 100 Hz and the
    assert (mags, baros) == (1001, 501)  # barometer's 50 Hz, and the first message has both
    assert len(got[mav.MAVLINK_MSG_ID_HIL_GPS]) == pytest.approx(100, abs=2)  # 10 Hz


def test_a_motor_output_that_is_not_a_number_is_off_and_said_once() -> None:
    said: list[str] = []
    physics = HilPhysics(Fleet(1, "iris"), notice=said.append)
    physics.connect(0)
    for _ in range(3):
        physics.answer({0: [actuators([math.nan, 0.5, 0.5, 0.5])]})
    assert physics.fleet.state[0, L.I_ROTOR0] == 0.0
    assert sum("not a number" in s for s in said) == 1


def test_the_stream_reader_finds_frames_split_anywhere_and_skips_garbage() -> None:
    frame = FC.pack(mav.MAVLink_heartbeat_message, (0, 2, 12, 0, 0, 3), 7, 1, 1)
    damaged = b"\xfd\x01" + bytes(11)  # a frame's start, length and size, a wrong CRC
    stream = b"\x00junk" + frame + damaged + frame
    reader = FrameReader()
    found = []
    for i in range(0, len(stream), 3):
        found += reader.feed(stream[i : i + 3])
    assert [f.msgid for f in found] == [0, 0]
    assert reader.skipped > 0


@pytest.mark.parametrize("airframe", ["iris", "paper-x-fast"])
def test_closed_loop_hover_through_the_adapter_matches_in_process_physics(airframe: str) -> None:
    """The fake's controller flies the vehicle through the adapter on the true state it is
    sent (HIL_STATE_QUATERNION at every round), leaning first so that the motor order
    matters, and the same controller flies the Fleet in-process: both settle at 2 m, on
    the same path within the wire's rounding, at u = √(hover thrust fraction)."""
    spec, home = get_airframe(airframe), Home()
    physics = HilPhysics(Fleet(1, airframe), notice=lambda _: None)
    physics.connect(0)
    kw = {"lean": (0.1, -0.1), "lean_until": 1.0}
    through = Px4HoverController(spec.hover_thrust_fraction, home, **kw)
    local = Px4HoverController(spec.hover_thrust_fraction, home, **kw)
    fleet = Fleet(1, airframe, dt=physics.fleet.dt)
    fleet.reset(physics.fleet.state[0], contact=L.ON_GROUND)
    physics.peers[0].state_interval_us = ROUND_US
    u_through = u_local = [0.0] * 4
    for k in range(10 * 250):
        got = received(physics.answer({0: [actuators(u_through)]})[0])
        state = state_from(got[mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION][-1])
        u_through = through(state)
        fleet.step(np.array(u_local) * spec.max_rotor_speed, 4)
        s = fleet.state[0]
        lat, lon, alt = home.to_global(s[0], s[1], s[2] - spec.gear_height)
        mine = HilState(
            (k + 1) * ROUND_US,
            tuple(frames.quat_enu_flu_to_ned_frd(s[L.QUAT])),
            tuple(frames.flu_to_frd(s[L.RATES])),
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            tuple(round(v * 100) for v in frames.enu_to_ned(s[L.VEL])),
            (0, 0, 0),
        )
        u_local = local(mine)
        assert abs(state.alt - mine.alt) < 20, (k, state, mine)  # mm
    assert state.alt / 1000 - home.altitude == pytest.approx(2.0, abs=0.05)
    assert max(abs(v) for v in state.velocity) <= 3  # cm/s
    assert np.allclose(u_through, math.sqrt(spec.hover_thrust_fraction), atol=0.005)
    assert np.allclose(u_local, u_through, atol=0.005)


def test_notices_are_said_once_per_interval_by_kind_and_the_rest_counted() -> None:
    """A kind of notice about one vehicle is said once per interval, whatever numbers its
    text holds; the rest are counted and said with the next line of that kind, or when
    the vehicle's peer goes. Other kinds and other vehicles have their own."""
    said: list[str] = []
    now = [0.0]
    notices = Notices(said.append, interval=10.0, clock=lambda: now[0])
    for i in range(1000):
        notices(0, "refused commands", f"command {i}: refused")
    notices(0, "bad outputs", "a bad output")
    notices(1, "refused commands", "command 5: refused")
    assert said == [
        "vehicle 0: command 0: refused",
        "vehicle 0: a bad output",
        "vehicle 1: command 5: refused",
    ]
    now[0] = 10.0
    notices(0, "refused commands", "command 1000: refused")
    assert said[-1] == (
        "vehicle 0: command 1000: refused (999 more refused commands in the last 10 s)"
    )
    notices(0, "refused commands", "command 1001: refused")
    notices.flush(0)
    assert said[4:] == ["vehicle 0: 1 more refused commands were not shown"]
    notices.flush()
    assert len(said) == 5  # nothing more was held back
    notices(0, "refused commands", "command 1002: refused")  # a new peer: said again
    assert said[-1] == "vehicle 0: command 1002: refused"


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # numpy's, about the sensors' NaN
@pytest.mark.parametrize("value", [1e9, -1e30, math.inf, math.nan])
def test_a_physics_value_beyond_the_wire_is_clamped_never_an_error_nor_nan(value: float) -> None:
    """A vehicle whose state is out of this world (blown away by a 1e9 m/s wind, or NaN)
    is still sent to PX4: every field of HIL_SENSOR, HIL_GPS and HIL_STATE_QUATERNION
    within its wire type and finite, never a struct.error."""
    physics = HilPhysics(Fleet(1, "iris"), notice=lambda _: None)
    physics.connect(0)
    physics.peers[0].state_interval_us = ROUND_US
    data = b""
    for _ in range(60):  # 0.24 s: GPS fixes 120 ms late among them
        physics.fleet.state[0, : L.I_ROTOR0] = value
        data += physics.answer({0: [actuators([0.5] * 4)]})[0]
    got = received(data)
    for msgid in (
        mav.MAVLINK_MSG_ID_HIL_SENSOR,
        mav.MAVLINK_MSG_ID_HIL_GPS,
        mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION,
    ):
        assert got[msgid], msgid
        assert all(math.isfinite(v) for values in got[msgid] for v in values), msgid
