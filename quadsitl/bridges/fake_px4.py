"""A stand-in for PX4's side of simulator_mavlink, written from its protocol.

For tests and benchmarks where no PX4 build is. :class:`FakePx4` does over real TCP what
PX4's ``SimulatorMavlink.cpp`` does: it connects to port 4560 + instance (trying again
until the simulator listens), sends HEARTBEAT and asks for HIL_STATE_QUATERNION with
SET_MESSAGE_INTERVAL, then answers each HIL_SENSOR with one HIL_ACTUATOR_CONTROLS that
carries the lockstep flag. It keeps everything it was sent (:class:`Received`), and
:func:`problems` checks it as PX4 would read it: units, frames, ``fields_updated``,
rates, and that the readings are noisy. :class:`Px4HoverController` flies a vehicle
through it.
"""

from __future__ import annotations

import itertools
import math
import socket
import statistics
import time
from dataclasses import dataclass, field
from typing import NamedTuple

from quadsitl.bridges.fake_ardupilot import HoverController, Kinematics
from quadsitl.bridges.frame_reader import FrameReader
from quadsitl.bridges.px4_hil import (
    ARMED_FLAG,
    FIELDS_ACCEL,
    FIELDS_BARO,
    FIELDS_GYRO,
    FIELDS_MAG,
    LOCKSTEP_FLAG,
    PORT,
    ROUND_US,
)
from quadsitl.geo import Home
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.units import STANDARD_GRAVITY

STATE_INTERVAL_US = 5_000  # what PX4 asks for HIL_STATE_QUATERNION
MODE_CUSTOM = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, always set in PX4's mode


class HilSensor(NamedTuple):
    time_usec: int
    accel: tuple[float, float, float]  # m/s², body FRD specific force
    gyro: tuple[float, float, float]  # rad/s, body FRD
    mag: tuple[float, float, float]  # gauss, body FRD
    abs_pressure: float  # hPa
    diff_pressure: float  # hPa
    pressure_alt: float  # m
    temperature: float  # °C
    fields_updated: int
    id: int


class HilGps(NamedTuple):
    time_usec: int
    lat: int  # 1e-7 degrees
    lon: int
    alt: int  # mm above mean sea level
    eph: int  # cm
    epv: int
    vel: int  # cm/s
    vn: int
    ve: int
    vd: int
    cog: int  # cdeg
    fix_type: int
    satellites_visible: int


class HilState(NamedTuple):
    time_usec: int
    quaternion: tuple[float, float, float, float]  # (w, x, y, z), body FRD -> NED
    rates: tuple[float, float, float]  # rad/s, body FRD
    lat: int
    lon: int
    alt: int  # mm
    velocity: tuple[int, int, int]  # cm/s, NED
    accel: tuple[int, int, int]  # mG, body FRD


def state_from(v: tuple) -> HilState:
    """A HIL_STATE_QUATERNION's values in wire order as a HilState."""
    return HilState(v[0], v[1:5], v[5:8], v[8], v[9], v[10], v[11:14], v[16:19])


@dataclass
class Received:
    """Everything the simulator sent, in order of arrival."""

    sensors: list[HilSensor] = field(default_factory=list)
    gps: list[HilGps] = field(default_factory=list)
    states: list[HilState] = field(default_factory=list)
    acks: list[tuple[int, int]] = field(default_factory=list)  # (command, result)


class FakePx4:
    """PX4 instance ``instance`` connecting to the simulator over TCP.

    Args:
        instance: PX4's ``-i``: it connects to ``port + instance``.
        connect_timeout: s to keep trying to connect (PX4 tries forever).
        lockstep: whether HIL_ACTUATOR_CONTROLS carries the lockstep flag.
        state_interval_us: asked for HIL_STATE_QUATERNION (None: not asked).
    """

    def __init__(
        self,
        instance: int = 0,
        port: int = PORT,
        host: str = "127.0.0.1",
        connect_timeout: float = 60.0,
        lockstep: bool = True,
        state_interval_us: int | None = STATE_INTERVAL_US,
    ) -> None:
        self.lockstep = lockstep
        deadline = time.monotonic() + connect_timeout
        while True:
            try:
                self.sock = socket.create_connection((host, port + instance), timeout=10.0)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)  # PX4 waits 500 µs; a test has no hurry
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.reader = FrameReader()
        self.received = Received()
        self._pending: list[HilSensor] = []
        self.clock_us = 0  # the time_usec of the last HIL_SENSOR taken (PX4's clock)
        self._seq = 0
        heartbeat = (0, mav.MAV_TYPE_GENERIC, mav.MAV_AUTOPILOT_PX4, 0, 0, 3)
        self._send(mav.MAVLink_heartbeat_message, heartbeat)
        if state_interval_us is not None:
            self.set_message_interval(mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, state_interval_us)

    def set_message_interval(self, message_id: int, interval_us: float) -> None:
        command = (message_id, interval_us, 0, 0, 0, 0, 0, mav.MAV_CMD_SET_MESSAGE_INTERVAL)
        self._send(mav.MAVLink_command_long_message, (*command, 0, 0, 0))

    def send_controls(self, controls: list[float] | tuple[float, ...], armed: bool = True) -> None:
        """One HIL_ACTUATOR_CONTROLS: motors 0.. in [0, 1] (zeros when disarmed, as PX4)."""
        values = [float(c) for c in controls] if armed else [0.0] * len(controls)
        values += [0.0] * (16 - len(values))
        mode = MODE_CUSTOM | (ARMED_FLAG if armed else 0)
        flags = LOCKSTEP_FLAG if self.lockstep else 0
        message = mav.MAVLink_hil_actuator_controls_message
        self._send(message, (self.clock_us, flags, *values, mode))

    def next_sensor(self, timeout: float = 10.0) -> HilSensor:
        """The next HIL_SENSOR (reading and keeping whatever comes before it)."""
        deadline = time.monotonic() + timeout
        while not self._pending:
            try:
                self.receive(max(0.001, deadline - time.monotonic()))
            except TimeoutError:
                raise TimeoutError(f"no HIL_SENSOR within {timeout} s") from None
        sensor = self._pending.pop(0)
        self.clock_us = sensor.time_usec  # PX4's clock in lockstep: its last HIL_SENSOR's
        return sensor

    def receive(self, timeout: float = 10.0) -> None:
        """Take what the next read brings (waiting up to ``timeout`` s for it)."""
        self.sock.settimeout(timeout)
        data = self.sock.recv(65536)
        if not data:
            raise ConnectionError("the simulator closed the connection")
        for frame in self.reader.feed(data):
            self._take(frame)

    def poll(self) -> None:
        """Take whatever the simulator has sent so far, without waiting for more."""
        self.sock.settimeout(0.0)
        try:
            while data := self.sock.recv(65536):
                for frame in self.reader.feed(data):
                    self._take(frame)
        except BlockingIOError:
            pass
        finally:
            self.sock.settimeout(10.0)

    def exchange(self, controls: list[float] | tuple[float, ...]) -> HilSensor:
        """One lockstep round: send ``controls``, return the HIL_SENSOR that answers."""
        self.send_controls(controls)
        return self.next_sensor()

    def _take(self, frame: FC.Frame) -> None:
        v = frame.unpack()
        r = self.received
        if frame.msgid == mav.MAVLINK_MSG_ID_HIL_SENSOR:
            sensor = HilSensor(v[0], v[1:4], v[4:7], v[7:10], *v[10:16])
            r.sensors.append(sensor)
            self._pending.append(sensor)
        elif frame.msgid == mav.MAVLINK_MSG_ID_HIL_GPS:
            r.gps.append(HilGps(*v[:13]))
        elif frame.msgid == mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION:
            r.states.append(state_from(v))
        elif frame.msgid == mav.MAVLINK_MSG_ID_COMMAND_ACK:
            r.acks.append((v[0], v[1]))

    def _send(self, message_class: object, values: tuple) -> None:
        self._seq += 1
        self.sock.sendall(FC.pack(message_class, values, self._seq, 1, 1))

    def close(self) -> None:
        self.sock.close()


def kinematics(state: HilState, home: Home) -> Kinematics:
    """A HIL_STATE_QUATERNION as the kinematics :class:`HoverController` flies on."""
    east, north, up = home.to_local(state.lat * 1e-7, state.lon * 1e-7, state.alt / 1000)
    return Kinematics(
        timestamp=state.time_usec * 1e-6,
        gyro=tuple(state.rates),
        accel_body=tuple(a * STANDARD_GRAVITY / 1000 for a in state.accel),
        position=(north, east, -up),
        velocity=tuple(v / 100 for v in state.velocity),
        quaternion=tuple(state.quaternion),
    )


class Px4HoverController:
    """The fake ArduPilot's hover controller on PX4's wire: it reads the true state
    (HIL_STATE_QUATERNION) and gives motor outputs in [0, 1] in PX4's quad-X order,
    which is ArduPilot's X order."""

    def __init__(self, hover_thrust_fraction: float, home: Home | None = None, **kw: float):
        self.controller = HoverController(hover_thrust_fraction, frame_type=1, **kw)  # type: ignore[arg-type]
        self.home = home or Home()

    def __call__(self, state: HilState) -> list[float]:
        pwm = self.controller(kinematics(state, self.home))
        return [(p - 1000) / 1000 for p in pwm]


def problems(
    received: Received, home: Home, state_interval_us: int = STATE_INTERVAL_US
) -> list[str]:
    """What PX4 would find wrong with what a vehicle at rest on the ground at ``home``,
    nose north, was sent (an empty list: nothing); needs a few simulated seconds."""
    out: list[str] = []
    sensors, gps = received.sensors, received.gps
    if len(sensors) < 500:
        return [f"only {len(sensors)} HIL_SENSOR messages"]
    steps = {b.time_usec - a.time_usec for a, b in itertools.pairwise(sensors)}
    if steps != {ROUND_US}:
        out.append(f"HIL_SENSOR times step by {sorted(steps)} µs, not {ROUND_US}")
    seconds = (sensors[-1].time_usec - sensors[0].time_usec) * 1e-6
    imu = FIELDS_ACCEL | FIELDS_GYRO
    if any(s.fields_updated & imu != imu or s.id != 0 for s in sensors):
        out.append("a HIL_SENSOR without accel and gyro, or not from sensor 0")
    for name, bits, rate in (("magnetometer", FIELDS_MAG, 100), ("barometer", FIELDS_BARO, 50)):
        count = sum(s.fields_updated & bits == bits for s in sensors)
        if abs(count / seconds - rate) > 0.1 * rate:
            out.append(f"{name} updated at {count / seconds:.1f} Hz, not {rate}")
    if any(s.fields_updated & 0b10000000000 for s in sensors):
        out.append("a differential pressure PX4 would use as airspeed")
    for name, values, mean, tolerance, noise in (
        ("accel", [s.accel for s in sensors], (0.0, 0.0, -9.81), 0.05, (1e-3, 0.2)),
        ("gyro", [s.gyro for s in sensors], (0.0, 0.0, 0.0), 0.01, (1e-4, 0.05)),
    ):
        for axis in range(3):
            column = [v[axis] for v in values]
            m, sd = statistics.fmean(column), statistics.stdev(column)
            if abs(m - mean[axis]) > tolerance or not noise[0] < sd < noise[1]:
                out.append(f"{name}[{axis}] mean {m:.4f} σ {sd:.5f}: not {mean[axis]} ± noise")
    fresh_mag = [s.mag for s in sensors if s.fields_updated & FIELDS_MAG]
    north, east, down = (statistics.fmean(m[i] for m in fresh_mag) for i in range(3))
    strength = math.sqrt(north**2 + east**2 + down**2)
    if not (0.25 < strength < 0.65 and north > 0 and abs(east) < north and down > 0):
        out.append(f"magnetic field (FRD) {north:.3f}, {east:.3f}, {down:.3f} G is not Earth's")
    if statistics.stdev(m[0] for m in fresh_mag) < 1e-4:
        out.append("a magnetometer without noise")
    expected_hpa = 1013.25 * (1 - 2.25577e-5 * home.altitude) ** 5.25588
    baro = [s for s in sensors if s.fields_updated & FIELDS_BARO]
    if abs(statistics.fmean(s.abs_pressure for s in baro) - expected_hpa) > 2.0:
        out.append(f"pressure {baro[-1].abs_pressure:.1f} hPa, not ~{expected_hpa:.1f} at home")
    if abs(statistics.fmean(s.pressure_alt for s in baro) - home.altitude) > 10:
        out.append(f"pressure altitude {baro[-1].pressure_alt:.1f} m, not ~{home.altitude}")
    if not -40 < baro[-1].temperature < 50:
        out.append(f"temperature {baro[-1].temperature} is not °C")
    if abs(len(gps) / seconds - 10) > 1.5:
        out.append(f"HIL_GPS at {len(gps) / seconds:.1f} Hz, not 10")
    elif gps:
        east, north, up = home.to_local(gps[-1].lat * 1e-7, gps[-1].lon * 1e-7, gps[-1].alt / 1e3)
        if math.hypot(east, north) > 5 or abs(up) > 5:
            out.append(f"HIL_GPS at {east:.1f} m east, {north:.1f} m north, {up:.1f} m up of home")
        if not (gps[-1].fix_type == 3 and gps[-1].satellites_visible >= 6):
            out.append(
                f"HIL_GPS fix {gps[-1].fix_type} with {gps[-1].satellites_visible} satellites"
            )
        if not 10 <= gps[-1].eph <= 500:  # cm: 0.1 .. 5 m
            out.append(f"HIL_GPS eph {gps[-1].eph} is not centimetres of a good fix")
        if len({g.lat for g in gps}) < 2:
            out.append("a GPS without noise")
    expected_states = seconds * 1e6 / state_interval_us
    if abs(len(received.states) - expected_states) > 0.05 * expected_states + 2:
        out.append(f"{len(received.states)} HIL_STATE_QUATERNION, not ~{expected_states:.0f}")
    return out
