"""Where MAVLink travels: link URLs, the loopback rule, the datagram limit, a free port.

URLs follow pymavlink: ``udpout:HOST:PORT`` sends to HOST:PORT, ``udpin:HOST:PORT``
listens, ``tcpin:HOST:PORT`` accepts TCP clients; an empty HOST means 127.0.0.1. Both
ends use these: the simulator's links and the bridges bind the loopback interface for a
loopback peer (nobody off this host can reach them), and so do the clients.
"""

from __future__ import annotations

import ipaddress
import socket

LOOPBACK = "127.0.0.1"
MAX_DATAGRAM = 65535  # bytes: the largest UDP datagram, what a receive asks for


def free_udp_port(host: str = LOOPBACK) -> int:
    """A UDP port on ``host`` that nothing uses right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((host, 0))
        return int(probe.getsockname()[1])


def parse_url(url: str) -> tuple[str, str, int]:
    """('udpout'|'udpin'|'tcpin', host, port); ValueError naming the problem."""
    try:
        kind, host, port_text = url.split(":")
        port = int(port_text)
    except ValueError:
        raise ValueError(
            f"link {url!r}: expected KIND:HOST:PORT, e.g. udpout:127.0.0.1:14550"
        ) from None
    if kind not in ("udpout", "udpin", "tcpin"):
        raise ValueError(f"link {url!r}: kind must be udpout, udpin or tcpin, got {kind!r}")
    if not 0 <= port <= 65535:
        raise ValueError(f"link {url!r}: port {port} out of range")
    return kind, host or LOOPBACK, port


def is_loopback(host: str) -> bool:
    """True for an address (or name) of this host's loopback interface."""
    try:
        return ipaddress.ip_address(socket.gethostbyname(host)).is_loopback
    except (OSError, ValueError):
        return False
