"""The motor path: HIL_ACTUATOR_CONTROLS in, the vehicle's state out, lockstep, reset.

PX4 semantics: ``controls[0..3]`` are normalised rotor speed commands in [0, 1]
(Ω = u·Ω_max, rotor order of the airframe), ``mode`` bit 128 is the armed flag (clear:
motors stopped), ``flags`` bit 0 asks for lockstep. Each accepted command bypasses the
onboard controller; in lockstep it advances simulated time by exactly one control
period. Every command is answered, accepted or not, by the state at full precision,
stamped with simulated time (see :meth:`MotorPath.state_messages`). A rejected command
changes nothing: its answer carries the unchanged time.

Reset for training episodes is two ``COMMAND_LONG``\\s, each ACKed: MAV_CMD_USER_2
stages velocity, body rates and rotor speed; MAV_CMD_USER_1 sets position and attitude
and applies what was staged, then answers with the state after its ACK. Before them,
MAV_CMD_USER_4 may stage the airframe of the episode (seven factors of the preset's
parameters, :data:`~quadsitl.vehicle.episodes.AIRFRAME_NAMES`); without it the reset
draws one (``quadsitl sim --randomize``) or flies the preset. A reset also starts the
vehicle's delay line afresh (:mod:`quadsitl.vehicle.episodes`).

Pure: no sockets. The server sends what the methods return.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.mavlink import mavlink as mav
from quadsitl.physics import layout as L
from quadsitl.vehicle import external_control as X
from quadsitl.vehicle.episodes import check_factors
from quadsitl.vehicle.results import ACCEPTED, Outcome, Result
from quadsitl.vehicle.vehicle import Vehicle
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.answer import answer_parts
from quadsitl.wire.lockstep import ARMED_FLAG, LOCKSTEP_FLAG, check_controls
from quadsitl.wire.state import WireState
from quadsitl.wire.units import STANDARD_GRAVITY, rotor_speed, to_time_usec

LOCKSTEP_IDLE = 5.0  # wall s without lockstep commands before real time resumes
# (only when lockstep was asked for by the flag; ``--lockstep`` waits for ever)

_encoder = mav.MAVLink(None)


def _int16(x: float) -> int:
    return int(max(-32767, min(32767, round(x))))


def fly(
    paths: Sequence[MotorPath],
    controls: Any,
    armed: Sequence[bool],
    rotor_cmd: np.ndarray,
) -> list[str | None]:
    """Fly one round of checked motor commands, one per vehicle of ``paths``: the
    vehicle's HIL_ACTUATOR_CONTROLS (a round of one) or a fleet's round. ``controls``
    (k, 4) normalised rotor speeds u in [0, 1]; ``armed`` (k,) what each command says;
    ``rotor_cmd`` (k, 4) rad/s, the vehicles' rotor commands, written here: Ω = u·Ω_max
    of the airframe, 0 where the command or the vehicle is disarmed. Returns each
    vehicle's warning worth a STATUSTEXT, or None."""
    warnings = [path.take(on) for path, on in zip(paths, armed, strict=True)]
    vehicles = [path.vehicle for path in paths]
    flying = np.array([on and v.armed for on, v in zip(armed, vehicles, strict=True)])
    max_speed = np.array([v.airframe.max_rotor_speed for v in vehicles])  # rad/s
    controls = np.asarray(controls, dtype=np.float64)
    rotor_cmd[:] = rotor_speed(controls, (max_speed * flying)[:, np.newaxis])
    return warnings


class MotorPath:
    """State of the motor path for one vehicle. ``lockstep``: started with --lockstep.
    The airframes and delays of its episodes are its batch's
    (:class:`~quadsitl.vehicle.episodes.MotorEpisodes`), in the vehicle's row."""

    def __init__(
        self,
        vehicle: Vehicle,
        lockstep: bool = False,
    ) -> None:
        self.vehicle = vehicle
        self.episodes, self.row = vehicle.batch.episodes, vehicle.row
        self.staged_airframe: np.ndarray | None = None
        self.flown_since_reset = True  # a reset before any command repeats the last one
        self.always_lockstep = lockstep
        self.last_lockstep_wall = -math.inf
        self.last_command_usec = 0
        self.resets = 0
        self.staged: dict[str, Any] | None = None
        self.counters = {"accepted": 0, "rejected": 0, "while_disarmed": 0, "repeats": 0}
        self.last_frame: tuple[Any, ...] | None = None  # the last lockstep command applied
        self._previous_velocity: tuple[float, np.ndarray] | None = None

    @property
    def lockstep(self) -> bool:
        """True while simulated time moves only with motor commands."""
        idle = time.monotonic() - self.last_lockstep_wall
        return self.always_lockstep or idle < LOCKSTEP_IDLE

    # --- motor commands ---------------------------------------------------------------
    def check(self, msg: Any) -> tuple[str, str] | None:
        """(kind, reason) why this HIL_ACTUATOR_CONTROLS must be rejected, or None."""
        problem = check_controls(msg.controls[: L.N_ROTORS])
        if problem is not None:
            return problem
        if msg.time_usec and msg.time_usec < self.last_command_usec:
            return "time_backwards", (
                f"motor command rejected: time {msg.time_usec} µs is before the last "
                f"command's {self.last_command_usec} µs"
            )
        return None

    def reject(self, kind: str, reason: str) -> str | None:
        """Count a rejected motor command; the reason, when it is worth a STATUSTEXT (the
        first of each kind, then every 100th)."""
        self.counters["rejected"] += 1
        self.counters[kind] = self.counters.get(kind, 0) + 1
        return reason if self.counters[kind] % 100 == 1 else None

    def command(self, msg: Any) -> str | None:
        """Apply one motor command (and step, in lockstep). Returns a problem worth
        reporting: the first rejection of each kind (then every 100th), or the first
        command ignored by a disarmed vehicle (then every 1000th). In lockstep, the same
        frame again (same sender, sequence number and content: a client resending after
        a lost answer) is answered without stepping again."""
        lockstep = bool(msg.flags & LOCKSTEP_FLAG) or self.always_lockstep
        frame = (
            msg.get_srcSystem(),
            msg.get_srcComponent(),
            msg.get_seq(),
            bytes(msg.get_payload()),
        )
        if lockstep and frame == self.last_frame:
            self.counters["repeats"] += 1
            self.last_lockstep_wall = time.monotonic()
            return None
        problem = self.check(msg)
        if problem is not None:
            return self.reject(*problem)
        controls = [msg.controls[: L.N_ROTORS]]  # a round of one
        armed = [bool(msg.mode & ARMED_FLAG)]
        (warning,) = fly([self], controls, armed, self.vehicle.rotor_cmd[np.newaxis])
        if msg.time_usec:
            self.last_command_usec = msg.time_usec
        self.last_frame = frame if lockstep else None
        if lockstep:
            self.last_lockstep_wall = time.monotonic()
            self.vehicle.advance()
        return warning

    def take(self, armed: bool = True) -> str | None:
        """Count one checked motor command and hand the rotors to it (the caller sets
        their speeds: :func:`fly`); ``armed`` False: the command stops the motors.
        Returns a warning worth a STATUSTEXT, or None."""
        v = self.vehicle
        warning = None
        self.flown_since_reset = True
        if not v.armed and armed:
            self.counters["while_disarmed"] += 1
            if self.counters["while_disarmed"] % 1000 == 1:
                warning = "motor commands ignored: vehicle disarmed (arm it first)"
        X.motor_command(v, None)
        self.counters["accepted"] += 1
        return warning

    # --- reset ------------------------------------------------------------------------
    def stage_airframe(self, params: list[float]) -> Result:
        """MAV_CMD_USER_4: the next reset's airframe, seven factors of the preset's
        parameters (mass, inertia, thrust, torque, drag, aerodynamic moment
        coefficients, motor rate), each in [0.1, 10]."""
        problem = check_factors(params[:7])
        if problem is not None:
            return Result(Outcome.DENIED, problem)
        self.staged_airframe = np.array(params[:7], dtype=np.float64)
        return ACCEPTED

    def stage_motion(self, params: list[float]) -> Result:
        """MAV_CMD_USER_2: velocity NED (m/s), body rates FRD (rad/s), rotor speed
        (rad/s, all four; NaN: hover speed if airborne), used by the next reset."""
        motion = params[:6]
        if not all(math.isfinite(x) for x in motion):
            return Result(Outcome.DENIED, "stage motion denied: NaN or inf")
        rotor = params[6]
        if not (math.isnan(rotor) or 0.0 <= rotor <= self.vehicle.airframe.max_rotor_speed):
            return Result(Outcome.DENIED, f"stage motion denied: rotor speed {rotor} rad/s")
        self.staged = {"velocity_ned": motion[:3], "rates_frd": motion[3:6], "rotor": rotor}
        return ACCEPTED

    def reset(self, params: list[float]) -> Result:
        """MAV_CMD_USER_1: position local NED (m), attitude quaternion w, x, y, z
        (FRD -> NED); with the staged motion (else at rest)."""
        if not all(math.isfinite(x) for x in params):
            return Result(Outcome.DENIED, "reset denied: NaN or inf in position or attitude")
        q = np.asarray(params[3:7], dtype=np.float64)
        if np.linalg.norm(q) < 1e-6:
            return Result(Outcome.DENIED, "reset denied: attitude quaternion is zero")
        staged = self.staged or {"velocity_ned": [0.0] * 3, "rates_frd": [0.0] * 3}
        v = self.vehicle
        q = q / np.linalg.norm(q)
        velocity_ned = np.asarray(staged["velocity_ned"], dtype=np.float64)
        velocity_frd = frames.quat_rotate(frames.quat_conjugate(q), velocity_ned)
        wire = WireState(
            time_usec=0,
            position_ned=np.asarray(params[:3], dtype=np.float64),
            q_ned_frd=q,
            velocity_frd=velocity_frd,
            rates_frd=np.asarray(staged["rates_frd"], dtype=np.float64),
            rotor_speeds=np.zeros(L.N_ROTORS),
            contact=L.AIRBORNE,
            touchdown_speed=0.0,
        )
        state = wire.to_physics(v.airframe.gear_height)
        rotor = staged.get("rotor", math.nan)
        on_ground = state[L.I_PZ] <= v.airframe.gear_height + 1e-6
        if math.isnan(rotor):
            rotor = 0.0 if on_ground else v.airframe.hover_rotor_speed
        state[L.ROTORS] = rotor
        result = X.reset_state(v, state)
        if result.ok:
            self.episodes.new_episode(self.row, self.staged_airframe, self.flown_since_reset)
            self.flown_since_reset = False
            self.staged, self.staged_airframe = None, None
            self.last_frame = None  # a command after a reset is never a repeat
            self.resets += 1
            self._previous_velocity = None
        return result

    # --- the answer -------------------------------------------------------------------
    def state_messages(self, hil_state: bool = True) -> list[Any]:
        """The answer to a motor command or a reset, in this order: HIL_STATE_QUATERNION
        (PX4's simulator state; integer position/velocity; left out when ``hil_state`` is
        False, which a client asks for with SET_MESSAGE_INTERVAL −1), ACTUATOR_OUTPUT_STATUS
        (rotor speeds, rad/s), NAMED_VALUE_INT ``CONTACT`` (0 airborne, 1 on the ground,
        2 crashed), NAMED_VALUE_FLOAT ``TD_SPEED`` (touchdown speed, m/s; only when not
        airborne) and last ODOMETRY (float32 pose and body-frame velocity)."""
        v = self.vehicle
        time_usec = to_time_usec(v.time)
        # what the delay line lets the controller see (without delays: the truth)
        states, contacts, touchdowns = self.episodes.observed([self.row])
        state, contact, touchdown = states[0], int(contacts[0]), touchdowns[0]
        wire = WireState.from_physics(
            state, v.airframe.gear_height, time_usec, contact, float(touchdown)
        )
        messages = [self._hil_state_quaternion(wire, state)] if hil_state else []
        columns = (
            wire.position_ned.tolist(),
            wire.q_ned_frd.tolist(),
            wire.velocity_frd.tolist(),
            wire.rates_frd.tolist(),
            wire.rotor_speeds.tolist(),
        )
        parts = answer_parts(time_usec, columns, contact, wire.touchdown_speed, self.resets)
        return messages + [FC.message(cls, values) for cls, values in parts]

    def _hil_state_quaternion(self, wire: WireState, state: np.ndarray) -> Any:
        v = self.vehicle
        lat, lon, alt = wire.global_position(v.origin)
        velocity_ned = frames.enu_to_ned(state[L.VEL])
        # Specific force (what an accelerometer reads), body FRD, over the last period:
        # the acceleration minus the simulated gravity.
        accel_ned = np.array([0.0, 0.0, -v.airframe.gravity])
        if self._previous_velocity is not None and v.time > self._previous_velocity[0]:
            t0, v0 = self._previous_velocity
            accel_ned += (velocity_ned - v0) / (v.time - t0)
        accel_frd = frames.quat_rotate(frames.quat_conjugate(wire.q_ned_frd), accel_ned)
        self._previous_velocity = (v.time, velocity_ned)
        speed = float(np.linalg.norm(velocity_ned)) * 100
        mg = accel_frd / STANDARD_GRAVITY * 1000
        return _encoder.hil_state_quaternion_encode(
            wire.time_usec,
            list(wire.q_ned_frd),
            *(float(x) for x in wire.rates_frd),
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            *(_int16(x * 100) for x in velocity_ned),
            min(round(speed), 65535),
            min(round(speed), 65535),
            *(_int16(x) for x in mg),
        )
