"""One vehicle's place in the motor path (:mod:`.motor_path`): what it counts, the last
command it flew (a repeat of it is not flown again), the reset staged for its next
training episode, and the state answer (:func:`answer_parts`, the one builder of it).

Reset for training episodes is two ``COMMAND_LONG``\\s, each ACKed: MAV_CMD_USER_2
stages velocity, body rates and rotor speed; MAV_CMD_USER_1 sets position and attitude
and applies what was staged, then answers with the state after its ACK. Before them,
MAV_CMD_USER_4 may stage the airframe of the episode (seven factors of the preset's
parameters, :data:`~quadsitl.flight_software.episodes.AIRFRAME_NAMES`); without it the reset
draws one (``quadsitl sim --randomize``) or flies the preset. A reset also starts the
vehicle's delay line afresh (:mod:`quadsitl.flight_software.episodes`).

Pure: no sockets.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np

from quadsitl import frames
from quadsitl.flight_software import external_control as X
from quadsitl.flight_software.episodes import check_factors
from quadsitl.flight_software.results import ACCEPTED, Outcome, Result
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.physics import layout as L
from quadsitl.wire import answer as A
from quadsitl.wire import batch_frames as BF
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.state import ROW_BY_ROW, WireState
from quadsitl.wire.units import STANDARD_GRAVITY, to_time_usec

Part = tuple[Any, tuple[Any, ...]]  # a message class and its values in wire order
WIRE_FIELDS = ("position_ned", "q_ned_frd", "velocity_frd", "rates_frd", "rotor_speeds")
HIL_STATE_QUATERNION = mav.MAVLink_hil_state_quaternion_message
ACTUATOR_OUTPUT_STATUS = mav.MAVLink_actuator_output_status_message
ODOMETRY = mav.MAVLink_odometry_message


def _int16(x: float) -> int:
    return int(max(-32767, min(32767, round(x))))


class MotorSlot:
    """One vehicle of the motor path, sending as ``system_id``/``component_id``. The
    airframes and delays of its episodes are its batch's
    (:class:`~quadsitl.flight_software.episodes.MotorEpisodes`), in the vehicle's row."""

    def __init__(self, vehicle: Vehicle, system_id: int = 1, component_id: int = 1) -> None:
        self.vehicle = vehicle
        self.system_id, self.component_id = system_id, component_id
        self.episodes, self.row = vehicle.batch.episodes, vehicle.row
        self.staged_airframe: np.ndarray | None = None
        self.staged: dict[str, Any] | None = None
        self.flown_since_reset = True  # a reset before any command repeats the last one
        self.last_key: Hashable | None = None  # the last lockstep command flown, as a key
        self.last_stamp = 0  # µs, the time_usec of the last command flown
        self.resets = 0
        self.counters = {"accepted": 0, "rejected": 0, "while_disarmed": 0, "repeats": 0}
        self._previous_velocity: tuple[float, np.ndarray] | None = None

    # --- motor commands ---------------------------------------------------------------
    def reject(self, kind: str, reason: str) -> str | None:
        """Count a rejected motor command; the reason, when it is worth a STATUSTEXT (the
        first of each kind, then every 100th)."""
        self.counters["rejected"] += 1
        self.counters[kind] = self.counters.get(kind, 0) + 1
        return reason if self.counters[kind] % 100 == 1 else None

    def take(self, armed: bool = True) -> str | None:
        """Count one checked motor command and hand the rotors to it (the motor path sets
        their speeds); ``armed`` False: the command stops the motors. Returns a warning
        worth a STATUSTEXT (the first command a disarmed vehicle ignores, then every
        1000th), or None."""
        v = self.vehicle
        warning = None
        self.flown_since_reset = True
        if not v.armed and armed:
            self.counters["while_disarmed"] += 1
            if self.counters["while_disarmed"] % 1000 == 1:
                warning = "motor commands ignored: vehicle disarmed (arm it first)"
        X.motor_command(v)
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
        (FRD -> NED); with the staged motion (else at rest). A command after a reset is
        never a repeat of one before it."""
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
            self.last_key = None
            self.resets += 1
            self._previous_velocity = None
        return result

    def state_messages(self, hil_state: bool = True) -> list[Any]:
        """The answer to a reset, as messages (they follow its ACK): :func:`answer_parts`
        of this vehicle, full."""
        (parts,) = answer_parts([self], full=True, hil_state=[hil_state])
        return [FC.message(cls, values) for cls, values in parts]

    def hil_state_quaternion(self, wire: WireState, state: np.ndarray) -> Part:
        """HIL_STATE_QUATERNION (PX4's simulator state) of the vehicle in ``wire``
        (``state``: its physics state), with the specific force over the last period."""
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
        speed = min(round(float(np.linalg.norm(velocity_ned)) * 100), 65535)  # cm/s
        values = (
            wire.time_usec,
            *(float(x) for x in wire.q_ned_frd),
            *(float(x) for x in wire.rates_frd),
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            *(_int16(x * 100) for x in velocity_ned),
            speed,
            speed,
            *(_int16(x) for x in accel_frd / STANDARD_GRAVITY * 1000),  # mG
        )
        return HIL_STATE_QUATERNION, values


def answer_parts(
    slots: Sequence[MotorSlot], full: bool, hil_state: Sequence[bool] = ()
) -> list[list[Part]]:
    """The state answer of each vehicle of ``slots`` (of one batch: they share a clock),
    stamped with simulated time, at full precision: ACTUATOR_OUTPUT_STATUS (rotor speeds,
    rad/s), NAMED_VALUE_INT ``CONTACT`` (0 airborne, 1 on the ground, 2 crashed),
    NAMED_VALUE_FLOAT ``TD_SPEED`` (touchdown speed, m/s; only when not airborne) and
    last ODOMETRY (:func:`quadsitl.wire.answer.answer_parts`). The state is what the
    delay line lets the controller see (without delays: the truth). ``full``: CONTACT
    even when airborne, and first HIL_STATE_QUATERNION for the vehicles ``hil_state``
    names (a lone vehicle's HIL_ACTUATOR_CONTROLS and resets are answered so, unless
    the client turned it off with SET_MESSAGE_INTERVAL −1); else lean (a fleet's rounds:
    no CONTACT means airborne)."""
    first = slots[0]
    rows = [slot.row for slot in slots]
    time_usec = to_time_usec(first.vehicle.time)
    gears = first.vehicle.batch.physics.params[rows, L.P_GEAR_HEIGHT].tolist()
    states, contact_rows, touchdown_rows = first.episodes.observed(rows)
    contacts, touchdowns = contact_rows.tolist(), touchdown_rows.tolist()
    if len(rows) <= ROW_BY_ROW:  # a whole-array conversion costs more for a few
        wires = [
            WireState.from_physics(state, gear, time_usec, contact, touchdown)
            for state, gear, contact, touchdown in zip(
                states, gears, contacts, touchdowns, strict=True
            )
        ]
        columns = [[getattr(w, f).tolist() for w in wires] for f in WIRE_FIELDS]
    else:
        batch = WireState.from_physics(states, np.array(gears), time_usec, None, None)
        columns = [getattr(batch, f).tolist() for f in WIRE_FIELDS]
    out = []
    for k, slot in enumerate(slots):
        state = tuple(column[k] for column in columns)
        parts = A.answer_parts(
            time_usec, state, contacts[k], touchdowns[k], slot.resets, lean=not full
        )
        if full and hil_state[k]:
            wire = WireState.from_physics(states[k], gears[k], time_usec, contacts[k], 0.0)
            parts.insert(0, slot.hil_state_quaternion(wire, states[k]))
        out.append(parts)
    return out


def lean_answer_frames(slots: Sequence[MotorSlot], next_seq: Any) -> list[list[bytes]]:
    """The frames of :func:`answer_parts` (lean: a fleet's round), unsigned, of more than
    ROW_BY_ROW vehicles: the same bytes as packing each part with
    :func:`~quadsitl.wire.fast_codec.pack`, ACTUATOR_OUTPUT_STATUS and ODOMETRY built for
    all the vehicles at once (:mod:`quadsitl.wire.batch_frames`); ``next_seq(system_id)``:
    the link's sequence numbers, taken in the frames' order."""
    first = slots[0]
    rows = [slot.row for slot in slots]
    count = len(rows)
    time_usec = to_time_usec(first.vehicle.time)
    time_ms = (time_usec // 1000) & 0xFFFFFFFF
    gears = first.vehicle.batch.physics.params[rows, L.P_GEAR_HEIGHT]
    states, contacts, touchdowns = first.episodes.observed(rows)
    wire = WireState.from_physics(states, gears, time_usec, None, None)
    outputs = np.zeros((count, len(A.UNUSED_OUTPUTS) + L.N_ROTORS))
    outputs[:, : L.N_ROTORS] = wire.rotor_speeds
    actuators = BF.payloads(ACTUATOR_OUTPUT_STATUS, [time_usec, 0b1111, outputs], count)
    resets = np.array([slot.resets & 0xFF for slot in slots])
    p, q, v, r = wire.position_ned, wire.q_ned_frd, wire.velocity_frd, wire.rates_frd
    odometries = BF.payloads(
        ODOMETRY,
        [time_usec, p[:, 0], p[:, 1], p[:, 2], q, v[:, 0], v[:, 1], v[:, 2],
         r[:, 0], r[:, 1], r[:, 2], A.NAN_COVARIANCE, A.NAN_COVARIANCE,
         mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_BODY_FRD, resets,
         mav.MAV_ESTIMATOR_TYPE_UNKNOWN, 100],
        count,
    )  # fmt: skip
    sysids = [slot.system_id for slot in slots]
    component = first.component_id
    first_seqs, named, last_seqs = [], [], []
    for slot, contact, touchdown in zip(slots, contacts.tolist(), touchdowns.tolist(), strict=True):
        first_seqs.append(next_seq(slot.system_id))
        extra = []
        if contact != L.AIRBORNE:  # on the ground: CONTACT and TD_SPEED, frame by frame
            for cls, values in (
                (mav.MAVLink_named_value_int_message, (time_ms, contact, A.CONTACT)),
                (mav.MAVLink_named_value_float_message, (time_ms, touchdown, A.TD_SPEED)),
            ):
                seq = next_seq(slot.system_id)
                extra.append(FC.pack(cls, values, seq, slot.system_id, slot.component_id))
        named.append(extra)
        last_seqs.append(next_seq(slot.system_id))
    opened = BF.frames(ACTUATOR_OUTPUT_STATUS, actuators, first_seqs, sysids, component)
    closed = BF.frames(ODOMETRY, odometries, last_seqs, sysids, component)
    return [[a, *extra, o] for a, extra, o in zip(opened, named, closed, strict=True)]
