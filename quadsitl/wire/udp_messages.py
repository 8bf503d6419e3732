"""The MAVLink messages waiting on a non-blocking UDP socket, parsed."""

from __future__ import annotations

import socket
from typing import Any

from quadsitl.wire import fast_codec as FC


def pending_messages(
    sock: socket.socket, parser: Any, fast: frozenset[int] = frozenset()
) -> list[Any]:
    """Every message in the datagrams ``sock`` holds now (none waited for), parsed by
    ``parser`` (a pymavlink ``MAVLink`` object; what it cannot parse is dropped). With
    ``fast`` message ids, the datagrams are split into frames by the fast codec, and the
    frames of those ids decoded by it (the same messages, in a fraction of the time); a
    frame that fails its checksum is dropped. An ICMP error a connected socket reports
    (its peer was not listening when it sent) is skipped, not raised: it would lose the
    messages read before it, and the datagrams behind it are still there."""
    messages: list[Any] = []
    while True:
        try:
            data = sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return messages
        except ConnectionRefusedError:
            continue  # the error is consumed by the recv that reported it
        if not fast:
            messages += parser.parse_buffer(data) or []
            continue
        for frame in FC.parse(data):
            if frame.msgid in fast:
                messages.append(FC.to_message(frame))
            else:
                messages += parser.parse_buffer(frame.data) or []
