"""A stand-in for ArduPilot's side of the JSON interface, written from its protocol.

For tests and benchmarks where no ArduPilot binary is. :class:`FakeArduPilot` sends servo
frames over real UDP as ArduCopter's SITL does (``libraries/SITL/SIM_JSON.cpp``): a frame
rate (1,200 Hz by default), a frame count that goes up by one per answered frame, the same
frame sent again when no answer comes within a timeout, and a count from 0 again after a
:meth:`~FakeArduPilot.restart`. It reads the answers with ArduPilot's own rules
(:func:`parse_kinematics`), so a reply it accepts is one ArduPilot accepts.
:class:`HoverController` is a small altitude and attitude controller that flies a vehicle
through it, mixing as ArduPilot's quad frames do.
"""

from __future__ import annotations

import math
import re
import select
import socket
import time
from typing import Any, NamedTuple

from quadsitl.bridges.ardupilot_json import (
    ARDUPILOT_QUAD_FRAMES,
    PORT,
    PWM_MAX_US,
    PWM_MIN_US,
    ServoFrame,
    encode_servo_packet,
)

FRAME_RATE = 1200  # Hz, ArduCopter's SIM_RATE_HZ
POLL = 200e-6  # s, longest poll for an answer before sleeping (``poll=True``)
RESEND_AFTER = 1.0  # s without an answer before ArduPilot sends the same frame again


class Kinematics(NamedTuple):
    """One answer, as ArduPilot reads it."""

    timestamp: float  # s
    gyro: tuple[float, ...]  # rad/s, body FRD
    accel_body: tuple[float, ...]  # m/s², body FRD specific force
    position: tuple[float, ...]  # m, NED
    velocity: tuple[float, ...]  # m/s, NED
    quaternion: tuple[float, ...]  # (w, x, y, z), body FRD -> world NED


class ReplyError(ValueError):
    """An answer ArduPilot would not use (the message is the one it prints)."""


# C's atof: leading whitespace, then the longest number (0 when there is none).
_ATOF = re.compile(
    r"\s*([+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf(?:inity)?|nan))", re.IGNORECASE
)
# sscanf's %f: whitespace skipped, then a number (a conversion that fails ends the scan).
_FLOAT = r"\s*([+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|inf(?:inity)?|nan))"
# "[%f, %f, %f]" and "[%f, %f, %f, %f]": the '[' and each ',' literally, then a format
# space, which matches any whitespace including none.
_VECTORS = {n: re.compile(r"\[" + _FLOAT + (r",\s*" + _FLOAT) * (n - 1), re.I) for n in (3, 4)}
# (section, key, values) of the fields quadsitl sends, all of which ArduPilot needs.
_FIELDS = (
    ("", "timestamp", 1),
    ("imu", "gyro", 3),
    ("imu", "accel_body", 3),
    ("", "position", 3),
    ("", "velocity", 3),
    ("", "quaternion", 4),
)


def parse_kinematics(data: bytes) -> Kinematics:
    """The answer in ``data`` read as ``SIM_JSON.cpp`` reads it; ReplyError if it would fail.

    Newlines become NULs and only the text between the last two is read, so the line must
    start and end with a newline. Each field is found with ``strstr``: the section, then
    the key after it; the value starts two characters after the key (``":``) and is read
    by ``atof`` or by ``sscanf("[%f, %f, %f]")``, which needs the ``[`` right there.
    """
    text = data.replace(b"\n", b"\0")
    end = text.rfind(b"\0")
    start = text.rfind(b"\0", 0, end) if end > 0 else -1
    if start < 0:
        raise ReplyError("no line between two newlines")
    json = text[start + 1 : end].decode("ascii", "replace")
    values: list[Any] = []
    for section, key, size in _FIELDS:
        p = json.find(section)
        if p < 0:
            raise ReplyError(f"Failed to find {section}")
        p = json.find(key, p + len(section) + 1)
        if p < 0:
            raise ReplyError(f"Failed to find key {section}/{key}")
        p += len(key) + 2
        if size == 1:
            number = _ATOF.match(json, p)
            values.append(float(number.group(1)) if number else 0.0)
            continue
        vector = _VECTORS[size].match(json, p)
        if vector is None:
            raise ReplyError(f"Failed to parse Vector{size}f for {section}/{key}")
        values.append(tuple(map(float, vector.groups())))
    return Kinematics(*values)


class FakeArduPilot:
    """ArduPilot instance ``instance`` sending servo frames to the physics over UDP.

    Args:
        instance: ArduPilot's ``-I``: the physics listens on ``port + 10 instance``.
        frame_rate: Hz, the frames' ``frame_rate``.
        channels: 16 or 32 (``SERVO_32_ENABLE``).
        resend_after: s to wait for an answer before sending the same frame again.
        poll: wait for each answer by polling the socket rather than asleep, as a peer
            with no wake-up latency: benchmarks use it to time the physics' side alone.
    """

    def __init__(
        self,
        instance: int = 0,
        port: int = PORT,
        host: str = "127.0.0.1",
        frame_rate: int = FRAME_RATE,
        channels: int = 16,
        resend_after: float = RESEND_AFTER,
        poll: bool = False,
    ) -> None:
        self.target = (host, port + 10 * instance)
        self.frame_rate, self.channels = frame_rate, channels
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))  # an ephemeral port, as ArduPilot's
        self.sock.settimeout(0.0 if poll else resend_after)
        self.resend_after, self.poll = resend_after, poll
        self.frame_count = 0  # of the next frame
        self.resends = 0  # frames sent again after a timeout
        self.stale = 0  # second answers to a frame sent again, dropped
        self.last_timestamp: float | None = None  # s, of the last answer taken
        self._packet = b""

    def send(self, pwm: tuple[int, ...] | list[int]) -> None:
        """Send the next frame: outputs ``pwm`` (µs, channel 1 first; the rest 0)."""
        outputs = tuple(int(v) for v in pwm) + (0,) * (self.channels - len(pwm))
        frame = ServoFrame(self.frame_rate, self.frame_count, outputs)
        self._packet = encode_servo_packet(frame)
        self.sock.sendto(self._packet, self.target)

    def receive(self, attempts: int = 10) -> Kinematics:
        """Wait for the answer, sending the frame again after each timeout (up to
        ``attempts`` waits; TimeoutError after them); the count moves on once answered.

        An answer with the last answer's timestamp is a second answer to a frame sent
        again (on a busy machine the first can come after the re-send): it is dropped
        and counted in ``stale``, so that it is not taken for this frame's answer."""
        waits = 0
        while waits < attempts:
            try:
                data = self._poll() if self.poll else self.sock.recv(65536)
            except TimeoutError:
                waits += 1
                self.resends += 1
                self.sock.sendto(self._packet, self.target)
                continue
            kinematics = parse_kinematics(data)
            if kinematics.timestamp == self.last_timestamp:
                self.stale += 1
                continue
            self.last_timestamp = kinematics.timestamp
            self.frame_count += 1
            return kinematics
        raise TimeoutError(f"no answer from {self.target} to frame {self.frame_count}")

    def _poll(self) -> bytes:
        """The next datagram: polled for up to POLL s, then waited for asleep, up to
        ``resend_after`` s in all (TimeoutError after): on a machine with a core to spare
        no wake-up is waited for, on a busy one the simulator still gets the core."""
        start = time.perf_counter()
        while True:
            try:
                return self.sock.recv(65536)
            except BlockingIOError:
                if time.perf_counter() - start > POLL:
                    break
        left = self.resend_after - (time.perf_counter() - start)
        if left > 0 and select.select([self.sock], [], [], left)[0]:
            return self.sock.recv(65536)
        raise TimeoutError

    def exchange(self, pwm: tuple[int, ...] | list[int]) -> Kinematics:
        """One lockstep frame: send ``pwm``, return the answer."""
        self.send(pwm)
        return self.receive()

    def restart(self) -> None:
        """As ArduPilot restarted: the frame count starts from 0 again."""
        self.frame_count = 0
        self.last_timestamp = None

    def close(self) -> None:
        self.sock.close()


def euler_ned(q: tuple[float, ...]) -> tuple[float, float, float]:
    """(roll, pitch, yaw) rad of attitude ``q`` (w, x, y, z), FRD -> NED, Z-Y-X."""
    w, x, y, z = q
    return (
        math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
        math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x)))),
        math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)),
    )


class HoverController:
    """Climb to ``altitude`` m and hover: a PID on height, PD on roll and pitch leaning
    against the horizontal velocity, D on yaw, mixed into four motors as ArduPilot mixes
    ``frame_type`` (1 X, 6 PLUSREV).
    ``lean`` (roll, pitch) is held instead until ``lean_until`` s, to show that
    each motor turns the vehicle the way ArduPilot expects.

    Thrust is linear in throttle² (``MOT_THST_EXPO 1``), so a motor asked for thrust
    fraction t gets throttle √t; ``hover_thrust_fraction`` is the airframe's."""

    def __init__(
        self,
        hover_thrust_fraction: float,
        frame_type: int = 1,
        altitude: float = 2.0,
        gravity: float = 9.81,
        lean: tuple[float, float] = (0.0, 0.0),
        lean_until: float = 0.0,
    ) -> None:
        self.hover, self.altitude, self.gravity = hover_thrust_fraction, altitude, gravity
        self.lean, self.lean_until = lean, lean_until  # rad (roll, pitch) held until s
        _, motors = ARDUPILOT_QUAD_FRAMES[frame_type]
        # ArduPilot's factors: roll cos(angle + 90°), pitch cos(angle), yaw ±1.
        self.mix = [
            (math.cos(math.radians(a + 90.0)), math.cos(math.radians(a)), spin)
            for a, spin in motors
        ]
        self.integral = 0.0  # m·s, of the height error
        self.last_time: float | None = None

    def __call__(self, k: Kinematics) -> list[int]:
        """PWM (µs) of motors 1..4 for the vehicle's state ``k``."""
        dt = 0.0 if self.last_time is None else max(0.0, k.timestamp - self.last_time)
        self.last_time = k.timestamp
        roll, pitch, yaw = euler_ned(k.quaternion)
        p, q, r = k.gyro
        error = self.altitude - (-k.position[2])  # m, height above the start
        self.integral = max(-2.0, min(2.0, self.integral + error * dt))
        up_accel = 2.0 * error - 2.5 * (-k.velocity[2]) + 0.5 * self.integral  # m/s²
        tilt = max(0.5, math.cos(roll) * math.cos(pitch))
        collective = self.hover * (1.0 + up_accel / self.gravity) / tilt
        if k.timestamp < self.lean_until:
            lean_roll, lean_pitch = self.lean
        else:  # lean against the horizontal velocity (forward, right) until it stops
            north, east = k.velocity[0], k.velocity[1]
            forward = north * math.cos(yaw) + east * math.sin(yaw)
            right = -north * math.sin(yaw) + east * math.cos(yaw)
            lean_roll = max(-0.2, min(0.2, -0.1 * right))
            lean_pitch = max(-0.2, min(0.2, 0.1 * forward))
        roll_out = 0.25 * (lean_roll - roll) - 0.03 * p  # fractions of a motor's full thrust
        pitch_out = 0.25 * (lean_pitch - pitch) - 0.03 * q
        yaw_out = -0.05 * r
        pwm = []
        for roll_factor, pitch_factor, yaw_factor in self.mix:
            thrust = collective + roll_out * roll_factor + pitch_out * pitch_factor
            thrust += yaw_out * yaw_factor
            level = math.sqrt(min(1.0, max(0.0, thrust)))
            pwm.append(round(PWM_MIN_US + (PWM_MAX_US - PWM_MIN_US) * level))
        return pwm
