"""Waiting for the simulator's next answer, as both lockstep clients (the single one and
the fleet's) wait: a short poll, then a sleep."""

from __future__ import annotations

import os
import select
import socket
import time

from quadsitl.wire.addresses import MAX_DATAGRAM

SPIN_SECONDS = 0.002  # poll this long for an answer before sleeping in select()


def next_datagram(sock: socket.socket, until: float) -> bytes | None:
    """The next datagram on the non-blocking ``sock``, or None at ``until`` (monotonic).
    Polls for the first SPIN_SECONDS (an answer is usually tens of microseconds away,
    and waking from select() costs about as much again), yielding the core to a
    simulator that shares it; then sleeps in select(). ConnectionRefusedError (ICMP:
    nothing listens at the address) is the caller's to word."""
    started = time.monotonic()
    while True:
        try:
            return sock.recv(MAX_DATAGRAM)
        except BlockingIOError:
            now = time.monotonic()
            if now >= until:
                return None
            if now - started < SPIN_SECONDS:
                os.sched_yield()
                continue
            select.select([sock], [], [], until - now)
