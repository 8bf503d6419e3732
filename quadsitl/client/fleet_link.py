"""The fleet client's socket to one simulator process: frames out, frames in, texts kept.

One UDP socket to the simulator's motor-command link. Frames go out in as few datagrams
as fit (:func:`quadsitl.wire.fast_codec.datagrams`), pymavlink messages encoded (and
signed, with a key) as they are sent; frames come in parsed by the fast codec, polled
for a moment before select() sleeps. The simulator's STATUSTEXTs are kept, and one
saying that it serves another client ends the exchange at once. The lockstep rounds,
resets and resends on top of it are :class:`~.fleet_client.FleetClient`'s.
"""

from __future__ import annotations

import socket
from collections import deque
from typing import Any

from quadsitl.client.datagrams import next_datagram
from quadsitl.client.motor_client import SimulatorError, refusal
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.addresses import is_loopback
from quadsitl.wire.answer import field_slices
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.signing import keep_signing_clock, sign_outgoing
from quadsitl.wire.statustext import TextJoiner

_TEXT = field_slices(mav.MAVLink_statustext_message)


class FleetLink:
    """A UDP socket to the simulator at ``host``:``port``, ``timeout`` s of silence
    allowed, signing with ``signing_key`` if given.

    Attributes:
        statustexts: the last 100 texts the simulator sent.
    """

    def __init__(
        self, host: str, port: int, timeout: float, signing_key: bytes | None = None
    ) -> None:
        self.address = (host, port)
        self.timeout = timeout
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1" if is_loopback(host) else "0.0.0.0", 0))
        self.sock.setblocking(False)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 * 2**20)
        self._frames: list[bytes] = []
        self.mav = mav.MAVLink(_Sink(self._frames), srcSystem=255, srcComponent=191)
        self.signing = signing_key is not None
        if signing_key is not None:
            sign_outgoing(self.mav, signing_key, link_id=0)
        self.statustexts: deque[str] = deque(maxlen=100)
        self._texts = TextJoiner()  # a long STATUSTEXT being put together

    def _encode(self, message: Any) -> bytes:
        if self.signing:
            keep_signing_clock(self.mav)
        self.mav.send(message)
        return self._frames.pop()

    def _send(self, items: list[Any]) -> None:
        """Frames in as few datagrams as fit. An item is a packed frame or a pymavlink
        message, encoded now: each resend of a signed message gets a new signature (a
        signed frame sent twice is a replay, which the simulator refuses)."""
        frames = [item if isinstance(item, bytes) else self._encode(item) for item in items]
        for datagram in FC.datagrams(frames):
            self.sock.sendto(datagram, self.address)

    def _receive(self, until: float) -> list[FC.Frame]:
        """The frames of the datagrams that arrive before ``until`` (wall, monotonic);
        returns as soon as one datagram has been read (:func:`next_datagram`)."""
        try:
            data = next_datagram(self.sock, until)
        except ConnectionRefusedError:
            raise SimulatorError(f"nothing listens at {self._where()}") from None
        if data is None:
            return []
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
