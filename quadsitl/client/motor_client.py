"""The external controller's end of the motor path: a small, fast lockstep client.

Talks to ``quadsitl sim --hil udpin:HOST:PORT`` (or any of its links) over one UDP
socket with its own pymavlink codec: HIL_ACTUATOR_CONTROLS out, the state answer
(:class:`~quadsitl.wire.state.WireState`, read by :func:`~quadsitl.wire.answer.decode_answer`
as the fleet client reads it) back. Used by the lockstep benchmark;
an example for anyone writing their own.

Lost datagrams are resent as the fleet client resends them (:func:`resend_wait`): what
goes unanswered goes again after 2.5 usual round trips (at least 1 ms, at most
``resend_after``, doubling while nothing comes back), as the same frames (same
sequence numbers), which the simulator recognises: a repeated lockstep command is
answered without stepping again; the commands (arm, the reset pair) are idempotent.
:class:`SimulatorError` only when nothing answers for ``timeout`` seconds.
"""

from __future__ import annotations

import math
import socket
import time
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from quadsitl.client.datagrams import next_datagram
from quadsitl.physics import layout as L
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.addresses import MAX_DATAGRAM, is_loopback
from quadsitl.wire.answer import ANSWER_IDS, AnswerReader, decode_answer
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import (
    ARMED_FLAG,
    BUSY_PREFIX,
    FORCE_MAGIC,
    LOCKSTEP_FLAG,
    OWNER_SILENCE,
    RELEASE_LOCKSTEP,
    RESET_STATE,
    STAGE_MOTION,
    check_controls,
)
from quadsitl.wire.signing import keep_signing_clock, sign_outgoing
from quadsitl.wire.state import WireState
from quadsitl.wire.statustext import TextJoiner

RESEND_AFTER = 0.05  # s: the longest wait for an answer before the commands go again
MIN_RESEND_AFTER = 0.001  # s: the shortest; in between, RESEND_ROUND_TRIPS usual round trips
RESEND_ROUND_TRIPS = 2.5


class SimulatorError(RuntimeError):
    """The simulator did not answer in time, or refused a command."""


def resend_wait(round_trip: float, longest: float) -> float:
    """How long to wait for an answer before sending again: RESEND_ROUND_TRIPS usual
    round trips (``round_trip``, NaN while unknown), within MIN_RESEND_AFTER..``longest``."""
    if math.isnan(round_trip):
        return longest
    return min(longest, max(MIN_RESEND_AFTER, RESEND_ROUND_TRIPS * round_trip))


def refusal(text: str, where: str) -> SimulatorError | None:
    """The error for a simulator's text saying it belongs to another client, or None."""
    if not text.startswith(BUSY_PREFIX):
        return None
    return SimulatorError(
        f"the simulator at {where} is {text}: a lockstep simulator serves one client at a "
        f"time (it is free once that client closes, or after {OWNER_SILENCE:g} s of its "
        "silence; docs/security.md)"
    )


def _fields(frame: FC.Frame) -> Any:
    """A frame's message with its fields by name (pymavlink's object)."""
    return FC.message(mav.mavlink_map[frame.msgid], frame.unpack())


class _Capture:
    def __init__(self) -> None:
        self.frame = b""

    def write(self, data: bytes) -> None:
        self.frame = bytes(data)


class MotorClient:
    """Lockstep motor commands to one simulated vehicle.

    Args:
        host, port: where the simulator's link listens (``udpin``).
        timeout: wall seconds to wait for any answer before :class:`SimulatorError`.
        signing_key: 32-byte MAVLink 2 key if the simulator requires signing.
        system_id, component_id: this client's MAVLink identity.
        resend_after: the longest wait for an answer before sending again.

    Attributes:
        resent: exchanges that needed a resend.
    """

    def __init__(
        self,
        host: str,
        port: int,
        timeout: float = 2.0,
        signing_key: bytes | None = None,
        system_id: int = 255,
        component_id: int = 191,
        resend_after: float = RESEND_AFTER,
    ) -> None:
        self.address = (host, port)
        self.timeout, self.resend_after = timeout, resend_after
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1" if is_loopback(host) else "0.0.0.0", 0))
        self.sock.setblocking(False)
        self._out = _Capture()
        self.mav = mav.MAVLink(self._out, srcSystem=system_id, srcComponent=component_id)
        if signing_key is not None:
            sign_outgoing(self.mav, signing_key, link_id=0)
        self.target_system = 1
        self.statustexts: deque[str] = deque(maxlen=100)
        self.state: WireState | None = None
        self.hil_state: Any = None  # the last HIL_STATE_QUATERNION received
        self.resent = 0
        self.round_trip = math.nan  # s, running mean of exchanges answered without a resend
        self._answers = AnswerReader()  # the state answer being read
        self._texts = TextJoiner()
        self._inbox: deque[FC.Frame] = deque()
        self._controls = [0.0] * 16
        self._outgoing: tuple[int, list[Any], float] = (0, [], 0.0)  # seq, messages, sent at
        self._later_than: int | None = None  # the time a step's answer must be later than

    # --- plumbing ---------------------------------------------------------------------
    def _send(self, messages: list[Any], seq: int | None = None) -> None:
        """``messages`` in one datagram (from sequence number ``seq``: the same frames
        again, each signed anew, for a resend); kept for :meth:`_exchange` to resend."""
        if seq is None:
            seq = self.mav.seq
            self._outgoing = (seq, messages, time.monotonic())
        self.mav.seq = seq
        frames = []
        for message in messages:
            if self.mav.signing.sign_outgoing:
                keep_signing_clock(self.mav)
            self.mav.send(message)
            frames.append(self._out.frame)
        self.sock.sendto(b"".join(frames), self.address)

    def _receive(self, deadline: float) -> None:
        """Queue the next datagram's messages, waiting until ``deadline`` for one."""
        try:
            data = next_datagram(self.sock, deadline)
        except ConnectionRefusedError:
            raise SimulatorError(f"nothing listens at {self.address}") from None
        if data is not None:
            self._inbox.extend(FC.parse(data))

    def _drain(self) -> None:
        """Drop what is waiting but the texts: late answers of earlier exchanges (a
        resend's), which an answer that cannot be told by its time must not be taken for."""
        pending = list(self._inbox)
        self._inbox.clear()
        while True:
            try:
                pending += FC.parse(self.sock.recv(MAX_DATAGRAM))
            except (BlockingIOError, ConnectionRefusedError):
                break
        for frame in pending:
            if frame.msgid == mav.MAVLINK_MSG_ID_STATUSTEXT:
                self._collect(frame)

    def _exchange(self, what: str, done: Any, eager: bool = False) -> Any:
        """Wait for the frame that completes the exchange just sent (``done(frame,
        answered)`` True; ``answered``: it completed a state answer, now :attr:`state`),
        sending the same frames again while it does not come; that frame.
        ``eager``: resend after a few usual round trips (a lockstep step, whose repeat
        the simulator recognises), else after ``resend_after`` (a command: the fewer
        needless repeats, the fewer late acknowledgements)."""
        seq, messages, sent_at = self._outgoing
        deadline = sent_at + self.timeout
        wait = resend_wait(self.round_trip, self.resend_after) if eager else self.resend_after
        resent = False
        while True:
            while self._inbox:
                frame = self._inbox.popleft()
                if done(frame, self._collect(frame)):
                    if not resent:
                        took = time.monotonic() - self._outgoing[2]
                        mean = self.round_trip
                        self.round_trip = took if math.isnan(mean) else 0.9 * mean + 0.1 * took
                    return frame
            now = time.monotonic()
            if now >= deadline:
                break
            if now - sent_at > wait:
                self.resent += 1
                resent = True
                self._send(messages, seq)
                sent_at = now
                wait = min(2 * wait, self.resend_after)  # back off while nothing comes
            self._receive(min(deadline, sent_at + wait))
        recent = "; ".join(list(self.statustexts)[-3:])
        raise SimulatorError(
            f"no {what} from the simulator at {self.address[0]}:{self.address[1]} within "
            f"{self.timeout:g} s" + (f" (it said: {recent})" if recent else "")
        )

    def _wait_for(self, wanted: int, what: str, accept: Any = None) -> Any:
        """The next message of id ``wanted`` (that ``accept`` takes, given its fields by
        name), resending meanwhile; its fields."""
        frame = self._exchange(
            what,
            lambda f, _: f.msgid == wanted and (accept is None or accept(_fields(f))),
        )
        return _fields(frame)

    def _collect(self, frame: FC.Frame) -> bool:
        """Keep texts, and the parts of a state answer until its closing ODOMETRY
        arrives; True when this frame completed one (now :attr:`state`)."""
        msgid = frame.msgid
        if msgid == mav.MAVLINK_MSG_ID_STATUSTEXT:
            message = _fields(frame)
            text = self._texts.take(message._text_raw, message.id, message.chunk_seq)
            if text is not None:
                self.statustexts.append(text)
                refused = refusal(text, f"{self.address[0]}:{self.address[1]}")
                if refused is not None:
                    raise refused
        elif msgid == mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION:
            self.hil_state = _fields(frame)  # PX4's view of the same state (when asked for)
        elif msgid in ANSWER_IDS:
            answer = self._answers.take(0, msgid, frame.unpack())
            if answer is not None:
                self.state = decode_answer([answer]).row(0)
                return True
        return False

    # --- the vehicle ------------------------------------------------------------------
    def connect(self, hil_state: bool = False) -> None:
        """Introduce ourselves (a udpin link learns its peers) and wait for a heartbeat.
        Unless ``hil_state``, ask for answers without HIL_STATE_QUATERNION (this client
        reads ODOMETRY; leaving it out saves encoding and decoding a message a step)."""
        hello = self.mav.heartbeat_encode(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        self._send([hello])
        heartbeat = self._exchange(
            "heartbeat", lambda f, _: f.msgid == mav.MAVLINK_MSG_ID_HEARTBEAT
        )
        self.target_system = heartbeat.sysid
        interval = 0 if hil_state else -1
        self.command(
            mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_HIL_STATE_QUATERNION, interval
        )

    def _command_long(self, command: int, *params: float) -> Any:
        values = list(params) + [0.0] * (7 - len(params))
        return self.mav.command_long_encode(self.target_system, 1, command, 0, *values)

    def command(self, command: int, *params: float) -> int:
        """COMMAND_LONG and its MAV_RESULT (up to 7 params; missing ones are 0), resent
        until acknowledged."""
        self._send([self._command_long(command, *params)])
        ack = self._wait_for(
            mav.MAVLINK_MSG_ID_COMMAND_ACK,
            f"COMMAND_ACK for {command}",
            lambda m: m.command == command,
        )
        return int(ack.result)

    def arm(self, force: bool = True) -> None:
        """Arm (forced by default: training starts in the air)."""
        result = self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1, FORCE_MAGIC if force else 0)
        if result != mav.MAV_RESULT_ACCEPTED:
            raise SimulatorError(f"arming refused (MAV_RESULT {result}): {self._last_text()}")

    def reset(
        self,
        position_ned: ArrayLike,
        q_ned_frd: ArrayLike = (1.0, 0.0, 0.0, 0.0),
        velocity_ned: ArrayLike = (0.0, 0.0, 0.0),
        rates_frd: ArrayLike = (0.0, 0.0, 0.0),
        rotor_speed: float = math.nan,
    ) -> WireState:
        """Put the vehicle in a state (local NED; see docs/mavlink.md); the state after it.
        Both reset commands go in one datagram (a loss takes both or neither), resent
        together until the reset's ACK and the state after it arrive."""
        motion = [*np.asarray(velocity_ned, float), *np.asarray(rates_frd, float), rotor_speed]
        pose = [*np.asarray(position_ned, float), *np.asarray(q_ned_frd, float)]
        self._drain()
        self._send(
            [self._command_long(STAGE_MOTION, *motion), self._command_long(RESET_STATE, *pose)]
        )
        results: dict[int, int] = {}
        where = np.asarray(position_ned, float)

        def done(frame: FC.Frame, answered: bool) -> bool:
            if frame.msgid == mav.MAVLINK_MSG_ID_COMMAND_ACK:
                ack = _fields(frame)
                if ack.command in (STAGE_MOTION, RESET_STATE):
                    results[ack.command] = int(ack.result)
                    return ack.result != mav.MAV_RESULT_ACCEPTED
            # The state follows the ACK, and is where the reset put it (a late answer
            # of an earlier reset, resent, is not taken for it).
            return (
                answered
                and RESET_STATE in results
                and self.state is not None
                and np.allclose(self.state.position_ned, where, atol=1e-3)
            )

        self._exchange("state after reset", done)
        refused = [r for r in results.values() if r != mav.MAV_RESULT_ACCEPTED]
        if refused:
            raise SimulatorError(f"reset refused (MAV_RESULT {refused[0]}): {self._last_text()}")
        assert self.state is not None
        return self.state

    def step(self, controls: ArrayLike, armed: bool = True, lockstep: bool = True) -> WireState:
        """Send normalised rotor commands in [0, 1]; the state one control period later."""
        self.send_controls(controls, armed, lockstep)
        return self.receive_state()

    def send_controls(self, controls: ArrayLike, armed: bool = True, lockstep: bool = True) -> None:
        """The first half of :meth:`step` (to drive several simulators at once)."""
        self._controls[: L.N_ROTORS] = [float(u) for u in np.asarray(controls).reshape(-1)]
        stamp = self.state.time_usec if self.state is not None else 0
        # A command the simulator steps for is answered with a later time; any other
        # (real time, or one it refuses) with the time it has.
        steps = lockstep and check_controls(self._controls[: L.N_ROTORS]) is None
        self._later_than = stamp if steps and self.state is not None else None
        if self._later_than is None:
            self._drain()
        self._send(
            [
                self.mav.hil_actuator_controls_encode(
                    stamp,
                    self._controls,
                    ARMED_FLAG if armed else 0,
                    LOCKSTEP_FLAG if lockstep else 0,
                )
            ]
        )

    def receive_state(self) -> WireState:
        """The second half of :meth:`step`: wait for the state answer (an answer of an
        earlier step, arriving late, is not taken for it)."""
        after = self._later_than

        def done(_: FC.Frame, answered: bool) -> bool:
            return answered and (after is None or self._state_time() > after)

        self._exchange("state answer", done)
        assert self.state is not None
        return self.state

    def _state_time(self) -> int:
        assert self.state is not None  # an answer has just been read
        return int(self.state.time_usec)

    def _last_text(self) -> str:
        return self.statustexts[-1] if self.statustexts else "no reason given"

    def close(self) -> None:
        """Hand the simulator back (it then serves the next client at once) and close."""
        try:
            for _ in range(2):  # no answer awaited: sent twice against a loss
                self._send([self._command_long(RELEASE_LOCKSTEP)])
        except OSError:
            pass
        self.sock.close()

    def __enter__(self) -> MotorClient:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()
