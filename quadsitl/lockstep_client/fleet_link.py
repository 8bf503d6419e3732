"""The lockstep client's socket to one simulator process: frames out, frames in, texts
kept, and the words of its errors.

One UDP socket to the simulator's motor-command link. Frames go out in as few datagrams
as fit (:func:`quadsitl.wire.fast_codec.datagrams`), pymavlink messages encoded (and
signed, with a key) as they are sent; a message sent again keeps its sequence number
(the simulator knows a resent HIL_ACTUATOR_CONTROLS by it) and is signed anew (a signed
frame sent twice is a replay, which the simulator refuses). Frames come in parsed by the
fast codec, polled for a moment before select() sleeps. The simulator's STATUSTEXTs are
kept, and one saying that it serves another client ends the exchange at once. The
lockstep rounds, resets and resends on top of it are :class:`~.fleet_client.FleetClient`'s.
"""

from __future__ import annotations

import math
import socket
from collections import deque
from typing import Any

from quadsitl.lockstep_client.datagrams import next_datagram
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.addresses import MAX_DATAGRAM, is_loopback
from quadsitl.wire.answer import field_slices
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.lockstep import BUSY_PREFIX, OWNER_SILENCE
from quadsitl.wire.signing import keep_signing_clock, sign_outgoing
from quadsitl.wire.statustext import TextJoiner

_TEXT = field_slices(mav.MAVLink_statustext_message)
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


class FleetLink:
    """A UDP socket to the simulator at ``host``:``port``, ``timeout`` s of silence
    allowed, signing with ``signing_key`` if given, sending as ``system_id``/``component_id``.

    Attributes:
        statustexts: the last 100 texts the simulator sent.
    """

    def __init__(
        self,
        host: str,
        port: int,
        timeout: float,
        signing_key: bytes | None = None,
        system_id: int = 255,
        component_id: int = 191,
    ) -> None:
        self.address = (host, port)
        self.timeout = timeout
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1" if is_loopback(host) else "0.0.0.0", 0))
        self.sock.setblocking(False)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 2**20)
        self._frames: list[bytes] = []
        self.mav = mav.MAVLink(_Sink(self._frames), srcSystem=system_id, srcComponent=component_id)
        self.signing = signing_key is not None
        if signing_key is not None:
            sign_outgoing(self.mav, signing_key, link_id=0)
        self.statustexts: deque[str] = deque(maxlen=100)
        self._texts = TextJoiner()  # a long STATUSTEXT being put together

    def _encode(self, message: Any) -> bytes:
        """``message``'s frame: the next sequence number, or the one it was first sent
        with (a resend), signed anew with a key."""
        if self.signing:
            keep_signing_clock(self.mav)
        if not message.get_msgbuf():  # never sent
            self.mav.send(message)
            return self._frames.pop()
        following = self.mav.seq
        self.mav.seq = message.get_seq()
        self.mav.send(message)
        self.mav.seq = following
        return self._frames.pop()

    def _send(self, items: list[Any]) -> None:
        """Frames in as few datagrams as fit. An item is a packed frame or a pymavlink
        message, encoded now (:meth:`_encode`)."""
        frames = [item if isinstance(item, bytes) else self._encode(item) for item in items]
        for datagram in FC.datagrams(frames) if frames else ():
            self.sock.sendto(datagram, self.address)

    def _receive(self, until: float) -> list[FC.Frame]:
        """The frames of the datagrams that arrive before ``until`` (wall, monotonic);
        returns as soon as one datagram has been read (:func:`next_datagram`)."""
        try:
            data = next_datagram(self.sock, until)
        except ConnectionRefusedError:
            raise SimulatorError(f"nothing listens at {self._where()}") from None
        return [] if data is None else self._parse(data)

    def _parse(self, data: bytes) -> list[FC.Frame]:
        """The frames of a datagram; its texts kept (:meth:`_text`)."""
        frames = list(FC.parse(data))
        for frame in frames:
            if frame.msgid == mav.MAVLINK_MSG_ID_STATUSTEXT:
                values = frame.unpack()
                text = self._texts.take(
                    values[_TEXT["text"].start],
                    values[_TEXT["id"].start],
                    values[_TEXT["chunk_seq"].start],
                )
                if text is not None:
                    self._text(text)
        return frames

    def _drain(self) -> None:
        """Drop what is waiting, but keep its texts: late answers of earlier exchanges,
        which an answer that cannot be told by its time must not be taken for."""
        while True:
            try:
                self._parse(self.sock.recv(MAX_DATAGRAM))
            except (BlockingIOError, ConnectionRefusedError):
                return

    def _text(self, text: str) -> None:
        """Keep a text; one saying the simulator belongs to another client ends the
        exchange at once (waiting would not change it)."""
        self.statustexts.append(text)
        refused = refusal(text, self._where())
        if refused is not None:
            raise refused

    def _where(self) -> str:
        return f"{self.address[0]}:{self.address[1]}"

    def _silent(self, what: str) -> SimulatorError:
        recent = "; ".join(list(self.statustexts)[-3:])
        return SimulatorError(
            f"no {what} from the simulator at {self._where()} within {self.timeout:g} s"
            + (f" (it said: {recent})" if recent else "")
        )


class _Sink:
    def __init__(self, frames: list[bytes]) -> None:
        self.frames = frames

    def write(self, data: bytes) -> None:
        self.frames.append(bytes(data))
