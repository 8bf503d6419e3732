"""Where MAVLink travels: link URLs, the loopback rule, the datagram limit, a free port.

URLs follow pymavlink: ``udpout:HOST:PORT`` sends to HOST:PORT, ``udpin:HOST:PORT``
listens, ``tcpin:HOST:PORT`` accepts TCP clients; an empty HOST means 127.0.0.1. Both
ends use these: the simulator's links and the bridges bind the loopback interface for a
loopback peer (nobody off this host can reach them), and so do the clients.
"""

from __future__ import annotations

import ipaddress
import os
import random
import socket
import tempfile
import time
from pathlib import Path

LOOPBACK = "127.0.0.1"
EPHEMERAL_PORTS = "/proc/sys/net/ipv4/ip_local_port_range"
RESERVE_S = 60.0  # s a drawn port is kept from other draws (a simulator binds it sooner)
MAX_DATAGRAM = 65535  # bytes: the largest UDP datagram, what a receive asks for


def free_udp_port(host: str = LOOPBACK) -> int:
    """A UDP port on ``host`` that nothing uses right now, for a process about to bind
    it (a simulator that starts in a second or two). Drawn above the kernel's ephemeral
    range where it is known (Linux): a port the kernel hands out itself, to any program
    that sends or connects meanwhile, could be taken before that process binds it. And
    reserved for RESERVE_S against the same draw in other processes of this machine (a
    file per port in the temporary folder), which would otherwise hand two simulators
    one port. Else (or if none there is free) one the kernel picks."""
    high = _ephemeral_range()[1]
    if high < 65535:
        for _ in range(64):
            port = random.randint(max(high + 1, 1024), 65535)
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                try:
                    probe.bind((host, port))
                except OSError:
                    continue
            if _reserve(port):
                return port
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((host, 0))
        return int(probe.getsockname()[1])


def _reserve(port: int) -> bool:
    """Whether ``port`` is now this process's for RESERVE_S: no other process of this
    machine drew it that recently (True too where the folder cannot be written)."""
    folder = Path(tempfile.gettempdir()) / "quadsitl-udp-ports"
    mark = folder / str(port)
    try:
        folder.mkdir(exist_ok=True)
        os.close(os.open(mark, os.O_CREAT | os.O_EXCL | os.O_WRONLY))  # atomic: one wins
        return True
    except FileExistsError:
        pass
    except OSError:
        return True
    try:  # drawn before: free again once its reservation is old
        if time.time() - mark.stat().st_mtime < RESERVE_S:
            return False
        os.utime(mark)
    except OSError:
        return True
    return True


def _ephemeral_range() -> tuple[int, int]:
    """The ports the kernel hands out itself (Linux's ip_local_port_range)."""
    try:
        low, high = Path(EPHEMERAL_PORTS).read_text().split()
        return int(low), int(high)
    except (OSError, ValueError):
        return 1024, 65535  # unknown: all of them


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
