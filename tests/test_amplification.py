"""No reflection: a simulator sends nothing to an address it has not heard a valid
MAVLink frame from (a validly signed one when signing is on), and forgets a peer that
falls silent. Real simulator processes and UDP sockets; bytes counted as they arrive."""

from __future__ import annotations

import contextlib
import hashlib
import socket
import time
from collections.abc import Iterator

import pytest
from pymavlink import mavutil

from gcs_tools.demo import free_udp_port
from quadsitl.simulator.links import PEER_TIMEOUT, Link
from quadsitl.wire.dialect import mavlink as mav
from quadsitl.wire.signing import sign_outgoing
from tests.conftest import running_sim

PASSPHRASE = "amplification test"
QUIET_SECONDS = 3.0  # how long a silent peer is listened to


def _bytes_received(sock: socket.socket, seconds: float) -> int:
    """Bytes arriving on ``sock`` within ``seconds``."""
    total, deadline = 0, time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        sock.settimeout(left)
        try:
            total += len(sock.recv(65535))
        except TimeoutError:
            break
    return total


def _heartbeat(signing_key: bytes | None = None) -> bytes:
    encoder = mav.MAVLink(None, srcSystem=240, srcComponent=190)
    if signing_key is not None:
        sign_outgoing(encoder, signing_key, 3)
    return encoder.heartbeat_encode(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(
        encoder
    )


@contextlib.contextmanager
def _answering_sim(port: int, *options: str) -> Iterator[None]:
    """A simulator whose only link listens on ``port``, from when it answers."""
    sim = f"sim --gcs udpin:127.0.0.1:{port} --api none --logs none"
    with running_sim(sim, *options, ports=(port,)):
        probe = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=250)
        key = _key() if "--signing-passphrase" in options else None
        if key is not None:
            probe.setup_signing(key, sign_outgoing=True)
        try:
            deadline = time.monotonic() + 60
            while not probe.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5):
                if time.monotonic() > deadline:
                    raise AssertionError("the simulator did not answer within 60 s")
                probe.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        finally:
            probe.close()
        yield


def _key() -> bytes:
    return hashlib.sha256(PASSPHRASE.encode()).digest()


@pytest.mark.parametrize("vehicles", [1, 4])
def test_one_junk_byte_brings_back_nothing_a_valid_frame_brings_telemetry(vehicles):
    port = free_udp_port()
    with (
        _answering_sim(port, "--vehicles", str(vehicles)),
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as peer,
    ):
        peer.sendto(b"\x00", ("127.0.0.1", port))
        assert _bytes_received(peer, QUIET_SECONDS) == 0
        peer.sendto(_heartbeat(), ("127.0.0.1", port))
        assert _bytes_received(peer, 2.0) > 0


def test_with_signing_only_a_signed_frame_brings_telemetry():
    port = free_udp_port()
    with (
        _answering_sim(port, "--signing-passphrase", PASSPHRASE),
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as peer,
    ):
        peer.sendto(b"\x00", ("127.0.0.1", port))
        peer.sendto(_heartbeat(), ("127.0.0.1", port))  # valid, but unsigned
        peer.sendto(_heartbeat(hashlib.sha256(b"wrong").digest()), ("127.0.0.1", port))
        assert _bytes_received(peer, QUIET_SECONDS) == 0
        peer.sendto(_heartbeat(_key()), ("127.0.0.1", port))
        assert _bytes_received(peer, 2.0) > 0


def test_a_peer_that_falls_silent_is_forgotten():
    """At the link: a live peer gets what is sent until PEER_TIMEOUT after its last
    accepted frame; then it is dropped. A peer that only sent junk never gets anything."""
    link = Link("udpin:127.0.0.1:0", "gcs", 1, 1)
    address = ("127.0.0.1", link.local_port)
    with (
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as station,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as junk,
    ):
        try:
            station.sendto(_heartbeat(), address)
            junk.sendto(b"\x00\x01", address)
            deadline = time.monotonic() + 5
            received = []
            while len(link.peers) < 2 and time.monotonic() < deadline:
                received += link.receive()
            ((message, peer),) = received
            assert message.get_type() == "HEARTBEAT"
            link.accept(peer)  # as the server does with a frame that passes its checks
            link.send_bytes(b"telemetry")
            assert _bytes_received(station, 1.0) == len(b"telemetry")
            assert _bytes_received(junk, 0.2) == 0
            for each in link.peers.values():  # as if PEER_TIMEOUT had passed
                each.last_seen -= PEER_TIMEOUT + 1
            peer.heard -= PEER_TIMEOUT + 1
            link.send_bytes(b"telemetry")
            assert _bytes_received(station, 0.5) == 0
            assert link.peers == {}
        finally:
            link.close()
