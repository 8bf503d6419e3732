"""PX4's simulator interface (``simulator_mavlink``), without sockets.

PX4 SITL connects to its simulator over TCP (4560 + instance) and speaks MAVLink 2. The
simulator leads: it sends sensor readings, and PX4's clock is the ``time_usec`` of its
HIL_SENSOR. As PX4's ``src/modules/simulation/simulator_mavlink/SimulatorMavlink.cpp``
reads them:

* PX4 -> simulator: HEARTBEAT; COMMAND_LONG MAV_CMD_SET_MESSAGE_INTERVAL for
  HIL_STATE_QUATERNION (5,000 µs); HIL_ACTUATOR_CONTROLS after each output update:
  ``controls[i]`` of motor i in [0, 1] (zeros while disarmed), ``mode`` with 128 set when
  armed, ``flags`` bit 0 set when PX4 runs in lockstep.
* simulator -> PX4: HIL_SENSOR at 250 Hz (body FRD accel m/s² as specific force, gyro
  rad/s, magnetic field gauss, pressure hPa, pressure altitude m, temperature °C;
  ``fields_updated`` names what is new), HIL_GPS at 10 Hz (1e-7 degrees, mm above mean
  sea level, cm/s north-east-down, accuracies in cm), HIL_STATE_QUATERNION (the truth) at
  the interval asked for.

Lockstep, per instance: until its first HIL_ACTUATOR_CONTROLS with the lockstep flag
the vehicle moves on the server's clock (:meth:`HilPhysics.tick`, one 4 ms round per
4 ms of wall time); from then on each HIL_ACTUATOR_CONTROLS steps it by one round and is
answered with the next HIL_SENSOR (:meth:`HilPhysics.answer`). The readings come from
quadsitl's sensor models (:mod:`quadsitl.physics.sensors`), one seeded suite per vehicle.

Motors: PX4's motor i drives the airframe's rotor i, which the parameter file places at
CA_ROTORi (:mod:`.px4_airframe`); Ω_c = Ω_max · clip(u, 0, 1), so thrust ∝ u², PX4's
``THR_MDL_FAC 1``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from quadsitl.bridges.lockstep import step_vehicles
from quadsitl.bridges.notices import Notices
from quadsitl.frames import NORTH_YAW_ENU
from quadsitl.geo import Home
from quadsitl.physics import layout as L
from quadsitl.physics.fleet import Fleet, initial_state
from quadsitl.physics.sensors import GpsParams, SensorParams, SensorSuite
from quadsitl.physics.sensors.suite import specific_force
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.fit import FLOAT32_MAX, wire_int
from quadsitl.wire.lockstep import ARMED_FLAG, LOCKSTEP_FLAG
from quadsitl.wire.units import STANDARD_GRAVITY, rotor_speed

PORT = 4560  # TCP port of instance 0 (PX4's simulator_mavlink default); instance i: + i
ROUND_US = 4_000  # µs of physics per lockstep round: PX4's 250 Hz IMU (IMU_INTEG_RATE)
LINK_PORT = 14580  # PX4 instance i listens for its onboard MAVLink link on 14580 + i ...
PEER_PORT = 14540  # ... and sends to 14540 + i (px4-rc.mavlink)
PHYSICS_SUBSTEPS = 4  # 1 ms physics steps per round
# HIL_SENSOR.fields_updated, as SimulatorMavlink.hpp's SensorSource tests them.
FIELDS_ACCEL = 0b111
FIELDS_GYRO = 0b111000
FIELDS_MAG = 0b111000000
FIELDS_BARO = 0b1101000000000  # absolute pressure, pressure altitude, temperature
DEFAULT_STATE_INTERVAL_US = 20_000  # HIL_STATE_QUATERNION until PX4 asks (50 Hz)
SYSTEM_ID, COMPONENT_ID = 1, 1  # of the simulator's messages (PX4 does not check them)
# The GPS as PX4's EKF2 accepts it on the ground: a settled, hot-started receiver whose
# error wanders over a minute (EKF2 refuses a fix that drifts faster than
# EKF2_REQ_HDRIFT 0.1 m/s while landed).
PX4_SENSORS = SensorParams(gps=GpsParams(error_tau=60.0, fix_sigma_factor=1.0))
_SQRT_HALF = math.sqrt(0.5)


@dataclass
class Peer:
    """What the simulator remembers of one PX4 instance's connection."""

    connected: bool = False
    lockstep: bool = False  # PX4 said so: each actuator message steps one round
    armed: bool = False
    time_us: int = 0  # physics time of this vehicle since PX4 connected
    answered_us: int = -1  # PX4's clock in its last HIL_ACTUATOR_CONTROLS (time_usec)
    rounds: int = 0  # rounds stepped since this process started
    state_interval_us: int | None = DEFAULT_STATE_INTERVAL_US  # None: not sent
    next_state_us: int = 0
    seq: int = 0
    seen: tuple[int, int, int] = (0, 0, 0)  # magnetometer, barometer, GPS samples sent


def motor_commands(controls: Sequence[float], omega_max: float) -> tuple[list[float], bool]:
    """Rotor speed commands (rad/s) of PX4's motors 0..3, and whether any was not a
    number (it is taken as 0: a motor that is off)."""
    out, bad = [], False
    for u in controls[: L.N_ROTORS]:
        if not math.isfinite(u):
            bad, u = True, 0.0
        out.append(rotor_speed(min(1.0, max(0.0, u)), omega_max))
    return out, bad


class HilPhysics:
    """N PX4 instances flying one batched Fleet through simulator_mavlink, in lockstep.

    Args:
        fleet: the vehicles, one per PX4 instance; each starts at rest on the ground at
            ``home``, nose north.
        home: where the local frame's origin is (GPS, barometer, magnetic field).
        noise_scale: of every sensor's noise (0: the truth).
        seed: of the sensors' noise; vehicle i uses seed + i, again at each reconnection.
        notice: where one-line messages go (connections, bad messages); those about
            bad messages are rate-limited by kind (:class:`~.notices.Notices`).
    """

    def __init__(
        self,
        fleet: Fleet,
        home: Home | None = None,
        noise_scale: float = 1.0,
        seed: int = 0,
        notice: Callable[[str], None] = print,
    ) -> None:
        self.fleet, self.notice = fleet, notice
        self.notices = Notices(notice)
        self.home = home or Home()
        self.noise_scale, self.seed = noise_scale, seed
        fleet.dt = ROUND_US * 1e-6 / PHYSICS_SUBSTEPS
        self.peers = [Peer() for _ in range(fleet.n)]
        self._gear = fleet.params[:, L.P_GEAR_HEIGHT].tolist()
        self._omega_max = fleet.params[:, L.P_OMEGA_MAX].tolist()
        self._commands = np.zeros((fleet.n, L.N_ROTORS))  # rad/s, the last rotor commands
        self.sensors = [self._new_sensors(i) for i in range(fleet.n)]
        self._step(list(range(fleet.n)))  # load the compiled kernels now, not while PX4 waits
        self.peers = [Peer() for _ in range(fleet.n)]
        self.sensors = [self._new_sensors(i) for i in range(fleet.n)]
        for index in range(fleet.n):
            self._put_on_ground(index)

    # --- connections ----------------------------------------------------------------
    def connect(self, index: int) -> None:
        """PX4 instance ``index`` connected: its vehicle starts again at rest at home,
        with new sensors and the clock at 0, on the server's clock until PX4 leads."""
        self.notices.flush(index)
        self.peers[index] = Peer(connected=True, rounds=self.peers[index].rounds)
        self.sensors[index] = self._new_sensors(index)
        self._put_on_ground(index)

    def disconnect(self, index: int) -> None:
        """PX4 instance ``index`` went away: its vehicle waits at rest for the next one."""
        peer = self.peers[index]
        peer.connected = peer.lockstep = False
        self._put_on_ground(index)
        self.notices.flush(index)

    def waiting_for_clock(self) -> list[int]:
        """Connected instances the server's clock moves (PX4 not in lockstep, or not yet)."""
        return [i for i, p in enumerate(self.peers) if p.connected and not p.lockstep]

    # --- messages -------------------------------------------------------------------
    def answer(self, messages: Mapping[int, Sequence[FC.Frame]]) -> dict[int, bytes]:
        """What to send each instance after ``messages`` (index -> frames it sent):
        command acknowledgements, and a round of sensors per HIL_ACTUATOR_CONTROLS in
        lockstep. Instances whose actuator messages came together step as one batch."""
        out: dict[int, list[bytes]] = {}
        rounds = dict.fromkeys(messages, 0)  # lockstep rounds owed to each instance
        for index, frames in messages.items():
            peer = self.peers[index]
            for frame in frames:
                if frame.msgid == mav.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS:
                    if self._actuators(index, frame):
                        rounds[index] += 1
                elif frame.msgid == mav.MAVLINK_MSG_ID_COMMAND_LONG:
                    ack = self._command(index, frame)
                    if ack:
                        out.setdefault(index, []).append(ack)
                elif frame.msgid == mav.MAVLINK_MSG_ID_HEARTBEAT:
                    peer.armed = bool(frame.unpack()[3] & ARMED_FLAG)
        while any(rounds.values()):
            rows = [i for i, owed in rounds.items() if owed]
            for index, data in self._step(rows).items():
                out.setdefault(index, []).append(data)
            for i in rows:
                rounds[i] -= 1
        return {index: b"".join(parts) for index, parts in out.items()}

    def tick(self, rows: list[int]) -> dict[int, bytes]:
        """One round of vehicles ``rows`` on the server's clock, with their last motor
        commands; the sensors to send each."""
        return self._step(rows) if rows else {}

    def _actuators(self, index: int, frame: FC.Frame) -> bool:
        """Take a HIL_ACTUATOR_CONTROLS; True when it asks for a lockstep round."""
        values = frame.unpack()  # time_usec, flags, controls[16], mode
        flags, controls, mode = values[1], values[2:18], values[18]
        peer = self.peers[index]
        peer.answered_us = values[0]
        peer.armed = bool(mode & ARMED_FLAG)
        commands, bad = motor_commands(controls, self._omega_max[index])
        if bad:
            self.notices(
                index,
                "motor outputs not a number",
                "PX4 sent a motor output that is not a number; taken as 0",
            )
        self._commands[index] = commands
        if flags & LOCKSTEP_FLAG and not peer.lockstep:
            peer.lockstep = True
            self.notice(f"vehicle {index}: PX4 leads in lockstep from {peer.time_us / 1e6:.3f} s")
        return peer.lockstep

    def _command(self, index: int, frame: FC.Frame) -> bytes:
        """A COMMAND_LONG: SET_MESSAGE_INTERVAL of HIL_STATE_QUATERNION is honoured
        (interval µs; −1 off; 0 the default), anything else refused; the COMMAND_ACK."""
        p1, p2, *_, command, _, _, _ = frame.unpack()
        peer = self.peers[index]
        result = mav.MAV_RESULT_UNSUPPORTED
        if (
            command == mav.MAV_CMD_SET_MESSAGE_INTERVAL
            and int(p1) == mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION
            and math.isfinite(p2)
        ):
            result = mav.MAV_RESULT_ACCEPTED
            if p2 < 0:
                peer.state_interval_us = None
            else:
                peer.state_interval_us = int(p2) if p2 > 0 else DEFAULT_STATE_INTERVAL_US
                peer.next_state_us = peer.time_us
        else:
            self.notices(
                index,
                "refused commands",
                f"PX4 asked for command {command} ({p1:g}, {p2:g}): refused",
            )
        ack = (command, result, 0, 0, frame.sysid, frame.compid)
        return self._pack(peer, mav.MAVLink_command_ack_message, ack)

    # --- stepping and the sensors -----------------------------------------------------
    def _step(self, rows: list[int]) -> dict[int, bytes]:
        """Step vehicles ``rows`` by one round; each one's sensor messages."""
        step_vehicles(self.fleet, self._commands, rows, PHYSICS_SUBSTEPS)
        out = {}
        for index in rows:
            peer = self.peers[index]
            peer.time_us += ROUND_US
            peer.rounds += 1
            out[index] = self._sensor_messages(index)
        return out

    def _sensor_messages(self, index: int) -> bytes:
        """HIL_SENSOR, and HIL_GPS and HIL_STATE_QUATERNION when due, of vehicle
        ``index`` now."""
        fleet, peer, suite = self.fleet, self.peers[index], self.sensors[index]
        one = slice(index, index + 1)
        state, params, contact = fleet.state[one], fleet.params[one], fleet.contact[one]
        air = fleet.air_velocity[one]
        suite.update(peer.time_us * 1e-6, state, params, contact, air)
        suite.sample_due()
        imu, mag, baro, gps = suite.imu, suite.magnetometer, suite.barometer, suite.gps
        fields = FIELDS_ACCEL | FIELDS_GYRO
        seen_mag, seen_baro, seen_gps = peer.seen
        if mag.samples != seen_mag:
            fields |= FIELDS_MAG
        if baro.samples != seen_baro:
            fields |= FIELDS_BARO
        peer.seen = (mag.samples, baro.samples, gps.samples)
        ax, ay, az = imu.accel[0].tolist()
        gx, gy, gz = imu.gyro[0].tolist()
        mx, my, mz = mag.field[0].tolist()
        sensor = (
            peer.time_us,
            *(ax, -ay, -az),  # body FLU -> FRD
            *(gx, -gy, -gz),
            *(mx, -my, -mz),
            float(baro.pressure[0]) / 100.0,  # Pa -> hPa
            0.0,  # differential pressure, hPa: no airspeed sensor
            float(baro.altitude[0]),  # m above mean sea level
            float(baro.temperature[0]) - 273.15,  # K -> °C
            fields,
            0,  # sensor id 0: PX4's lockstep master
        )
        parts = [self._pack(peer, mav.MAVLink_hil_sensor_message, _finite(sensor))]
        if gps.samples != seen_gps:
            parts.append(self._gps_message(index))
        due = peer.state_interval_us is not None and peer.time_us >= peer.next_state_us
        if due:
            parts.append(self._state_message(index))
            interval = peer.state_interval_us or DEFAULT_STATE_INTERVAL_US
            peer.next_state_us += interval * max(
                1, math.ceil((peer.time_us + 1 - peer.next_state_us) / interval)
            )
        return b"".join(parts)

    def _gps_message(self, index: int) -> bytes:
        """HIL_GPS of the fix the receiver delivered now (measured ``latency`` ago)."""
        fix, peer = self.sensors[index].gps.fix, self.peers[index]
        east, north, up = fix.position[0].tolist()
        v_east, v_north, v_up = fix.velocity[0].tolist()
        lat, lon, alt = self.home.to_global(east, north, up - self._gear[index])
        speed = math.hypot(v_north, v_east)
        cog = math.degrees(math.atan2(v_east, v_north)) * 100 % 36000  # cdeg
        gps = (
            peer.time_us,
            wire_int(lat * 1e7),
            wire_int(lon * 1e7),
            wire_int(alt * 1000),  # mm above mean sea level
            wire_int(float(fix.eph[0]) * 100),  # cm, 1-σ horizontal (PX4 reads metres·100)
            wire_int(float(fix.epv[0]) * 100),
            wire_int(speed * 100),  # cm/s over ground
            wire_int(v_north * 100),
            wire_int(v_east * 100),
            wire_int(-v_up * 100),
            min(round(cog), 35999) if speed > 0.1 and math.isfinite(cog) else 65535,  # unknown
            int(fix.fix_type[0]),
            int(fix.satellites[0]),
            0,  # receiver id
            0,  # yaw: not measured
        )
        return self._pack(peer, mav.MAVLink_hil_gps_message, gps)

    def _state_message(self, index: int) -> bytes:
        """HIL_STATE_QUATERNION: the vehicle's true state (PX4 publishes it as ground
        truth only)."""
        fleet, peer = self.fleet, self.peers[index]
        one = slice(index, index + 1)
        px, py, pz, vx, vy, vz, w, x, y, z, wx, wy, wz = fleet.state[index, : L.I_ROTOR0].tolist()
        force = specific_force(
            fleet.state[one], fleet.params[one], fleet.contact[one], fleet.air_velocity[one]
        )[0].tolist()  # m/s², body FLU
        lat, lon, alt = self.home.to_global(px, py, pz - self._gear[index])
        air_speed = float(np.linalg.norm(fleet.state[index, L.VEL] - fleet.air_velocity[index]))
        h, mg = _SQRT_HALF, 1000.0 / STANDARD_GRAVITY
        state = (
            peer.time_us,
            *(h * (w + z), h * (x + y), h * (x - y), h * (w - z)),  # FLU->ENU to FRD->NED
            *(wx, -wy, -wz),  # rad/s, body FRD
            wire_int(lat * 1e7),
            wire_int(lon * 1e7),
            wire_int(alt * 1000),
            *(wire_int(vy * 100), wire_int(vx * 100), wire_int(-vz * 100)),  # cm/s, NED
            wire_int(air_speed * 100),
            wire_int(air_speed * 100),
            *(wire_int(force[0] * mg), wire_int(-force[1] * mg), wire_int(-force[2] * mg)),  # mG
        )
        return self._pack(peer, mav.MAVLink_hil_state_quaternion_message, _finite(state))

    def _pack(self, peer: Peer, message_class: object, values: tuple) -> bytes:
        """One frame; a value beyond its field's type is saturated (:mod:`quadsitl.wire.fit`)."""
        peer.seq += 1
        return FC.pack(message_class, values, peer.seq, SYSTEM_ID, COMPONENT_ID)

    def _new_sensors(self, index: int) -> SensorSuite:
        gear = float(self.fleet.params[index, L.P_GEAR_HEIGHT])
        return SensorSuite(
            1,
            self.home.latitude,
            self.home.longitude,
            altitude_offset=self.home.altitude - gear,  # the centre of mass is gear high
            params=PX4_SENSORS,
            noise_scale=self.noise_scale,
            seed=self.seed + index,
        )

    def _put_on_ground(self, index: int) -> None:
        """Vehicle ``index`` at rest on the ground at home, nose north, rotors stopped."""
        one = np.zeros(self.fleet.n, bool)
        one[index] = True
        # At rest at home, facing north (as PX4's and ArduPilot's own simulators start)
        rest = initial_state(1, position=(0.0, 0.0, self._gear[index]), yaw=NORTH_YAW_ENU)
        self.fleet.reset(rest, contact=L.ON_GROUND, mask=one)
        self._commands[index] = 0.0


def _finite(values: tuple) -> tuple:
    """``values`` of the physics with NaN as 0 and ±inf as ±FLOAT32_MAX, so that PX4 is
    never sent a non-finite number (integer fields come through ``wire_int``, and packing
    saturates what is beyond a field's type). The values themselves when all are finite:
    one sum, about a µs."""
    if math.isfinite(sum(values)):
        return values
    return tuple(
        v if isinstance(v, int) else 0.0 if v != v else max(-FLOAT32_MAX, min(FLOAT32_MAX, v))
        for v in values
    )
