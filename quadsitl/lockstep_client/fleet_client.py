"""The learner's end of the motor path: every vehicle of one simulator process stepped by
one round trip, and resent until answered.

Talks to ``quadsitl sim --vehicles N --lockstep --hil udpin:HOST:PORT``. A round is one
datagram of SET_ACTUATOR_CONTROL_TARGET, one per vehicle (``target_system`` addresses
it; ``time_usec`` is the simulated time the command applies from), answered by one
datagram (or a few, for large fleets) holding each vehicle's ACTUATOR_OUTPUT_STATUS,
NAMED_VALUE_INT ``CONTACT``, NAMED_VALUE_FLOAT ``TD_SPEED`` (on the ground only) and
ODOMETRY, stamped with the time after the step. An answer is matched to its round by
that time, so a late one is never taken for the next. A lost command or a lost answer:
the commands of the vehicles still unanswered are sent again, unchanged, after 2.5
usual round trips (at least 1 ms, at most ``resend_after``); the simulator steps a round
once and answers a repeat without stepping again. :class:`SimulatorError` only when no
answer comes back for ``timeout`` seconds.

Resets are batched the same way: the reset commands (and the arming command) of every
vehicle to reset in one datagram, resent for the vehicles whose answers are missing; a
reset's answer is the first after its ACK that is where the reset put the vehicle. A
lone vehicle flown with HIL_ACTUATOR_CONTROLS is this client with one vehicle
(:class:`~.motor_client.MotorClient`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from quadsitl.lockstep_client.fleet_link import RESEND_AFTER, FleetLink, SimulatorError, resend_wait
from quadsitl.physics import layout as L
from quadsitl.wire import batch_frames as BF
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
from quadsitl.wire.state import ROW_BY_ROW, WireState

HEARTBEAT_WAIT = 2.5  # s: the shortest wait for every vehicle's heartbeat (1 Hz each)
ODOMETRY = mav.MAVLINK_MSG_ID_ODOMETRY
COMMAND_ACK = mav.MAVLINK_MSG_ID_COMMAND_ACK
HIL_STATE_QUATERNION = mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION
SET_ACTUATOR_CONTROL_TARGET = mav.MAVLink_set_actuator_control_target_message
RESET_AT = 1e-3  # m: how close to the asked position a reset's answer must be
_ACK = field_slices(mav.MAVLink_command_ack_message)
Fresh = Callable[[int, Answer], bool]  # whether vehicle i's answer is the one awaited


class FleetClient(FleetLink):
    """Lockstep rounds with the vehicles ``first_system_id`` … ``+ n − 1`` of one
    simulator process, listening at ``host``:``port`` (``first_system_id`` None: the
    system whose heartbeat comes first, for one vehicle).

    Attributes:
        time_usec: simulated time of the last complete answer (all vehicles share it).
        answer: the last answer of every vehicle, a :class:`WireState` of (n, ·) arrays.
        hil_state: the last HIL_STATE_QUATERNION (answers carry it when asked for).
        resent: rounds (and resets) that needed a resend; ``late``: answers dropped
            because they belonged to an earlier exchange.

    The socket, the frames' encoding and what the simulator says are :class:`FleetLink`'s.
    """

    def __init__(
        self,
        host: str,
        port: int,
        n: int,
        first_system_id: int | None = 1,
        timeout: float = 2.0,
        signing_key: bytes | None = None,
        resend_after: float = RESEND_AFTER,
        system_id: int = 255,
        component_id: int = 191,
    ) -> None:
        super().__init__(host, port, timeout, signing_key, system_id, component_id)
        self.n, self.first = n, first_system_id or 1
        self._learn_first = first_system_id is None
        self.resend_after = resend_after
        self.seq = 0
        self.time_usec = 0
        self.answer = _empty_answer(n)
        self.hil_state: Any = None
        self.resent = 0
        self.late = 0
        self._round: list[list[Any]] = [[] for _ in range(n)]  # each vehicle's frames
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

    def _exchange(self, groups: list[list[Any]], rows: list[int], what: str, **wanted: Any) -> Any:
        """Send ``groups`` (the frames of each vehicle of ``rows``) in one go, then
        :meth:`_collect` what they ask for."""
        self._send([frame for group in groups for frame in group])
        self._sent_at = time.monotonic()
        return self._collect(groups, rows, what, **wanted)

    # --- connecting -------------------------------------------------------------------
    def connect(self, hil_state: bool = False) -> None:
        """Introduce ourselves (the udpin link learns its peer) and wait until every
        vehicle's heartbeat has been heard (for ``timeout``, and at least HEARTBEAT_WAIT:
        each vehicle beats once a second, at its own time). Then ask for answers without
        HIL_STATE_QUATERNION (this client reads ODOMETRY; leaving it out saves encoding
        and decoding a message a step), unless ``hil_state``."""
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
                if frame.msgid == mav.MAVLINK_MSG_ID_HEARTBEAT:
                    if self._learn_first:
                        self.first, self._learn_first = frame.sysid, False
                    if self._index(frame.sysid) >= 0:
                        heard.add(self._index(frame.sysid))
        interval = (HIL_STATE_QUATERNION, 0 if hil_state else -1)
        command = mav.MAV_CMD_SET_MESSAGE_INTERVAL
        groups = [[self._command_frame(command, i, *interval)] for i in range(self.n)]
        self._exchange(groups, list(range(self.n)), "acknowledgement", awaited={command})

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
        controls = np.asarray(controls, dtype=np.float64)
        if self.signing or self.n <= ROW_BY_ROW:
            self._round = [
                [self._actuator_frame(stamp, i, row)] for i, row in enumerate(controls.tolist())
            ]
        else:  # a fleet's commands framed at once: the bytes of _actuator_frame's
            self._round = [[frame] for frame in self._actuator_frames(stamp, controls)]
        self._send([group[0] for group in self._round])
        self._sent_at = time.monotonic()

    def receive_step(self) -> WireState:
        """The second half of :meth:`step`: the answers, resending what goes missing."""
        stamp = self.time_usec
        rows = list(range(self.n))
        self._collect(self._round, rows, "state answer", fresh=lambda i, a: a.time_usec > stamp)
        self.time_usec = int(self.answer.time_usec)
        return self.answer

    def _actuator_frame(self, stamp: int, i: int, row: list[float]) -> Any:
        controls = [*row, 0.0, 0.0, 0.0, 0.0]
        if self.signing:  # signed by pymavlink when sent
            return self.mav.set_actuator_control_target_encode(
                stamp, 0, self.first + i, 1, controls
            )
        values = (stamp, *controls, 0, self.first + i, 1)
        return self._pack(SET_ACTUATOR_CONTROL_TARGET, values)

    def _actuator_frames(self, stamp: int, controls: NDArray[np.float64]) -> list[bytes]:
        """Every vehicle's unsigned command of a round (``controls`` (n, 4)), built at
        once (:mod:`quadsitl.wire.batch_frames`)."""
        n = len(controls)
        padded = np.zeros((n, 8))
        padded[:, : L.N_ROTORS] = controls
        targets = np.arange(self.first, self.first + n)
        rows = BF.payloads(SET_ACTUATOR_CONTROL_TARGET, [stamp, padded, 0, targets, 1], n)
        seqs = (self.seq + 1 + np.arange(n)) & 0xFF
        self.seq = int(seqs[-1])
        sysids = [self.mav.srcSystem] * n
        return BF.frames(SET_ACTUATOR_CONTROL_TARGET, rows, seqs, sysids, self.mav.srcComponent)

    def _pack(self, message_class: Any, values: tuple[Any, ...]) -> bytes:
        """An unsigned frame of ours, packed without pymavlink (the hot path)."""
        self.seq = (self.seq + 1) & 0xFF
        return FC.pack(message_class, values, self.seq, self.mav.srcSystem, self.mav.srcComponent)

    # --- resets -----------------------------------------------------------------------
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
        motions = [
            [*velocity_ned[k], *wire.rates_frd[k], float(wire.rotor_speeds[k, 0])]
            for k in range(len(rows))
        ]
        poses = [[*wire.position_ned[k], *wire.q_ned_frd[k]] for k in range(len(rows))]
        arm = (mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, FORCE_MAGIC)
        return self._reset(rows, motions, poses, airframes, arm)

    def _reset(
        self,
        rows: list[int],
        motions: list[list[float]],
        poses: list[list[float]],
        airframes: NDArray[np.float64] | None = None,
        then: tuple[float, ...] = (),
    ) -> WireState:
        """Stage each vehicle's motion (and airframe), reset it to its pose, then send
        the command ``then`` (none if empty), all in one datagram; the answer of every
        vehicle once each reset is acknowledged and its state is where it was put."""
        groups = []
        for k, i in enumerate(rows):
            staged = [] if airframes is None else [(STAGE_AIRFRAME, *airframes[k])]
            commands = [*staged, (STAGE_MOTION, *motions[k]), (RESET_STATE, *poses[k])]
            commands += [then] if then else []
            groups.append([self._command_frame(int(c[0]), i, *c[1:]) for c in commands])
        awaited = {int(frame.command) for frame in groups[0]}
        where = {i: np.asarray(poses[k][:3]) for k, i in enumerate(rows)}
        self._drain()

        def fresh(i: int, answer: Answer) -> bool:  # after the ACK, where it was put
            position = decode_answer([answer]).position_ned[0]
            return RESET_STATE in acks[i] and np.allclose(position, where[i], atol=RESET_AT)

        acks: dict[int, dict[int, int]] = {i: {} for i in rows}
        self._exchange(groups, rows, "reset answer", fresh=fresh, awaited=awaited, acks=acks)
        self.time_usec = int(self.answer.time_usec)  # the next round starts there
        return self.answer

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

    def __enter__(self) -> FleetClient:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    # --- answers ----------------------------------------------------------------------
    def _collect(
        self,
        groups: list[list[Any]],
        rows: list[int],
        what: str,
        fresh: Fresh | None = None,
        awaited: set[int] | frozenset[int] = frozenset(),
        acks: dict[int, dict[int, int]] | None = None,
        refuse: bool = True,
    ) -> dict[int, dict[int, int]]:
        """Collect the answers to the frames just sent (``groups``, one list per vehicle
        of ``rows``): for each vehicle its state answer (the first that ``fresh`` takes;
        None: no state awaited) and the ACKs of the commands ``awaited``, sending again
        the frames of those still missing after a few usual round trips. A refused
        command raises :class:`SimulatorError` (unless not ``refuse``). The results of
        the ACKs, by vehicle and command (kept in ``acks`` if given)."""
        if acks is None:
            acks = {i: {} for i in rows} if awaited else {}
        answered = {i: fresh is None for i in rows}

        def done(i: int) -> bool:
            return answered[i] and (not awaited or awaited <= acks[i].keys())

        # A vehicle's answer is taken once: a later one is an older exchange's repeat.
        once = lambda i, a: not answered[i] and fresh is not None and fresh(i, a)  # noqa: E731
        # Silence is measured from the last progress (an answer completed): heartbeats
        # or refusals alone do not keep a stuck round alive.
        progress = sent_at = self._sent_at
        wait = resend_wait(self.round_trip, self.resend_after)
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
                if i in answered and self._take(i, frame, once, reader, acks, refuse, awaited):
                    answered[i] = True
                    progress = time.monotonic()
        self._store(rows)
        if not resent and not awaited:
            took = time.monotonic() - self._sent_at
            mean = self.round_trip
            self.round_trip = took if math.isnan(mean) else 0.9 * mean + 0.1 * took
        return acks

    def _take(
        self,
        i: int,
        frame: FC.Frame,
        fresh: Fresh,
        reader: AnswerReader,
        acks: dict[int, dict[int, int]],
        refuse: bool,
        awaited: set[int] | frozenset[int],
    ) -> bool:
        """Use one frame of vehicle i's answer (:class:`~quadsitl.wire.answer.AnswerReader`);
        True when it completes a fresh answer, kept for :meth:`_store`."""
        msgid = frame.msgid
        if msgid == COMMAND_ACK:
            values = frame.unpack()
            command, result = values[_ACK["command"].start], values[_ACK["result"].start]
            if refuse and command in awaited and result != mav.MAV_RESULT_ACCEPTED:
                text = self.statustexts[-1] if self.statustexts else "no reason given"
                raise SimulatorError(
                    f"system {frame.sysid} refused command {command} (MAV_RESULT {result}): {text}"
                )
            acks.setdefault(i, {})[command] = result
            return False
        if msgid == HIL_STATE_QUATERNION:  # PX4's view of the same state (when asked for)
            self.hil_state = FC.message(mav.mavlink_map[msgid], frame.unpack())
            return False
        if msgid not in ANSWER_IDS:
            return False
        answer = reader.take(i, msgid, frame.unpack())
        if msgid != ODOMETRY:
            return False
        if answer is None or not fresh(i, answer):
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
