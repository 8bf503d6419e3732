"""A stand-in for PX4 flown from outside (offboard), for tests and benchmarks without a
PX4 build: :class:`~quadsitl.bridges.fake_px4.FakePx4`'s simulator side, PX4's offboard
MAVLink port, and quadsitl's own cascade controller in between.

What it does as PX4 does (its "Offboard Mode" docs, ``px4-rc.mavlink``):

* It connects to the simulator (TCP 4560 + i) and flies in lockstep: its clock is the
  ``time_usec`` of the HIL_SENSOR it was sent, and every timeout below runs on it.
* It is MAVLink system i + 1 (PX4's MAV_SYS_ID), and ignores messages for another.
* It listens for MAVLink on UDP 14580 + i and sends to 14540 + i (PX4's onboard link),
  every round (4 ms): LOCAL_POSITION_NED and ATTITUDE_QUATERNION stamped with its clock,
  HEARTBEAT once a simulated second, COMMAND_ACK for each command. Its telemetry (not
  the acknowledgements) goes to 14030 + i too, where PX4's onboard payload link sends
  (what ``quadsitl sim --flight-stack px4 --rerun`` reads).
* Commands: arm and disarm (MAV_CMD_COMPONENT_ARM_DISARM), and the mode
  (MAV_CMD_DO_SET_MODE with PX4's custom main mode: OFFBOARD, or POSCTL to hold).
  OFFBOARD is refused unless a setpoint came within the last OFFBOARD_LOSS_S.
* Setpoints: SET_POSITION_TARGET_LOCAL_NED and SET_ATTITUDE_TARGET, decoded as the
  built-in flight software decodes them (:mod:`quadsitl.simulator.offboard`).
* Offboard loss: no setpoint for OFFBOARD_LOSS_S (PX4's ``COM_OF_LOSS_T``) of simulated
  time, and it holds where it is (position control), saying so in a STATUSTEXT.

Its estimate is the truth it is sent (HIL_STATE_QUATERNION every round): a fake has no
EKF. Run it as ``python -m quadsitl.fake_stacks.offboard_px4 -i 0``.
"""

from __future__ import annotations

import argparse
import contextlib
import socket

import numpy as np

from quadsitl import frames
from quadsitl.bridges.autopilot_telemetry import PX4_PAYLOAD_PORT
from quadsitl.bridges.fake_px4 import FakePx4, HilState, kinematics
from quadsitl.bridges.px4_hil import LINK_PORT, PEER_PORT, PORT, ROUND_US
from quadsitl.flight_software.controller import CascadedController, Setpoint
from quadsitl.geo import Home
from quadsitl.physics import get_airframe
from quadsitl.physics import layout as L
from quadsitl.simulator import offboard
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.modes import MAIN_OFFBOARD, MAIN_POSCTL, Mode
from quadsitl.wire.udp_messages import pending_messages

OFFBOARD_LOSS_S = 1.0  # COM_OF_LOSS_T's default
HEARTBEAT_S = 1.0
MAIN_MODE_POSCTL, MAIN_MODE_OFFBOARD = MAIN_POSCTL, MAIN_OFFBOARD  # PX4's main modes
_LEVEL = np.eye(1, L.STATE_SIZE, L.QUAT.start)[0]  # a state row at rest, level


def custom_mode(main_mode: int) -> int:
    return Mode.from_custom(main_mode).custom_mode


class FakeOffboardPx4:
    """PX4 instance ``instance`` of airframe ``airframe`` on the simulator at ``port``."""

    def __init__(
        self, instance: int = 0, port: int = PORT, airframe: str = "iris", home: Home | None = None
    ) -> None:
        self.home = home or Home()
        self.airframe = get_airframe(airframe)
        self.controller = CascadedController(self.airframe)
        self.controller.rotor_command(np.zeros(L.STATE_SIZE) + _LEVEL, Setpoint(idle=True), 0.004)
        self.controller.reset()  # (compiled code loaded before the simulator waits on it)
        self.link = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.link.bind(("127.0.0.1", LINK_PORT + instance))
        self.link.setblocking(False)
        self.peer = ("127.0.0.1", PEER_PORT + instance)
        self.payload_peer = ("127.0.0.1", PX4_PAYLOAD_PORT + instance)
        self.mav = mav.MAVLink(None, srcSystem=instance + 1, srcComponent=1)  # PX4's MAV_SYS_ID
        self.seq = 0  # of the frames it sends on its MAVLink links
        self.mav.robust_parsing = True
        self.armed = False
        self.main_mode = MAIN_MODE_POSCTL
        self.setpoint: Setpoint | None = None
        self.setpoint_us = -(10**12)  # clock of the last setpoint
        self.hold = Setpoint(idle=True)
        self.rotors = np.zeros(L.N_ROTORS)  # rad/s, the motors' modelled speeds
        self.next_heartbeat_us = 0
        self.state = np.zeros(L.STATE_SIZE)
        self.streaming = False  # HIL_STATE_QUATERNION comes every round
        self.px4 = FakePx4(instance, port, state_interval_us=ROUND_US)  # last: ready now

    # --- one lockstep round ---------------------------------------------------------
    def run(self) -> None:
        """Rounds until the simulator closes the connection."""
        try:
            while True:
                self.round()
        except (ConnectionError, TimeoutError):
            pass
        finally:
            self.px4.close()
            self.link.close()

    def round(self) -> None:
        sensor = self.px4.next_sensor(timeout=3600.0)  # the simulator holds the clock
        received = self.px4.received
        # Once streaming, the round's HIL_STATE_QUATERNION comes with its HIL_SENSOR,
        # maybe in the next TCP segment: wait for it, so that every round flies on its
        # own state (the first rounds, before the stream starts, are at rest).
        while self.streaming and (
            not received.states or received.states[-1].time_usec < sensor.time_usec
        ):
            self.px4.receive(3600.0)
        if received.states:
            self.streaming = True
            self.state = self._state(received.states[-1])
        for kept in (received.sensors, received.gps, received.states, received.acks):
            kept.clear()  # a long flight keeps nothing
        now = sensor.time_usec
        self._read_link(now)
        if self.main_mode == MAIN_MODE_OFFBOARD and now - self.setpoint_us > OFFBOARD_LOSS_S * 1e6:
            self._hold_here("offboard setpoint lost: holding position")
        self._telemetry(now)
        controls = self._controls()
        self.px4.send_controls(controls, armed=self.armed)

    def _state(self, hil: HilState) -> np.ndarray:
        """The HIL state as quadsitl's state row (ENU/FLU; rotors: as modelled)."""
        k = kinematics(hil, self.home)
        state = np.zeros(L.STATE_SIZE)
        state[L.POS] = frames.ned_to_enu(np.array(k.position))
        state[L.VEL] = frames.ned_to_enu(np.array(k.velocity))
        state[L.QUAT] = frames.quat_ned_frd_to_enu_flu(np.array(k.quaternion))
        state[L.RATES] = frames.frd_to_flu(np.array(k.gyro))
        state[L.ROTORS] = self.rotors
        return state

    def _controls(self) -> list[float]:
        if not self.armed:
            self.rotors[:] = 0.0
            return [0.0] * L.N_ROTORS
        offboard_on = self.main_mode == MAIN_MODE_OFFBOARD and self.setpoint is not None
        setpoint = self.setpoint if offboard_on else self.hold
        assert setpoint is not None
        dt = ROUND_US * 1e-6
        command = self.controller.rotor_command(self.state, setpoint, dt)
        # No ESC telemetry: the motors' speeds as their first-order lag takes them there.
        self.rotors += (command - self.rotors) * min(1.0, self.airframe.motor_rate * dt)
        return [float(w) / self.airframe.max_rotor_speed for w in command]

    def _hold_here(self, why: str | None, switch: bool = True) -> None:
        """Hold the position and heading of now (position control); ``switch``: in
        POSCTL from now on, saying ``why``."""
        if switch:
            self.main_mode = MAIN_MODE_POSCTL
        yaw = float(frames.euler_from_quat(self.state[L.QUAT])[2])
        self.hold = Setpoint(position=self.state[L.POS].copy(), yaw=yaw)
        if why:
            self._send(self.mav.statustext_encode(mav.MAV_SEVERITY_WARNING, why.encode()))

    # --- the MAVLink link -----------------------------------------------------------
    def _read_link(self, now: int) -> None:
        for msg in pending_messages(self.link, self.mav):
            self._handle(msg, now)

    def _handle(self, msg: object, now: int) -> None:
        kind = msg.get_type()  # type: ignore[attr-defined]
        target = getattr(msg, "target_system", 0)
        if target not in (0, self.mav.srcSystem):
            return  # another vehicle's, as PX4's MAVLink receiver ignores it
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            yaw = float(frames.euler_from_quat(self.state[L.QUAT])[2])
            gear = 0.0  # the fake's NED z is the simulator's: no gear offset
            self._take(offboard.position_target(msg, self.state[L.POS], yaw, gear), now)
        elif kind == "SET_ATTITUDE_TARGET":
            self._take(offboard.attitude_target(msg), now)
        elif kind == "COMMAND_LONG":
            self._command(msg)

    def _take(self, setpoint: Setpoint | str, now: int) -> None:
        if isinstance(setpoint, str):
            self._send(self.mav.statustext_encode(mav.MAV_SEVERITY_WARNING, setpoint.encode()))
            return
        self.setpoint, self.setpoint_us = setpoint, now

    def _command(self, msg: object) -> None:
        command = msg.command  # type: ignore[attr-defined]
        result = mav.MAV_RESULT_ACCEPTED
        if command == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            self.armed = msg.param1 == 1.0  # type: ignore[attr-defined]
            self.controller.reset()
            if self.armed:
                self._hold_here(None, switch=False)  # where POSCTL holds, if it comes to it
        elif command == mav.MAV_CMD_DO_SET_MODE:
            main_mode = int(msg.param2)  # type: ignore[attr-defined]
            fresh = self.setpoint is not None
            if main_mode == MAIN_MODE_OFFBOARD and fresh:
                self.main_mode = MAIN_MODE_OFFBOARD
            elif main_mode == MAIN_MODE_POSCTL:
                self._hold_here(None)
            else:
                result = mav.MAV_RESULT_DENIED
        else:
            result = mav.MAV_RESULT_UNSUPPORTED
        self._send(self.mav.command_ack_encode(command, result))

    def _telemetry(self, now: int) -> None:
        ms = now // 1000
        s = self.state
        if now >= self.next_heartbeat_us:
            self.next_heartbeat_us = now + int(HEARTBEAT_S * 1e6)
            base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            base |= mav.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
            heartbeat = self.mav.heartbeat_encode(
                mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4, base,
                custom_mode(self.main_mode), mav.MAV_STATE_ACTIVE,
            )  # fmt: skip
            self._send(heartbeat, payload=True)
        north_east_down = frames.enu_to_ned(s[L.POS])
        velocity = frames.enu_to_ned(s[L.VEL])
        position = self.mav.local_position_ned_encode(ms, *north_east_down, *velocity)
        q = frames.quat_enu_flu_to_ned_frd(s[L.QUAT])
        rates = frames.flu_to_frd(s[L.RATES])
        attitude = self.mav.attitude_quaternion_encode(ms, *q, *rates, [0.0] * 4)
        self._send(position, attitude, payload=True)  # one datagram, as PX4 bundles a loop's

    def _send(self, *messages: object, payload: bool = False) -> None:
        """``messages`` in one datagram to the onboard link (``payload``: and the payload
        link), framed by the fast codec (pymavlink's bytes, a fraction of its time)."""
        data, self.seq = FC.pack_messages(
            messages, self.seq, self.mav.srcSystem, self.mav.srcComponent
        )
        for peer in (self.peer, self.payload_peer) if payload else (self.peer,):
            with contextlib.suppress(OSError):  # nobody listens yet: PX4 sends on regardless
                self.link.sendto(data, peer)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-i", "--instance", type=int, default=0, help="PX4's -i (default 0)")
    parser.add_argument("--port", type=int, default=PORT, help="simulator port of instance 0")
    parser.add_argument("--airframe", default="iris", help="the airframe it flies (iris)")
    options = parser.parse_args(argv)
    FakeOffboardPx4(options.instance, options.port, options.airframe).run()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
