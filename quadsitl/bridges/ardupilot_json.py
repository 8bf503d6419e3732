"""ArduPilot's JSON physics interface (``arducopter --model JSON``), without sockets.

ArduPilot sends a binary servo frame and blocks until the physics answers with one line of
JSON, so the physics steps exactly once per frame (lockstep). This module holds the
protocol as ArduPilot's ``libraries/SITL/SIM_JSON.{h,cpp}`` defines it, and
:class:`JsonPhysics`, which answers the frames of N ArduPilot instances on one batched
:class:`~quadsitl.physics.fleet.Fleet`. The UDP side is :mod:`.ardupilot_udp`.

Servo frame, little-endian: ``uint16 magic, uint16 frame_rate (Hz), uint32 frame_count,
uint16 pwm[16 or 32] (µs)``; magic 18458 with 16 channels (40 bytes), 29569 with 32
(72 bytes, ``SERVO_32_ENABLE 1``).

Reply: one compact JSON object between newlines. ArduPilot's parser is ``strstr`` and
``sscanf``: ``"key":`` must be followed by the value itself (``"gyro":[1,2,3]``; a space
after the colon breaks the arrays), so the line is written by a fixed format string.
Units and frames: ``timestamp`` s (absolute physics time of this vehicle), ``imu.gyro``
rad/s body FRD, ``imu.accel_body`` m/s² body FRD specific force ((0, 0, −g) at rest),
``position`` m NED from where the vehicle started, ``velocity`` m/s NED, ``quaternion``
(w, x, y, z) body FRD -> world NED.

Long frames: a frame of 1/frame_rate s longer than MAX_STEP (ArduPilot's SIM_RATE_HZ may be as
low as 1 Hz) is flown in equal sub-steps of at most MAX_STEP: one RK4 step of a second
diverges. No reply carries a number that is not finite or beyond REPLY_LIMIT in magnitude.

Motors: ArduPilot's motor i drives the airframe rotor at the same bearing with the same
spin (:func:`motor_channels`); Ω_c = Ω_max · clip((pwm − 1000 µs) / 1000 µs, 0, 1), so that
thrust ∝ throttle², which is ArduPilot's ``MOT_THST_EXPO 1``.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from quadsitl.bridges.lockstep import step_vehicles
from quadsitl.bridges.notices import Notices
from quadsitl.frames import NORTH_YAW_ENU
from quadsitl.physics import layout as L
from quadsitl.physics.airframe import Airframe
from quadsitl.physics.fleet import Fleet, initial_state
from quadsitl.wire.units import rotor_speed

SERVO_MAGIC_16 = 18458  # 16 channels
SERVO_MAGIC_32 = 29569  # 32 channels (SERVO_32_ENABLE 1)
_HEADER = struct.Struct("<HHI")  # magic, frame_rate (Hz), frame_count
_CHANNELS = {SERVO_MAGIC_16: 16, SERVO_MAGIC_32: 32}
_PWM = {n: struct.Struct(f"<{n}H") for n in _CHANNELS.values()}
PACKET_SIZES = {magic: _HEADER.size + 2 * n for magic, n in _CHANNELS.items()}  # 40, 72 bytes
PWM_MIN_US, PWM_MAX_US = 1000.0, 2000.0  # the parameter files' MOT_PWM_MIN / MOT_PWM_MAX
PORT = 9002  # UDP port of instance 0 (ArduPilot's default); instance i: PORT + 10 i
PORT_STRIDE = 10
# s, the longest physics step: 1/400 s, ArduCopter's main loop rate, which ArduPilot asks
# SIM_RATE_HZ to stay above; frames at 400 Hz and faster are one step each.
MAX_STEP = 1 / 400
# The largest magnitude a reply's field may carry (m, m/s, m/s², rad/s): what is beyond, or
# not a number, is replaced (NaN by 0, the rest clamped) and said; the timestamp is exempt.
REPLY_LIMIT = 1e6
_SQRT_HALF = math.sqrt(0.5)

# ArduPilot's quad frames (libraries/AP_Motors/AP_MotorsMatrix.cpp): motor i (output
# channel i + 1) at bearing degrees clockwise from the nose, and its spin seen from above
# (+1 counter-clockwise, ArduPilot's AP_MOTORS_MATRIX_YAW_FACTOR_CCW; −1 clockwise).
ARDUPILOT_QUAD_FRAMES: dict[int, tuple[str, tuple[tuple[float, int], ...]]] = {
    1: ("X", ((45.0, 1), (-135.0, 1), (-45.0, -1), (135.0, -1))),
    6: ("PLUSREV", ((90.0, -1), (-90.0, -1), (0.0, 1), (180.0, 1))),
}
FRAME_CLASS_QUAD = 1
_BEARING_TOLERANCE = 30.0  # degrees between a motor's and a rotor's bearing to match

# The reply, as SIM_JSON.cpp parses it: no whitespace, a newline before and after.
_REPLY = (
    '\n{"timestamp":%.9f,"imu":{"gyro":[%.7f,%.7f,%.7f],"accel_body":[%.6f,%.6f,%.6f]},'
    '"position":[%.6f,%.6f,%.6f],"velocity":[%.6f,%.6f,%.6f],'
    '"quaternion":[%.8f,%.8f,%.8f,%.8f]}\n'
)


class PacketError(ValueError):
    """A datagram that is not an ArduPilot servo frame (the message says why, in one line;
    ``kind`` names the fault with a fixed phrase, for rate-limited notices)."""

    def __init__(self, kind: str, text: str) -> None:
        super().__init__(text)
        self.kind = kind


@dataclass(frozen=True)
class ServoFrame:
    """One ArduPilot servo frame."""

    frame_rate: int  # Hz: the frame asks for 1/frame_rate s of physics
    frame_count: int  # counts up from 0 at ArduPilot's start; the same count is a re-send
    pwm: tuple[int, ...]  # µs, output channels 1..16 (or 1..32)


def parse_servo_packet(data: bytes) -> ServoFrame:
    """The servo frame in ``data``; PacketError when the magic or the size is wrong."""
    if len(data) < _HEADER.size:
        raise PacketError(
            "datagrams too short", f"a {len(data)}-byte datagram is too short for a servo frame"
        )
    magic, frame_rate, frame_count = _HEADER.unpack_from(data)
    channels = _CHANNELS.get(magic)
    if channels is None:
        raise PacketError(
            "datagrams of unknown magic",
            f"magic {magic} is not a servo frame's ({SERVO_MAGIC_16} or {SERVO_MAGIC_32})",
        )
    if len(data) != PACKET_SIZES[magic]:
        raise PacketError(
            "datagrams of the wrong size",
            f"a servo frame with magic {magic} has {PACKET_SIZES[magic]} bytes, got {len(data)}",
        )
    if frame_rate == 0:
        raise PacketError("frames with frame rate 0", "a servo frame with frame_rate 0")
    return ServoFrame(frame_rate, frame_count, _PWM[channels].unpack_from(data, _HEADER.size))


def encode_servo_packet(frame: ServoFrame) -> bytes:
    """The datagram ArduPilot sends for ``frame`` (16 or 32 channels by its length)."""
    magic = SERVO_MAGIC_32 if len(frame.pwm) == 32 else SERVO_MAGIC_16
    pwm = _PWM[_CHANNELS[magic]].pack(*frame.pwm)
    return _HEADER.pack(magic, frame.frame_rate, frame.frame_count) + pwm


def motor_channels(airframe: Airframe) -> tuple[int, tuple[int, int, int, int]]:
    """(FRAME_TYPE, channel index 0.. driving each rotor) of the ArduPilot quad frame whose
    motors sit at the airframe's rotor bearings with the same spin; ValueError if none.

    A rotor's spin follows its reaction torque: ``rotor_yaw_sign`` −1 (torque −z) is a
    rotor turning counter-clockwise seen from above."""
    for frame_type, (_, motors) in ARDUPILOT_QUAD_FRAMES.items():
        channels = []
        for (x, y), sign in zip(airframe.rotor_xy, airframe.rotor_yaw_sign, strict=True):
            bearing = math.degrees(math.atan2(-y, x))  # clockwise from the nose (FLU y left)
            match = [
                k
                for k, (angle, spin) in enumerate(motors)
                if spin == -sign
                and abs((bearing - angle + 180.0) % 360.0 - 180.0) < _BEARING_TOLERANCE
            ]
            if len(match) != 1:
                break
            channels.append(match[0])
        if len(channels) == L.N_ROTORS and len(set(channels)) == L.N_ROTORS:
            return frame_type, (channels[0], channels[1], channels[2], channels[3])
    raise ValueError(
        f"airframe {airframe.name!r} matches no ArduPilot quad frame "
        f"({', '.join(name for name, _ in ARDUPILOT_QUAD_FRAMES.values())})"
    )


def throttle(pwm_us: float) -> float:
    """Motor throttle in [0, 1] of an output in µs (MOT_PWM_MIN 1000 … MOT_PWM_MAX 2000)."""
    return min(1.0, max(0.0, (pwm_us - PWM_MIN_US) / (PWM_MAX_US - PWM_MIN_US)))


def kinematics_line(
    time_s: float,
    state: list[float],
    previous_velocity: tuple[float, float, float],
    dt: float,
    gravity: float,
    gear_height: float,
) -> tuple[bytes, bool]:
    """The reply for one vehicle after a step of ``dt`` s, and whether a value had to be
    replaced (not finite, or beyond REPLY_LIMIT: see :func:`in_range`).

    ``state``: the vehicle's state row as floats (layout: world ENU, body FLU);
    ``previous_velocity``: m/s ENU before the step. The specific force is the step's
    mean acceleration minus gravity, rotated into the body, so that it holds the ground's
    push as well as thrust and drag. Conversions to NED/FRD are those of
    :mod:`quadsitl.frames`, written out in scalars for speed.
    """
    px, py, pz, vx, vy, vz, w, x, y, z, wx, wy, wz = state[: L.I_ROTOR0]
    # Specific force, world ENU: (v − v₀)/dt + (0, 0, g); into the body by the conjugate
    # attitude: f + 2w (u × f) + 2 u × (u × f) with u = −(x, y, z).
    fx = (vx - previous_velocity[0]) / dt
    fy = (vy - previous_velocity[1]) / dt
    fz = (vz - previous_velocity[2]) / dt + gravity
    tx, ty, tz = 2 * (z * fy - y * fz), 2 * (x * fz - z * fx), 2 * (y * fx - x * fy)
    bx = fx + w * tx - y * tz + z * ty
    by = fy + w * ty - z * tx + x * tz
    bz = fz + w * tz - x * ty + y * tx
    h = _SQRT_HALF
    values = (
        time_s,
        *(wx, -wy, -wz),  # body rates FLU -> FRD
        *(bx, -by, -bz),  # specific force FLU -> FRD
        *(py, px, gear_height - pz),  # ENU -> NED, from the start point on the ground
        *(vy, vx, -vz),
        *(h * (w + z), h * (x + y), h * (x - y), h * (w - z)),  # FLU->ENU to FRD->NED
    )
    # One C call decides for all but the timestamp: hypot is NaN or inf if any value is,
    # and at least each |value| (the north-east-down height may pass the limit by the
    # gear's height: still finite).
    if math.hypot(wx, wy, wz, bx, by, bz, px, py, pz, vx, vy, vz, w, x, y, z) < REPLY_LIMIT:
        return (_REPLY % values).encode(), False
    clean = (time_s, *in_range(values[1:]))
    return (_REPLY % clean).encode(), clean != values


def in_range(values: tuple[float, ...]) -> tuple[float, ...]:
    """``values`` with NaN replaced by 0 and the rest clamped to ±REPLY_LIMIT: ArduPilot
    reads the reply into floats, and a NaN or an overflow there spreads through its EKF."""
    return tuple(0.0 if math.isnan(v) else max(-REPLY_LIMIT, min(REPLY_LIMIT, v)) for v in values)


@dataclass
class Peer:
    """What the physics remembers of one ArduPilot instance."""

    frame_count: int | None = None  # of the last frame answered
    frame_rate: int | None = None  # Hz, of the last frame answered
    time_s: float = 0.0  # physics time of this vehicle since ArduPilot (re)started
    reply: bytes = b""  # the last answer, sent again for a repeated frame
    frames: int = 0  # frames stepped since this process started


class JsonPhysics:
    """N ArduPilot instances flying one batched Fleet, each in lockstep with its vehicle.

    :meth:`answer` takes the frames that arrived and returns the replies: a new frame
    steps its vehicle by 1/frame_rate (in sub-steps of at most MAX_STEP), a repeated frame
    (same count) is answered again without a step, a count that goes back means ArduPilot
    restarted and puts the vehicle back at rest at its start. Vehicles whose frames arrive
    together step in one batch; the others keep their state.

    Args:
        fleet: the vehicles, one per ArduPilot instance; each starts at rest on the ground.
        notice: where one-line messages go (restarts, rate changes, bad packets), through
            :attr:`notices`, which rate-limits them by kind.
    """

    def __init__(self, fleet: Fleet, notice: Callable[[str], None] = print) -> None:
        self.fleet = fleet
        self.notices = Notices(notice)
        self.frame_types = []
        channels = []
        for airframe in fleet.airframes:
            frame_type, rotor_channels = motor_channels(airframe)
            self.frame_types.append(frame_type)
            channels.append(rotor_channels)
        self.channels = channels  # per vehicle: output channel index of each rotor
        self.peers = [Peer() for _ in range(fleet.n)]
        self._gravity = fleet.params[:, L.P_GRAVITY].tolist()
        self._gear = fleet.params[:, L.P_GEAR_HEIGHT].tolist()
        self._omega_max = fleet.params[:, L.P_OMEGA_MAX].tolist()
        self._commands = np.zeros((fleet.n, L.N_ROTORS))  # rad/s, last rotor commands
        for index in range(fleet.n):
            self._put_on_ground(index)

    def answer(self, frames: Mapping[int, ServoFrame]) -> dict[int, bytes]:
        """Replies to ``frames`` (vehicle index -> its newest frame)."""
        replies: dict[int, bytes] = {}
        due: dict[int, list[int]] = {}  # frame rate -> vehicles to step at it
        for index, frame in frames.items():
            peer = self.peers[index]
            if peer.frame_count is not None:
                if frame.frame_count == peer.frame_count:  # a re-send: our reply was lost
                    replies[index] = peer.reply
                    continue
                if frame.frame_count < peer.frame_count:
                    self.notices(
                        index,
                        "restarts",
                        f"ArduPilot restarted (frame {frame.frame_count} after "
                        f"{peer.frame_count}); the vehicle is back at its start",
                    )
                    self.restart(index)
            if peer.frame_rate is not None and frame.frame_rate != peer.frame_rate:
                self.notices(
                    index,
                    "frame rate changes",
                    f"ArduPilot's frame rate changed mid-flight from {peer.frame_rate} to "
                    f"{frame.frame_rate} Hz (SIM_RATE_HZ); stepping 1/{frame.frame_rate} s "
                    "per frame from now on",
                )
            peer.frame_count, peer.frame_rate = frame.frame_count, frame.frame_rate
            pwm, omega_max = frame.pwm, self._omega_max[index]
            self._commands[index] = [
                rotor_speed(throttle(pwm[channel]), omega_max) for channel in self.channels[index]
            ]
            due.setdefault(frame.frame_rate, []).append(index)
        for rate, rows in due.items():
            replies.update(self._step(rows, 1.0 / rate))
        return replies

    def _step(self, rows: list[int], dt: float) -> dict[int, bytes]:
        """Step vehicles ``rows`` by ``dt`` s (the others keep their state) and answer."""
        fleet = self.fleet
        before = fleet.state[rows, L.I_VX : L.I_VZ + 1].tolist()  # m/s ENU
        substeps = math.ceil(dt / MAX_STEP - 1e-9)  # 1 at 400 Hz and faster
        fleet.dt = dt / substeps  # this Fleet is ours: its steps are the frame's
        step_vehicles(fleet, self._commands, rows, substeps)
        replies = {}
        for index, velocity in zip(rows, before, strict=True):
            peer = self.peers[index]
            peer.time_s += dt
            peer.frames += 1
            peer.reply, replaced = kinematics_line(
                peer.time_s,
                fleet.state[index].tolist(),
                velocity,
                dt,
                self._gravity[index],
                self._gear[index],
            )
            if replaced:
                self.notices(
                    index,
                    "out-of-range replies",
                    f"the physics gave a value that is not finite or beyond ±{REPLY_LIMIT:g} "
                    "(m, m/s, m/s², rad/s); ArduPilot is sent it replaced (NaN by 0, the "
                    "rest clamped)",
                )
            replies[index] = peer.reply
        return replies

    def restart(self, index: int) -> None:
        """Vehicle ``index`` back at its start, its clock at 0: its ArduPilot starts anew."""
        self._put_on_ground(index)
        peer = self.peers[index]
        peer.frame_count = peer.frame_rate = None
        peer.time_s = 0.0

    def _put_on_ground(self, index: int) -> None:
        """Vehicle ``index`` at rest on the ground at its start, nose north, rotors
        stopped."""
        one = np.zeros(self.fleet.n, bool)
        one[index] = True
        # At rest at home, facing north (as PX4's and ArduPilot's own simulators start)
        rest = initial_state(1, position=(0.0, 0.0, self._gear[index]), yaw=NORTH_YAW_ENU)
        self.fleet.reset(rest, contact=L.ON_GROUND, mask=one)
        self._commands[index] = 0.0
