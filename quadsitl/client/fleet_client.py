"""The learner's end of a fleet in lockstep: every vehicle of one simulator process
stepped by one round trip, and resent until answered.

Talks to ``quadsitl sim --vehicles N --lockstep --hil udpin:HOST:PORT``. A round is one
datagram of SET_ACTUATOR_CONTROL_TARGET, one per vehicle (``target_system`` addresses
it; ``time_usec`` is the simulated time the command applies from), answered by one
datagram (or a few, for large fleets) holding each vehicle's ACTUATOR_OUTPUT_STATUS,
NAMED_VALUE_INT ``CONTACT``, NAMED_VALUE_FLOAT ``TD_SPEED`` (on the ground only) and
ODOMETRY, stamped with the time after the step. An answer is matched to its round by
that time, so a late one is never taken for the next. A lost command or a lost answer:
the commands of the vehicles still unanswered are sent again, unchanged, after 2.5
usual round trips (at least 1 ms, at most ``resend_after``); the simulator steps a round
once and answers a repeat from its cache. :class:`SimulatorError` only when no answer
comes back for ``timeout`` seconds.

Resets are batched the same way: the two reset commands and the arming command of every
vehicle to reset in one datagram, resent for the vehicles whose answers are missing.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quadsitl.client.fleet_link import FleetLink
from quadsitl.client.motor_client import RESEND_AFTER, SimulatorError, resend_wait
from quadsitl.physics import layout as L
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.answer import ANSWER_IDS, Answer, AnswerReader, decode_answer, field_slices
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import (
    FORCE_MAGIC,
    RELEASE_LOCKSTEP,
    RESET_STATE,
    STAGE_AIRFRAME,
    STAGE_MOTION,
)
from quadsitl.wire.state import WireState

HEARTBEAT_WAIT = 2.5  # s: the shortest wait for every vehicle's heartbeat (1 Hz each)
ODOMETRY = mav.MAVLINK_MSG_ID_ODOMETRY
COMMAND_ACK = mav.MAVLINK_MSG_ID_COMMAND_ACK
SET_ACTUATOR_CONTROL_TARGET = mav.MAVLink_set_actuator_control_target_message
RESET_COMMANDS = 3  # stage motion, reset, arm
_ACK = field_slices(mav.MAVLink_command_ack_message)


class FleetClient(FleetLink):
    """Lockstep rounds with the vehicles ``first_system_id`` … ``+ n − 1`` of one
    simulator process, listening at ``host``:``port``.

    Attributes:
        time_usec: simulated time of the last complete answer (all vehicles share it).
        answer: the last answer of every vehicle, a :class:`WireState` of (n, ·) arrays.
        resent: rounds (and resets) that needed a resend; ``late``: answers dropped
            because they belonged to an earlier round.

    The socket, the frames' encoding and what the simulator says are :class:`FleetLink`'s.
    """

    def __init__(
        self,
        host: str,
        port: int,
        n: int,
        first_system_id: int = 1,
        timeout: float = 2.0,
        signing_key: bytes | None = None,
        resend_after: float = RESEND_AFTER,
    ) -> None:
        super().__init__(host, port, timeout, signing_key)
        self.n, self.first = n, first_system_id
        self.resend_after = resend_after
        self.seq = 0
        self.time_usec = 0
        self.answer = _empty_answer(n)
        self.resent = 0
        self.late = 0
        self._round: list[list[Any]] = []
        self._rows: list[Answer | None] = [None] * n  # each vehicle's answer of this exchange
        self._sent_at = 0.0
        self.round_trip = math.nan  # s, running mean of rounds answered without a resend

    # --- plumbing ---------------------------------------------------------------------
    def _command_frame(self, command: int, index: int, *params: float) -> Any:
        """A COMMAND_LONG to vehicle ``index`` (encoded when sent: see :meth:`_send`)."""
        values = list(params) + [0.0] * (7 - len(params))
        return self.mav.command_long_encode(self.first + index, 1, command, 0, *values)

    def _index(self, sysid: int) -> int:
        """Vehicle index of a system id, or −1 for one this client does not fly."""
        index = sysid - self.first
        return index if 0 <= index < self.n else -1

    # --- connecting -------------------------------------------------------------------
    def connect(self) -> None:
        """Introduce ourselves (the udpin link learns its peer) and wait until every
        vehicle's heartbeat has been heard (for ``timeout``, and at least HEARTBEAT_WAIT:
        each vehicle beats once a second, at its own time)."""
        heard: set[int] = set()
        hello = self.mav.heartbeat_encode(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        deadline = time.monotonic() + max(self.timeout, HEARTBEAT_WAIT)
        next_hello = 0.0
        while len(heard) < self.n:
            now = time.monotonic()
            if now >= deadline:
                missing = sorted(self.first + i for i in set(range(self.n)) - heard)
                raise self._silent(f"heartbeat of system(s) {missing}")
            if now >= next_hello:
                self._send([hello])
                next_hello = now + 0.2
            for frame in self._receive(min(deadline, next_hello)):
                if frame.msgid == mav.MAVLINK_MSG_ID_HEARTBEAT and self._index(frame.sysid) >= 0:
                    heard.add(self._index(frame.sysid))
        # Answers to resets without HIL_STATE_QUATERNION (this client reads ODOMETRY).
        rows = list(range(self.n))
        leave_out = (mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, -1)
        groups = [
            [self._command_frame(mav.MAV_CMD_SET_MESSAGE_INTERVAL, i, *leave_out)] for i in rows
        ]
        self._send([group[0] for group in groups])
        self._sent_at = time.monotonic()
        acks: dict[int, set[int]] = {i: set() for i in rows}
        self._collect(groups, rows, lambda i, t: False, acks, "acknowledgement", 1, state=False)

    # --- rounds -----------------------------------------------------------------------
    def step(self, controls: NDArray[np.float64]) -> WireState:
        """One lockstep round: ``controls`` (n, 4) normalised rotor commands in [0, 1]
        (vehicle i is system ``first + i``); the answer of every vehicle, one control
        period later."""
        self.send_step(controls)
        return self.receive_step()

    def send_step(self, controls: NDArray[np.float64]) -> None:
        """The first half of :meth:`step` (to drive several simulators at once)."""
        stamp = self.time_usec
        self._round = [
            [self._actuator_frame(stamp, i, row)]
            for i, row in enumerate(np.asarray(controls, dtype=np.float64).tolist())
        ]
        self._send([group[0] for group in self._round])
        self._sent_at = time.monotonic()

    def receive_step(self) -> WireState:
        """The second half of :meth:`step`: the answers, resending what goes missing."""
        stamp = self.time_usec
        rows = list(range(self.n))
        self._collect(self._round, rows, lambda i, t: t > stamp, None, "state answer")
        self.time_usec = int(self.answer.time_usec)
        return self.answer

    def reset(
        self,
        rows: list[int],
        wire: WireState,
        velocity_ned: NDArray[np.float64],
        airframes: NDArray[np.float64] | None = None,
    ) -> WireState:
        """Put vehicles ``rows`` in the states of ``wire`` ((len(rows), ·) arrays, local
        NED, see docs/mavlink.md; ``velocity_ned`` (len(rows), 3) m/s) and arm them; the
        answer of every vehicle. ``airframes``: (len(rows), 7) factors of the preset's
        parameters each vehicle flies from this reset on (MAV_CMD_USER_4; None: the
        simulator's choice)."""
        groups = []
        for k, i in enumerate(rows):
            motion = [*velocity_ned[k], *wire.rates_frd[k], float(wire.rotor_speeds[k, 0])]
            pose = [*wire.position_ned[k], *wire.q_ned_frd[k]]
            staged = (
                [] if airframes is None else [self._command_frame(STAGE_AIRFRAME, i, *airframes[k])]
            )
            groups.append(
                [
                    *staged,
                    self._command_frame(STAGE_MOTION, i, *motion),
                    self._command_frame(RESET_STATE, i, *pose),
                    self._command_frame(mav.MAV_CMD_COMPONENT_ARM_DISARM, i, 1, FORCE_MAGIC),
                ]
            )
        acks: dict[int, set[int]] = {i: set() for i in rows}
        self._send([f for group in groups for f in group])
        self._sent_at = time.monotonic()
        # A state counts only once its reset is acknowledged (the state follows the ACK).
        needed = RESET_COMMANDS + (airframes is not None)
        fresh = lambda i, t: RESET_STATE in acks[i]  # noqa: E731
        self._collect(groups, rows, fresh, acks, "reset answer", needed)
        self.time_usec = int(self.answer.time_usec)  # the next round starts there
        return self.answer

    def _actuator_frame(self, stamp: int, i: int, row: list[float]) -> Any:
        controls = [*row, 0.0, 0.0, 0.0, 0.0]
        if self.signing:  # signed by pymavlink when sent
            return self.mav.set_actuator_control_target_encode(
                stamp, 0, self.first + i, 1, controls
            )
        self.seq = (self.seq + 1) & 0xFF
        values = (stamp, *controls, 0, self.first + i, 1)
        return FC.pack(SET_ACTUATOR_CONTROL_TARGET, values, self.seq, 255, 191)

    def _collect(
        self,
        groups: list[list[Any]],
        rows: list[int],
        fresh: Any,
        acks: dict[int, set[int]] | None,
        what: str,
        needed: int = RESET_COMMANDS,
        state: bool = True,
    ) -> None:
        """Collect answers to the frames just sent (``groups``, one list per vehicle of
        ``rows``) until each vehicle has one (and ``needed`` ACKs, with ``acks``), sending
        again the frames of those still missing after ``resend_after``."""
        answered = {i: not state for i in rows}  # ``state`` False: the ACKs are all

        def done(i: int) -> bool:
            return answered[i] and (acks is None or len(acks[i]) == needed)

        # A vehicle's answer is taken once: a later one is an older exchange's repeat.
        fresh_once = lambda i, t: not answered[i] and fresh(i, t)  # noqa: E731
        # Silence is measured from the last progress (an answer completed): heartbeats
        # or refusals alone do not keep a stuck round alive.
        progress = sent_at = self._sent_at
        wait = self._resend_wait()
        resent = False
        reader = AnswerReader()
        while not all(done(i) for i in rows):
            now = time.monotonic()
            if now - progress > self.timeout:
                raise self._silent(what)
            if now - sent_at > wait:
                self.resent += 1
                resent = True
                self._send([f for i, g in zip(rows, groups, strict=True) if not done(i) for f in g])
                sent_at = now
                wait = min(2 * wait, self.resend_after)  # back off while nothing comes
            until = min(sent_at + wait, progress + self.timeout)
            for frame in self._receive(until):
                i = self._index(frame.sysid)
                if i in answered and self._take(i, frame, fresh_once, reader, acks):
                    answered[i] = True
                    progress = time.monotonic()
        self._store(rows)
        if not resent and acks is None:
            took = time.monotonic() - self._sent_at
            mean = self.round_trip
            self.round_trip = took if math.isnan(mean) else 0.9 * mean + 0.1 * took

    def _resend_wait(self) -> float:
        return resend_wait(self.round_trip, self.resend_after)

    def _take(
        self,
        i: int,
        frame: FC.Frame,
        fresh: Any,
        reader: AnswerReader,
        acks: dict[int, set[int]] | None,
    ) -> bool:
        """Use one frame of vehicle i's answer (:class:`~quadsitl.wire.answer.AnswerReader`);
        True when it completes a fresh answer, kept for :meth:`_store`."""
        msgid = frame.msgid
        if msgid == COMMAND_ACK:
            if acks is not None:
                values = frame.unpack()
                command, result = values[_ACK["command"].start], values[_ACK["result"].start]
                if result != mav.MAV_RESULT_ACCEPTED:
                    text = self.statustexts[-1] if self.statustexts else "no reason given"
                    raise SimulatorError(
                        f"system {frame.sysid} refused command {command} (MAV_RESULT {result}): "
                        f"{text}"
                    )
                acks[i].add(command)
            return False
        if msgid not in ANSWER_IDS:
            return False
        answer = reader.take(i, msgid, frame.unpack())
        if msgid != ODOMETRY:
            return False
        if answer is None or not fresh(i, answer.time_usec):
            self.late += 1
            return False
        self._rows[i] = answer
        return True

    def _store(self, rows: list[int]) -> None:
        """Move the answers of ``rows`` into :attr:`answer` (one array write per field)."""
        taken = [i for i in rows if self._rows[i] is not None]
        if not taken:
            return
        decoded = decode_answer([self._rows[i] for i in taken])  # type: ignore[misc]
        index: Any = taken
        if len(taken) == self.n:
            index = slice(None)  # every vehicle, in order: cheaper than a list index
        self.answer.put(index, decoded)
        for i in taken:
            self._rows[i] = None

    def close(self) -> None:
        """Hand the simulator back (it then serves the next client at once; were this
        lost, it frees itself after its owner's silence) and close the socket."""
        try:
            release = self._command_frame(RELEASE_LOCKSTEP, 0)
            for _ in range(2):  # no answer awaited: sent twice against a loss
                self._send([release])
        except OSError:
            pass
        self.sock.close()


def _empty_answer(n: int) -> WireState:
    return WireState(
        time_usec=0,
        position_ned=np.zeros((n, 3)),
        q_ned_frd=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
        velocity_frd=np.zeros((n, 3)),
        rates_frd=np.zeros((n, 3)),
        rotor_speeds=np.zeros((n, L.N_ROTORS)),
        contact=np.zeros(n, np.int64),  # type: ignore[arg-type]
        touchdown_speed=np.zeros(n),  # type: ignore[arg-type]
    )
