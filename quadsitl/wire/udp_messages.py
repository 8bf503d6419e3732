"""The MAVLink messages waiting on a non-blocking UDP socket, parsed."""

from __future__ import annotations

import socket
from typing import Any


def pending_messages(sock: socket.socket, parser: Any) -> list[Any]:
    """Every message in the datagrams ``sock`` holds now (none waited for), parsed by
    ``parser`` (a pymavlink ``MAVLink`` object; what it cannot parse is dropped)."""
    messages: list[Any] = []
    while True:
        try:
            data = sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return messages
        messages += parser.parse_buffer(data) or []
