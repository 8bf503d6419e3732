"""A stand-in for ArduCopter flown from outside (GUIDED), for tests and benchmarks without
an ArduPilot build: :class:`~quadsitl.bridges.fake_ardupilot.FakeArduPilot`'s JSON side,
ArduCopter's MAVLink on SERIAL0 as a UDP client, and quadsitl's own cascade controller in
between.

What it does as ArduCopter does (``ArduCopter/mode_guided.cpp``, ``GCS_Common.cpp``):

* It sends servo frames at 800 Hz (SIM_RATE_HZ 800) to UDP 9002 + 10 i and waits for
  each answer (again after 1 s without one): its clock is the answer's ``timestamp``,
  and every timeout below runs on it.
* Its MAVLink goes to UDP 5760 + 10 i (``--serial0 udpclient:127.0.0.1:5760``) as system
  1: HEARTBEAT once a simulated second (MAV_AUTOPILOT_ARDUPILOTMEGA, ArduCopter's mode
  number as custom_mode), COMMAND_ACK for each command, and only the streams asked for by
  MAV_CMD_SET_MESSAGE_INTERVAL (LOCAL_POSITION_NED, ATTITUDE_QUATERNION), once its
  "EKF" has an origin (EKF_ORIGIN_S after start; no local position before).
* Commands: MAV_CMD_DO_SET_MODE (custom: STABILIZE 0, GUIDED 4, LOITER 5; others
  denied), arming (refused, with ArduCopter's "PreArm: Need Position Estimate", until
  the EKF is ready), MAV_CMD_NAV_TAKEOFF (GUIDED, armed, on the ground: it climbs to
  param7 m above home).
* GUIDED flies SET_POSITION_TARGET_LOCAL_NED and SET_ATTITUDE_TARGET (thrust as thrust:
  ``GUID_OPTIONS`` 8) once airborne, decoded as the built-in flight software decodes
  them (:mod:`quadsitl.simulator.offboard`); a velocity or attitude setpoint older than
  GUID_TIMEOUT_S holds position, as ArduCopter's ``GUID_TIMEOUT``. Other modes hold.

Its estimate is the truth it is sent: a fake has no EKF. Run it as
``python -m quadsitl.fake_stacks.offboard_ardupilot -i 0``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import socket

import numpy as np

from quadsitl import frames
from quadsitl.bridges.ardupilot_json import PORT, PWM_MAX_US, PWM_MIN_US, motor_channels
from quadsitl.bridges.fake_ardupilot import FakeArduPilot, Kinematics
from quadsitl.flight_software.controller import CascadedController, Setpoint
from quadsitl.physics import get_airframe
from quadsitl.physics import layout as L
from quadsitl.simulator import offboard
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.udp_messages import pending_messages

FRAME_RATE = 800  # Hz, SIM_RATE_HZ of quadsitl's offboard.parm
LINK_PORT = 5760  # UDP port its SERIAL0 sends to, instance i: + 10 i
HEARTBEAT_S = 1.0
EKF_ORIGIN_S = 1.0  # simulated s before its local position (ArduCopter: ~20 s) ...
EKF_READY_S = 3.0  # ... and before it may arm (ArduCopter: once it uses GPS, ~45 s)
GUID_TIMEOUT_S = 3.0  # GUID_TIMEOUT's default
STABILIZE, GUIDED, LOITER = 0, 4, 5  # ArduCopter's mode numbers (mode.h)
WAIT_S = 1.0  # wall s for an answer before the frame is sent again (SIM_JSON.cpp)


class FakeOffboardArduPilot:
    """ArduCopter instance ``instance`` of airframe ``airframe`` on the JSON physics at
    ``port`` (instance 0's)."""

    def __init__(self, instance: int = 0, port: int = PORT, airframe: str = "iris") -> None:
        self.airframe = get_airframe(airframe)
        _, self.channels = motor_channels(self.airframe)
        self.controller = CascadedController(self.airframe)
        level = np.eye(1, L.STATE_SIZE, L.QUAT.start)[0]
        self.controller.rotor_command(level, Setpoint(idle=True), 1 / FRAME_RATE)
        self.controller.reset()  # (compiled code loaded before the simulator waits on it)
        self.link = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.link.connect(("127.0.0.1", LINK_PORT + 10 * instance))  # as udpclient
        self.link.setblocking(False)
        self.mav = mav.MAVLink(None, srcSystem=1, srcComponent=1)  # SYSID_THISMAV 1
        self.mav.robust_parsing = True
        self.seq = 0
        self.armed = False
        self.mode = STABILIZE
        self.airborne = False
        self.setpoint: Setpoint | None = None
        self.setpoint_us = 0
        self.hold = Setpoint(idle=True)
        self.rotors = np.zeros(L.N_ROTORS)  # rad/s, the motors' modelled speeds
        self.state = np.zeros(L.STATE_SIZE)
        self.streams: dict[int, int] = {}  # message id -> interval µs (asked for)
        self.next_send: dict[int, int] = {}  # message id -> µs of its next
        self.next_heartbeat_us = 0
        self.parent = os.getppid()
        self.json = FakeArduPilot(
            instance, port, frame_rate=FRAME_RATE, resend_after=WAIT_S, poll=True
        )

    # --- one lockstep frame ---------------------------------------------------------
    def run(self) -> None:
        """Frames until the process that started it is gone."""
        pwm = [int(PWM_MIN_US)] * L.N_ROTORS
        try:
            while True:
                self.json.send(pwm)
                pwm = self.frame(self._answer())
        except (ConnectionError, TimeoutError):
            pass
        finally:
            self.json.close()
            self.link.close()

    def _answer(self) -> Kinematics:
        """The answer to the frame sent, however long the simulator holds it (it is sent
        again each WAIT_S); TimeoutError once the process that started this one is gone."""
        while True:
            with contextlib.suppress(TimeoutError):
                return self.json.receive(attempts=1)
            if os.getppid() != self.parent:
                raise TimeoutError("the simulator's process is gone")

    def frame(self, k: Kinematics) -> list[int]:
        """ArduCopter's loop at the answer's time: its link, failsafes, telemetry, and the
        outputs (µs) of the next frame."""
        now = round(k.timestamp * 1e6)
        self.state = self._state(k)
        self._read_link(now)
        stale = self.setpoint is not None and self.setpoint.position is None
        if self.mode == GUIDED and stale and now - self.setpoint_us > GUID_TIMEOUT_S * 1e6:
            self._hold_here("GUIDED: setpoint timed out, holding position")
        self._telemetry(now)
        return self._outputs()

    def _state(self, k: Kinematics) -> np.ndarray:
        """The answer as quadsitl's state row in the local frame (ENU/FLU, origin on the
        ground where it started: its LOCAL_POSITION_NED's)."""
        state = np.zeros(L.STATE_SIZE)
        state[L.POS] = frames.ned_to_enu(np.array(k.position))
        state[L.VEL] = frames.ned_to_enu(np.array(k.velocity))
        state[L.QUAT] = frames.quat_ned_frd_to_enu_flu(np.array(k.quaternion))
        state[L.RATES] = frames.frd_to_flu(np.array(k.gyro))
        state[L.ROTORS] = self.rotors
        return state

    def _outputs(self) -> list[int]:
        if not self.armed:
            self.rotors[:] = 0.0
            return [int(PWM_MIN_US)] * L.N_ROTORS
        guided = self.mode == GUIDED and self.airborne and self.setpoint is not None
        setpoint = self.setpoint if guided else self.hold
        assert setpoint is not None
        dt = 1.0 / FRAME_RATE
        command = self.controller.rotor_command(self.state, setpoint, dt)
        self.rotors += (command - self.rotors) * min(1.0, self.airframe.motor_rate * dt)
        pwm = [int(PWM_MIN_US)] * L.N_ROTORS
        span = PWM_MAX_US - PWM_MIN_US
        for rotor, channel in enumerate(self.channels):
            fraction = float(command[rotor]) / self.airframe.max_rotor_speed
            pwm[channel] = round(PWM_MIN_US + span * min(1.0, max(0.0, fraction)))
        return pwm

    def _hold_here(self, why: str | None, position: np.ndarray | None = None) -> None:
        """Hold ``position`` (where it is) and the heading of now; ``why`` said."""
        yaw = float(frames.euler_from_quat(self.state[L.QUAT])[2])
        here = self.state[L.POS].copy() if position is None else position
        self.hold = Setpoint(position=here, yaw=yaw)
        self.setpoint = None
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
            return
        if kind == "COMMAND_LONG":
            self._command(msg, now)
        elif self.mode != GUIDED or not (self.armed and self.airborne):
            return  # GUIDED flies setpoints only armed and in the air
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            yaw = float(frames.euler_from_quat(self.state[L.QUAT])[2])
            self._take(offboard.position_target(msg, self.state[L.POS], yaw, 0.0), now)
        elif kind == "SET_ATTITUDE_TARGET":
            self._take(offboard.attitude_target(msg), now)

    def _take(self, setpoint: Setpoint | str, now: int) -> None:
        if isinstance(setpoint, str):
            self._send(self.mav.statustext_encode(mav.MAV_SEVERITY_WARNING, setpoint.encode()))
            return
        self.setpoint, self.setpoint_us = setpoint, now

    def _command(self, msg: object, now: int) -> None:
        command = msg.command  # type: ignore[attr-defined]
        p = [getattr(msg, f"param{i}") for i in range(1, 8)]
        ok, refused = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_FAILED
        result = ok
        if command == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] == 1.0 and now < EKF_READY_S * 1e6:
                self._send(self.mav.statustext_encode(
                    mav.MAV_SEVERITY_CRITICAL, b"PreArm: Need Position Estimate"))  # fmt: skip
                result = refused
            else:
                self.armed = p[0] == 1.0
                self.airborne = False
                self.controller.reset()
                self._hold_here(None)
        elif command == mav.MAV_CMD_DO_SET_MODE:
            mode = int(p[1])
            if mode in (STABILIZE, GUIDED, LOITER):
                self.mode = mode
                self._hold_here(None)
            else:
                result = mav.MAV_RESULT_DENIED
        elif command == mav.MAV_CMD_NAV_TAKEOFF:
            if self.mode == GUIDED and self.armed and not self.airborne:
                self.airborne = True
                above = self.state[L.POS] * [1.0, 1.0, 0.0] + [0.0, 0.0, p[6]]
                self._hold_here(None, above)
            else:
                result = refused
        elif command == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            self.streams[int(p[0])] = int(p[1])
            self.next_send[int(p[0])] = now
        else:
            result = mav.MAV_RESULT_UNSUPPORTED
        self._send(self.mav.command_ack_encode(command, result))

    def _telemetry(self, now: int) -> None:
        if now >= self.next_heartbeat_us:
            self.next_heartbeat_us = now + int(HEARTBEAT_S * 1e6)
            base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            base |= mav.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0
            heartbeat = self.mav.heartbeat_encode(
                mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, base, self.mode,
                mav.MAV_STATE_ACTIVE,
            )  # fmt: skip
            self._send(heartbeat)
        if now < EKF_ORIGIN_S * 1e6:
            return  # no origin yet: no local position
        ms, s, due = now // 1000, self.state, []
        for message, interval in self.streams.items():
            if interval > 0 and now >= self.next_send[message]:
                self.next_send[message] = now + interval
                due.append(message)
        messages = []
        if mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED in due:
            north_east_down = frames.enu_to_ned(s[L.POS])
            velocity = frames.enu_to_ned(s[L.VEL])
            messages.append(self.mav.local_position_ned_encode(ms, *north_east_down, *velocity))
        if mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION in due:
            q = frames.quat_enu_flu_to_ned_frd(s[L.QUAT])
            rates = frames.flu_to_frd(s[L.RATES])
            messages.append(self.mav.attitude_quaternion_encode(ms, *q, *rates, [0.0] * 4))
        if messages:
            self._send(*messages)

    def _send(self, *messages: object) -> None:
        """``messages`` in one datagram (the fast codec's framing of pymavlink's bytes)."""
        data, self.seq = FC.pack_messages(
            messages, self.seq, self.mav.srcSystem, self.mav.srcComponent
        )
        with contextlib.suppress(OSError):  # nobody listens yet: ArduPilot sends regardless
            self.link.send(data)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-i", "--instance", type=int, default=0, help="ArduPilot's -I (0)")
    parser.add_argument("--port", type=int, default=PORT, help="JSON port of instance 0 (9002)")
    parser.add_argument("--airframe", default="iris", help="the airframe it flies (iris)")
    options = parser.parse_args(argv)
    FakeOffboardArduPilot(options.instance, options.port, options.airframe).run()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
