"""Who may command a simulator on its motor link: one client at a time.

The first peer to send the motor link anything but a HEARTBEAT owns it. Until it hands
it back (COMMAND_LONG ``RELEASE_LOCKSTEP``, which the lockstep clients send on
``close()``) or falls silent for OWNER_SILENCE seconds, everything another peer sends
there is refused: not dispatched, answered only by a STATUSTEXT naming the owner, and
nothing sent on the link reaches it. A silent owner that speaks again takes the link
back if nobody else has.

Pure: no sockets. The fleet server asks :meth:`Ownership.admit` for every message.
"""

from __future__ import annotations

import hashlib
import hmac
import math
from typing import Any

from quadsitl.simulator.signing import NEW_STREAM_SLACK, SIGNED_FLAG
from quadsitl.wire.lockstep import BUSY_PREFIX, OWNER_SILENCE
from quadsitl.wire.signing import now_timestamp

REFUSAL_PERIOD = 0.5  # s: at most one refusal text a peer in this time


def where(address: Any) -> str:
    """``HOST:PORT`` of a peer address."""
    return f"{address[0]}:{address[1]}" if isinstance(address, tuple) else str(address)


class Ownership:
    """The owner of one motor link and the peers refused meanwhile."""

    def __init__(self) -> None:
        self.owner: Any = None
        self.heard = -math.inf  # wall s of the owner's last datagram
        self.refused = 0
        self._told: dict[Any, float] = {}  # refused peer: when it was last told

    def admit(self, address: Any, kind: str, now: float, may_take: bool = True) -> bool:
        """Whether a message of ``kind`` from ``address`` may be handled. A stranger's
        HEARTBEAT (a client introducing itself) takes nothing; anything else it sends
        takes a free link (unless not ``may_take``: e.g. not validly signed)."""
        if self.owner is not None and now - self.heard > OWNER_SILENCE:
            self.owner = None  # gone silent: whoever speaks next may take it
        if address == self.owner:
            self.heard = now
            return True
        if self.owner is None:
            if kind != "HEARTBEAT" and may_take:
                self.owner, self.heard = address, now
            return True
        self.refused += 1
        return False

    def release(self, address: Any) -> None:
        """The owner hands the link back (anyone else's release is ignored)."""
        if address == self.owner:
            self.owner = None
            self._told.clear()

    def tell(self, address: Any, now: float) -> str | None:
        """The refusal text to send a refused peer, at most every REFUSAL_PERIOD."""
        if now - self._told.get(address, -math.inf) < REFUSAL_PERIOD:
            return None
        if len(self._told) > 1000:  # many forged sources: forget the oldest
            self._told.clear()
        self._told[address] = now
        return BUSY_PREFIX + where(self.owner)


def may_take(check: Any, message: Any) -> bool:
    """With signing on (``check``, a :class:`~quadsitl.simulator.signing.SignatureCheck`),
    whether ``message`` is signed with the key and newer than its stream's last frame,
    without moving the stream on (the server checks it again when it handles it): an
    unsigned, forged or replayed frame never takes the link."""
    if check is None:
        return True
    frame = bytes(message.get_msgbuf())
    if not message.get_header().incompat_flags & SIGNED_FLAG or len(frame) <= 13:
        return False
    digest = hashlib.sha256(check.key + frame[:-6]).digest()[:6]
    if not hmac.compare_digest(digest, frame[-6:]):
        return False
    stamp = int.from_bytes(frame[-12:-6], "little")
    header = message.get_header()
    last = check.streams.get((frame[-13], header.srcSystem, header.srcComponent))
    if last is None:
        return stamp + NEW_STREAM_SLACK >= now_timestamp()
    return stamp > last
