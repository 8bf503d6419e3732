"""The motor path: motor commands in, rounds flown, each vehicle's state out.

A motor command is a vehicle's normalised rotor speeds u in [0, 1] (Ω = u·Ω_max, rotor
order of the airframe). It comes in one of two messages, both handled here in one way:

- SET_ACTUATOR_CONTROL_TARGET, addressed to a vehicle by ``target_system`` and stamped
  with the simulated time of the round it is for (docs/mavlink.md, "A fleet in
  lockstep"); a command stamped with any other time is refused;
- HIL_ACTUATOR_CONTROLS, PX4's message for a lone vehicle (``mode`` bit 128 the armed
  flag, clear: motors stopped; ``flags`` bit 0 lockstep; ``time_usec`` the time of the
  state it was computed from, 0 or never going back): a round of one.

:class:`MotorPath` holds the commands of a round until every vehicle has its own, then
flies them: the onboard controllers are bypassed, and in lockstep the group advances
exactly one control period in one call of the physics. Every command is answered,
accepted or not (:meth:`MotorPath.answer`): a refused one changes nothing and is
answered with the unchanged state, a repeat of a vehicle's last lockstep command (its
client lost the answer: the same round's stamp, or the same HIL frame) with the state,
without stepping again. Simulated time moves only with lockstep commands while they
come (:meth:`MotorPath.in_lockstep`).

Pure: no sockets. The fleet server routes the messages here and sends the answers.
"""

from __future__ import annotations

import math
import time
from collections.abc import Hashable, Sequence
from typing import NamedTuple

import numpy as np

from quadsitl.flight_software.stepping import Stepping
from quadsitl.physics import layout as L
from quadsitl.simulator.links import Link
from quadsitl.simulator.motor_slot import MotorSlot, answer_parts, lean_answer_frames
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.lockstep import ARMED_FLAG, LOCKSTEP_FLAG, check_controls
from quadsitl.wire.state import ROW_BY_ROW
from quadsitl.wire.units import rotor_speed, to_time_usec

LOCKSTEP_IDLE = 5.0  # wall s without lockstep commands before real time resumes
# (only when lockstep was asked for by the commands; ``--lockstep`` waits for ever)


class MotorCommand(NamedTuple):
    """One vehicle's motor command, as its message says it."""

    row: int  # the vehicle, in its batch
    controls: list[float]  # normalised rotor speeds u of its four rotors
    armed: bool  # False: the command stops the motors
    steps: bool  # lockstep: its round advances simulated time one control period
    key: Hashable  # what a resend of it repeats: the round's stamp, or the HIL frame
    stamp: int  # µs, its time_usec (0: unstamped)
    problem: tuple[str, str] | None  # (kind, reason) its message's own rule refuses it for


class Reply(NamedTuple):
    """What a command asks of the fleet server."""

    rows: list[int]  # the vehicles to answer (none while the round waits for commands)
    warnings: list[tuple[int, str]]  # (vehicle, text) worth a STATUSTEXT


class MotorPath:
    """The motor path of the vehicles of ``batch``, one ``slots`` entry each, in row
    order. ``lockstep``: started with --lockstep (simulated time waits for commands)."""

    def __init__(self, batch: Stepping, slots: Sequence[MotorSlot], lockstep: bool = False):
        if [slot.row for slot in slots] != list(range(len(batch.vehicles))):
            raise ValueError("the motor path needs one slot per vehicle of its batch, in order")
        self.batch, self.slots = batch, list(slots)
        self.always_lockstep = lockstep
        self.last_wall = -math.inf  # wall s of the last lockstep command
        self.pending: dict[int, MotorCommand] = {}  # vehicle: its command of this round
        self.rounds = 0  # rounds stepped

    # --- the lockstep clock -----------------------------------------------------------
    def in_lockstep(self, wall_now: float) -> bool:
        """Whether simulated time moves only with motor commands: always with
        ``--lockstep``, else until LOCKSTEP_IDLE wall seconds after the last one."""
        return self.always_lockstep or wall_now - self.last_wall < LOCKSTEP_IDLE

    @property
    def round_start(self) -> int:
        """µs: the simulated time of the vehicles (they share a clock)."""
        return to_time_usec(self.slots[0].vehicle.time)

    # --- the two messages -------------------------------------------------------------
    def round_command(self, row: int, stamp: int, controls: Sequence[float]) -> Reply:
        """SET_ACTUATOR_CONTROL_TARGET to vehicle ``row``, stamped ``stamp`` µs."""
        now = self.round_start
        problem = None
        if stamp != now:
            reason = f"motor command refused: stamped {stamp} µs, the round starts at {now} µs"
            problem = ("wrong_round", reason)
        controls = list(controls[: L.N_ROTORS])
        return self.command(MotorCommand(row, controls, True, True, stamp, stamp, problem))

    def hil_command(
        self,
        sender: tuple[int, int, int],
        time_usec: int,
        flags: int,
        controls: Sequence[float],
        mode: int,
    ) -> Reply:
        """HIL_ACTUATOR_CONTROLS to the lone vehicle from ``sender`` (system, component,
        sequence number): a round of one. The same frame again is its repeat."""
        last = self.slots[0].last_stamp
        problem = None
        if time_usec and time_usec < last:
            reason = f"motor command rejected: time {time_usec} µs is before the last command's"
            problem = ("time_backwards", f"{reason} {last} µs")
        steps = bool(flags & LOCKSTEP_FLAG) or self.always_lockstep
        key = (sender, time_usec, flags, tuple(controls), mode)
        armed, rotors = bool(mode & ARMED_FLAG), list(controls[: L.N_ROTORS])
        return self.command(MotorCommand(0, rotors, armed, steps, key, time_usec, problem))

    # --- one round --------------------------------------------------------------------
    def command(self, command: MotorCommand) -> Reply:
        """Take one vehicle's command: a repeat of its last lockstep command is answered
        without flying it again; a command with bad controls (or that its message's rule
        refuses) is counted and answered, changing nothing; any other joins its round,
        which flies once every vehicle has its command (each vehicle is then answered)."""
        slot = self.slots[command.row]
        if command.steps and command.key == slot.last_key:
            slot.counters["repeats"] += 1
            self.last_wall = time.monotonic()
            return Reply([command.row], [])
        problem = check_controls(command.controls) or command.problem
        if problem is not None:
            reason = slot.reject(*problem)
            return Reply([command.row], [] if reason is None else [(command.row, reason)])
        self.pending[command.row] = command
        if command.steps:
            self.last_wall = time.monotonic()
        if len(self.pending) < len(self.slots):
            return Reply([], [])
        return Reply(list(range(len(self.slots))), self._fly())

    def _fly(self) -> list[tuple[int, str]]:
        """Fly the round whose commands are all here: Ω = u·Ω_max of each airframe, 0
        where the command or the vehicle is disarmed; in lockstep, one control period
        of every vehicle (:meth:`Stepping.advance <quadsitl.flight_software.stepping.Stepping.
        advance>`). Returns the warnings of the vehicles."""
        commands = [self.pending[row] for row in range(len(self.slots))]
        self.pending.clear()
        warnings = []
        for command, slot in zip(commands, self.slots, strict=True):
            warning = slot.take(command.armed)
            if warning is not None:
                warnings.append((command.row, warning))
        vehicles = [slot.vehicle for slot in self.slots]
        flying = np.array([c.armed and v.armed for c, v in zip(commands, vehicles, strict=True)])
        max_speed = np.array([v.airframe.max_rotor_speed for v in vehicles])  # rad/s
        controls = np.array([c.controls for c in commands], dtype=np.float64)
        self.batch.rotor_cmd[:] = rotor_speed(controls, (max_speed * flying)[:, np.newaxis])
        for command, slot in zip(commands, self.slots, strict=True):
            slot.last_key = command.key if command.steps else None
            if command.stamp:
                slot.last_stamp = command.stamp
        if any(command.steps for command in commands):
            self.batch.advance()
            self.rounds += 1
        return warnings

    # --- the answer -------------------------------------------------------------------
    def answer(
        self, link: Link, rows: list[int], full: bool, hil_state: Sequence[bool] = ()
    ) -> list[list[bytes]]:
        """The frames of vehicles ``rows``' answers (:func:`~.motor_slot.answer_parts`)
        for ``link``: its sequence numbers, its signing."""
        slots = [self.slots[row] for row in rows]
        signer = link.signing()
        if signer is None and not full and len(slots) > ROW_BY_ROW and _one_component(slots):
            return lean_answer_frames(slots, link.next_seq)  # a fleet's round, at once
        return [
            [
                FC.pack(cls, values, link.next_seq(slot.system_id), slot.system_id,
                        slot.component_id, signer)
                for cls, values in parts
            ]
            for slot, parts in zip(slots, answer_parts(slots, full, hil_state), strict=True)
        ]  # fmt: skip


def _one_component(slots: Sequence[MotorSlot]) -> bool:
    return len({slot.component_id for slot in slots}) == 1
