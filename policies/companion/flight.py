"""A setpoint policy flying a PX4 or ArduPilot vehicle over MAVLink, as a companion
computer does: the deployment of a policy trained through the flight stack
(``quadsitl train --backend px4``).

It connects, learns which stack it speaks to (:mod:`.stacks`), asks for the estimate at
the policy's control rate, and refuses, saying why and changing nothing, when the vehicle
is not one it may command: no estimate, disarmed or on the ground (unless asked to take
off), a stack option the action level needs unset, the offboard mode refused. Then it
takes the offboard mode (OFFBOARD / GUIDED: setpoints stream first, as PX4 asks) and
flies: each time the autopilot's clock (its estimate's ``time_boot_ms``) has moved a
control period on, the policy's action for the latest estimate goes out as the
autopilot's setpoint (:mod:`quadsitl.envs.setpoints`, the training's own conversion). So
it keeps the training's control period on a real vehicle and on a SITL running faster
than real time alike. It stops when the pilot or a failsafe takes the vehicle out of the
offboard mode, or it disarms; it hands the vehicle back in the stack's hold mode when its
time is up (``duration``), on Ctrl-C, when the estimate stops coming, when the vehicle
strays beyond ``max_distance`` from the goal, or when the policy gives a non-finite
action.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from policies.autopilot import PolicyAutopilot, trained_range
from policies.companion import vehicle_state as VS
from policies.companion.stacks import GUIDED_THRUST_AS_THRUST, Stack, stack_of
from policies.config import FLIGHT_STACKS, TrainConfig
from policies.export.contract import trained_options
from quadsitl.envs import setpoints
from quadsitl.envs.autopilot_link import Estimate
from quadsitl.physics import get_airframe
from quadsitl.physics import layout as L
from quadsitl.tasks import TASKS
from quadsitl.wire.dialect import mavlink as mav

STREAM_FIRST_S = 1.0  # autopilot s of setpoints before asking for the offboard mode
ESTIMATE_LOST_S = 1.0  # wall s without a new estimate: hand the vehicle back
TAKEOFF_LIMIT_S = 60.0  # autopilot s a take-off may take (arming refused meanwhile included)
TAKEOFF_NEAR_M = 0.3  # m below the take-off altitude that counts as there
ACK_WAIT_S = 3.0  # wall s to wait for a COMMAND_ACK
REPORT_S = 1.0  # wall s between status lines
IN_AIR = {mav.MAV_LANDED_STATE_IN_AIR, mav.MAV_LANDED_STATE_TAKEOFF}


class RefusalError(RuntimeError):
    """The vehicle is not in a state the companion may command (the text says why)."""


@dataclass(frozen=True)
class CompanionOptions:
    """``goal``: ENU m in the autopilot's local frame (None: where the vehicle is when the
    policy takes over); ``takeoff``: m to climb to first when it is on the ground (None:
    refuse); ``duration``: s of the autopilot's clock to fly (None: until stopped);
    ``max_distance``: m from the goal by the estimate before it is handed back;
    ``system``: the vehicle's system id (None: the first autopilot heard); ``timeout``:
    wall s to wait for the vehicle and its estimate."""

    goal: tuple[float, float, float] | None = None
    takeoff: float | None = None
    duration: float | None = None
    max_distance: float = 5.0
    system: int | None = None
    timeout: float = 15.0


class Companion:
    """``net`` (a setpoint policy trained with ``config``) flying the vehicle on ``conn``
    (a pymavlink connection); ``say`` prints a line."""

    def __init__(
        self, conn: Any, net: Any, config: TrainConfig, options: CompanionOptions,
        say: Callable[[str], None] = print,
    ) -> None:  # fmt: skip
        if config.backend not in FLIGHT_STACKS:
            raise ValueError(
                "this policy commands rotor speeds (it was trained on quadsitl's own "
                f"physics, backend {config.backend!r}): fly it with quadsitl sim --autopilot. "
                "The companion flies setpoint policies (trained with --backend px4 or ardupilot)"
            )
        task = TASKS[config.task]
        if task.carrot is None:
            raise ValueError(f"a {task.name} policy has no goal to hold: the companion flies "
                             "hover and waypoint policies")  # fmt: skip
        self.conn, self.config, self.options, self.say = conn, config, options, say
        task_options = trained_options(config)
        self.airframe = get_airframe(task_options.airframe)  # type: ignore[arg-type]
        self.period = task_options.control_period
        self.level = setpoints.check_level(config.action_level)
        trained = trained_range(config)
        # A vehicle yawed beyond the headings the policy was trained at (the flight-stack
        # envs' resets hold it facing east, the task's heading) is shown to it at their
        # edge, the frame turned about up; its world-frame setpoints are turned back
        # (:func:`unturned`).
        self.pilot = PolicyAutopilot(net, self.airframe, task_options, trained.offset,
                                     goal_at_origin=task.goal_at_origin,
                                     heading=trained.heading or np.pi)  # fmt: skip
        # A runtime's first call sets itself up (ONNX Runtime: most of a second): not while
        # the vehicle waits for its first setpoint, whose loss it would take for a failsafe.
        level = np.zeros(L.STATE_SIZE)
        level[L.I_QW] = 1.0
        self.pilot.action(level, np.zeros(3))
        self.pilot.reset()
        self.estimate = Estimate()
        self.stack: Stack | None = None
        self.target = (0, 1)  # system, component of the autopilot
        self.params: dict[str, float] = {}
        self.channels: tuple[int, ...] = ()
        self.rotor_source = ""
        self.next_heartbeat = 0.0

    # --- the link -----------------------------------------------------------------
    def pump(self, timeout: float = 0.0) -> bool:
        """Take what arrived (waiting up to ``timeout`` s for the first); whether anything
        from the autopilot did. A heartbeat goes out each wall second meanwhile."""
        self.heartbeat()
        heard = False
        msg = self.conn.recv_match(blocking=timeout > 0, timeout=timeout)
        while msg is not None:
            if msg.get_srcSystem() == self.target[0] and msg.get_type() != "BAD_DATA":
                heard = True
                self.estimate.take(msg)
                if msg.get_type() == "PARAM_VALUE":
                    self.params[msg.param_id] = msg.param_value
                elif msg.get_type() == "STATUSTEXT":
                    self.say(f"vehicle: {msg.text}")
            msg = self.conn.recv_match(blocking=False)
        return heard

    def heartbeat(self) -> None:
        """The companion's HEARTBEAT, once each wall second."""
        now = time.monotonic()
        if now >= self.next_heartbeat:
            self.next_heartbeat = now + 1.0
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_ONBOARD_CONTROLLER,
                                         mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)  # fmt: skip

    def wait(self, done: Callable[[], bool], seconds: float) -> bool:
        """Pump until ``done()`` or ``seconds`` of wall time; whether it came."""
        end = time.monotonic() + seconds
        while not done():
            if time.monotonic() > end:
                return False
            self.pump(0.02)
        return True

    def command(self, command: int, *params: float) -> int:
        """COMMAND_LONG to the autopilot; its COMMAND_ACK's result (FAILED on none)."""
        values = [*params, *[0.0] * (7 - len(params))]
        self.estimate.acks.pop(command, None)
        self.conn.mav.command_long_send(*self.target, command, 0, *values)
        if not self.wait(lambda: command in self.estimate.acks, ACK_WAIT_S):
            return mav.MAV_RESULT_FAILED
        return self.estimate.acks[command]

    def clock(self) -> float:
        """The autopilot's clock (s) by its latest estimate."""
        return self.estimate.position_time_ms * 1e-3

    def send_setpoint(self, message: Any) -> None:
        self.conn.mav.send(message)

    # --- the flight -----------------------------------------------------------------
    def run(self) -> int:
        """Connect, check, engage, fly; the exit status (0: the flight ended as asked or
        the pilot took over; 1: handed back on a fault). Raises RefusalError."""
        self.connect()
        self.check_may_command()
        self.engage()
        return self.fly()

    def connect(self) -> None:
        wanted = self.options.system

        def heard_autopilot() -> bool:
            self.heartbeat()  # a vehicle listening (udpin) hears of the companion first
            msg = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.1)
            if msg is None or msg.autopilot == mav.MAV_AUTOPILOT_INVALID:
                return False
            if wanted is not None and msg.get_srcSystem() != wanted:
                return False
            self.target = (msg.get_srcSystem(), msg.get_srcComponent())
            self.estimate.take(msg)
            return True

        end = time.monotonic() + self.options.timeout
        while not heard_autopilot():
            if time.monotonic() > end:
                who = f"system {wanted}" if wanted is not None else "an autopilot"
                raise RefusalError(f"no heartbeat from {who} in {self.options.timeout:g} s")
        try:
            self.stack = stack_of(self.estimate.autopilot)
        except ValueError as error:
            raise RefusalError(str(error)) from None
        self.channels = VS.output_channels(self.stack.name, self.airframe)
        self.say(f"connected: {self.stack.name}, system {self.target[0]}")
        interval_us = self.period * 1e6
        for message_id, interval in (
            (mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, interval_us),
            (mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION, interval_us),
            (mav.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, interval_us),
            (mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 500_000.0),
        ):
            self.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, message_id, interval)
        e = self.estimate
        if not self.wait(lambda: min(e.position_time_ms, e.attitude_time_ms) >= 0,
                         self.options.timeout):  # fmt: skip
            raise RefusalError(
                "no estimate (LOCAL_POSITION_NED and ATTITUDE_QUATERNION) from the vehicle "
                f"in {self.options.timeout:g} s: without a position estimate (GPS, its "
                "estimator converged) a policy cannot fly it"
            )

    def check_may_command(self) -> None:
        """Refuse what the policy may not fly; take off first if asked."""
        assert self.stack is not None
        if self.stack.needs_thrust_option(self.level):
            self.conn.mav.param_request_read_send(*self.target, b"GUID_OPTIONS", -1)
            if not self.wait(lambda: "GUID_OPTIONS" in self.params, ACK_WAIT_S):
                raise RefusalError("ArduPilot did not say its GUID_OPTIONS")
            if not int(self.params["GUID_OPTIONS"]) & GUIDED_THRUST_AS_THRUST:
                raise RefusalError(
                    f"this policy sends thrust at action level {self.level!r}, and ArduCopter "
                    "reads SET_ATTITUDE_TARGET's thrust as a climb rate unless GUID_OPTIONS "
                    f"has bit 3 (8): it is {int(self.params['GUID_OPTIONS'])}. Set it "
                    "(param set GUID_OPTIONS 8) and start again"
                )
        self.wait(lambda: self.estimate.landed_state != mav.MAV_LANDED_STATE_UNDEFINED, 1.0)
        if self.flying():
            return
        state = "disarmed" if not self.estimate.armed else "on the ground"
        if self.options.takeoff is None:
            raise RefusalError(
                f"the vehicle is {state}: the policy flies it in the air. Arm it and take "
                "off (or pass --takeoff ALT), then start the companion again"
            )
        self.take_off(self.options.takeoff)

    def flying(self) -> bool:
        """Armed and in the air (by EXTENDED_SYS_STATE; armed, where it is not sent)."""
        e = self.estimate
        if not e.armed:
            return False
        return e.landed_state in IN_AIR or e.landed_state == mav.MAV_LANDED_STATE_UNDEFINED

    def here(self) -> np.ndarray:
        """Where the vehicle is by its estimate (local ENU, m)."""
        return VS.state_row(self.estimate, None, self.airframe)[:3]

    def take_off(self, altitude: float) -> None:
        """Climb ``altitude`` m straight up from where it rests, under the autopilot's
        own position control."""
        assert self.stack is not None
        target = self.here() + np.array([0.0, 0.0, altitude])
        self.say(f"taking off to {altitude:g} m")
        began = self.clock()
        while True:
            if self.clock() - began > TAKEOFF_LIMIT_S:
                raise RefusalError(f"the vehicle did not arm and take off in {TAKEOFF_LIMIT_S:g} s")
            if self.stack.name == "PX4":
                self.stream_position(target, STREAM_FIRST_S)
                self.set_offboard_mode()
                if self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == mav.MAV_RESULT_ACCEPTED:
                    break
            else:
                self.set_offboard_mode()
                armed = self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
                if armed == mav.MAV_RESULT_ACCEPTED:
                    self.command(mav.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, altitude)
                    break
                self.wait(lambda: False, 1.0)  # ArduPilot refuses until its EKF is ready
        while self.here()[2] < target[2] - TAKEOFF_NEAR_M:
            if self.clock() - began > TAKEOFF_LIMIT_S:
                limit = TAKEOFF_LIMIT_S
                raise RefusalError(f"the vehicle did not reach {altitude:g} m in {limit:g} s")
            if self.stack.name == "PX4":
                self.stream_position(target, self.period)
            else:
                self.pump_estimate()
        if self.options.goal is None:  # the take-off point is the goal
            goal = (float(target[0]), float(target[1]), float(target[2]))
            self.options = dataclasses.replace(self.options, goal=goal)

    def stream_position(self, target: np.ndarray, seconds: float) -> None:
        """Position setpoints at ``target`` each control period for ``seconds`` of the
        autopilot's clock."""
        began, last = self.clock(), -math.inf
        while self.clock() - began < seconds:
            if self.clock() - last >= self.period:
                last = self.clock()
                self.send_setpoint(setpoints.position_message(
                    self.conn.mav, target, 0.0, self.estimate.position_time_ms, self.target[0]
                ))  # fmt: skip
            self.pump_estimate()

    def pump_estimate(self) -> None:
        """Pump until the estimate moves on; RefusalError when it stops for ESTIMATE_LOST_S."""
        before = self.estimate.position_time_ms
        if not self.wait(lambda: self.estimate.position_time_ms != before, ESTIMATE_LOST_S):
            raise RefusalError(f"the vehicle sent no estimate for {ESTIMATE_LOST_S:g} s")

    def set_offboard_mode(self) -> None:
        assert self.stack is not None
        result = self.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                              *self.stack.offboard_command)  # fmt: skip
        if result != mav.MAV_RESULT_ACCEPTED:
            raise RefusalError(
                f"{self.stack.name} refused {self.stack.offboard_name} "
                f"({_result_name(result)}); the vehicle is left as it was"
            )

    def engage(self) -> None:
        """Into the offboard mode, holding where it is until the policy takes over."""
        stack = self.stack
        assert stack is not None
        if not stack.in_offboard(self.estimate.custom_mode):
            if stack.name == "PX4":
                self.stream_position(self.here(), STREAM_FIRST_S)
            self.set_offboard_mode()
            self.wait(lambda: stack.in_offboard(self.estimate.custom_mode), ACK_WAIT_S)

    def fly(self) -> int:
        assert self.stack is not None
        goal = np.array(self.options.goal if self.options.goal is not None else self.here())
        self.say(f"{self.stack.offboard_name}: the policy flies to "
                 f"({goal[0]:.2f}, {goal[1]:.2f}, {goal[2]:.2f}) m east, north, up")  # fmt: skip
        began, last_action, heard = self.clock(), -math.inf, time.monotonic()
        next_report = time.monotonic() + REPORT_S
        try:
            while True:
                if self.pump(0.01):
                    heard = time.monotonic()
                e = self.estimate
                if not self.stack.in_offboard(e.custom_mode):
                    self.say(f"the vehicle left {self.stack.offboard_name} (the pilot or a "
                             "failsafe took it): the companion stops")  # fmt: skip
                    return 0
                if not e.armed:
                    self.say("the vehicle disarmed: the companion stops")
                    return 0
                if time.monotonic() - heard > ESTIMATE_LOST_S:
                    return self.hand_back(f"no estimate for {ESTIMATE_LOST_S:g} s", 1)
                now = self.clock()
                if self.options.duration is not None and now - began >= self.options.duration:
                    return self.hand_back(f"{self.options.duration:g} s flown", 0)
                if now - last_action < self.period - 1e-6:
                    continue
                last_action = now
                state = self.state()
                distance = float(np.linalg.norm(state[:3] - goal))
                if distance > self.options.max_distance:
                    limit = self.options.max_distance
                    return self.hand_back(f"{distance:.1f} m from the goal (limit {limit:g})", 1)
                action = unturned(self.pilot.action(state, goal), self.level, self.pilot.turned)
                if not np.all(np.isfinite(action)):
                    return self.hand_back(f"the policy gave a non-finite action {action}", 1)
                self.send_setpoint(setpoints.message(
                    self.conn.mav, self.level, action, e.position_time_ms,
                    self.airframe.hover_thrust_fraction, self.target[0],
                ))  # fmt: skip
                if time.monotonic() >= next_report:
                    next_report = time.monotonic() + REPORT_S
                    self.say(f"t {now - began:6.1f} s  {distance:5.2f} m from the goal")
        except KeyboardInterrupt:
            return self.hand_back("stopped (Ctrl-C)", 0)

    def state(self) -> np.ndarray:
        """The state row the policy sees (the estimate; rotor speeds from the outputs)."""
        speeds = VS.rotor_speeds(self.estimate.outputs_us, self.channels, self.airframe)
        source = "the motor outputs (SERVO_OUTPUT_RAW)" if speeds is not None else (
            "not reported: the hover speed is fed")  # fmt: skip
        if source != self.rotor_source:
            self.rotor_source = source
            self.say(f"rotor speeds: {source}")
        return VS.state_row(self.estimate, speeds, self.airframe)

    def hand_back(self, why: str, status: int) -> int:
        """Put the vehicle in the stack's hold mode; ``status``."""
        assert self.stack is not None
        result = self.command(mav.MAV_CMD_DO_SET_MODE, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                              *self.stack.hold_command)  # fmt: skip
        handed = "handed back in " + self.stack.hold_name
        if result != mav.MAV_RESULT_ACCEPTED:
            handed = (f"{self.stack.hold_name} refused ({_result_name(result)}): the "
                      "autopilot's offboard-loss failsafe takes it")  # fmt: skip
        self.say(f"{why}: {handed}")
        return status


def unturned(action: np.ndarray, level: str, turned: float) -> np.ndarray:
    """A setpoint action the policy gave in a frame turned by ``-turned`` about up (its
    observation's), in the world's: a velocity's east and north turned by ``turned``, an
    attitude's yaw plus ``turned``; body rates stay as they are."""
    if turned == 0.0:
        return action
    a = np.array(action, dtype=np.float64)
    if level == "velocity":
        c, s = math.cos(turned), math.sin(turned)
        a[0], a[1] = c * a[0] - s * a[1], s * a[0] + c * a[1]
    elif level == "attitude":
        yaw = float(np.clip(a[2], -1.0, 1.0)) * math.pi + turned
        a[2] = ((yaw + math.pi) % (2 * math.pi) - math.pi) / math.pi
    return a


def _result_name(result: int) -> str:
    entry = mav.enums["MAV_RESULT"].get(result)
    return entry.name if entry is not None else str(result)
