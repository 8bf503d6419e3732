"""Two ground stations with the same system and component ids (255/190) uploading a
mission at once, against a real simulator over real UDP with pymavlink: on the GCS link
and the API link of a fleet, and as two peers of one link of a single vehicle. A transfer
belongs to the link, remote address and ids that began it: no mixed mission is ever
accepted, and each uploader hears either its own MISSION_ACK accepted or an error. The
answers go to the sender alone, in order with what the link sends to everyone."""

from __future__ import annotations

import os
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil

from gcs_tools.demo import free_udp_port
from quadsitl.simulator.links import Link
from quadsitl.wire.dialect import mavlink as mav
from tests.conftest import cli, stop_process, wait_until_listening
from tests.test_ground_station_wire import _item

GCS_IDS = (255, 190)  # what QGroundControl and MAVProxy use by default
TIMEOUT = 15.0  # s to wait for one answer (a loaded machine); never reached when right


class Uploader:
    """A ground station on its own UDP socket, uploading its own waypoints."""

    def __init__(self, port: int, target: int, north_m: float, count: int) -> None:
        self.target = target
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=GCS_IDS[0], source_component=GCS_IDS[1]
        )
        self.items = [_item(self.conn, self.target, seq, north_m + seq) for seq in range(count)]

    def connect(self) -> None:
        """Heartbeat until the vehicle's heartbeat comes back (it is starting up: on a
        loaded machine it may compile the physics first)."""
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            beat = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if beat is not None and beat.get_srcSystem() == self.target:
                return
        raise AssertionError("no heartbeat from the simulator")

    def send(self, message) -> None:  # type: ignore[no-untyped-def]
        self.conn.mav.send(message)

    def next(self, kind: str, check=None):  # type: ignore[no-untyped-def]
        """The next ``kind`` from the target vehicle to us, passing ``check``."""
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            msg = self.conn.recv_match(type=kind, blocking=True, timeout=0.1)
            if (
                msg is not None
                and msg.get_srcSystem() == self.target
                and (msg.target_system, msg.target_component) == GCS_IDS
                and (check is None or check(msg))
            ):
                return msg
        raise AssertionError(f"no {kind} within {TIMEOUT} s")

    def count(self) -> None:
        self.send(
            self.conn.mav.mission_count_encode(
                self.target, 1, len(self.items), mav.MAV_MISSION_TYPE_MISSION
            )
        )

    def upload(self) -> int:
        """A whole upload as a ground station does it: MISSION_COUNT, then each item the
        vehicle requests, until a MISSION_ACK; its result."""
        self.count()
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            msg = self.conn.recv_match(
                type=["MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=0.1
            )
            if msg is None or msg.get_srcSystem() != self.target:
                continue
            if (msg.target_system, msg.target_component) != GCS_IDS:
                continue
            if msg.get_type() == "MISSION_ACK":
                return int(msg.type)
            if 0 <= msg.seq < len(self.items):
                self.send(self.items[msg.seq])
        raise AssertionError(f"no MISSION_ACK within {TIMEOUT} s")

    def download(self) -> list[int]:
        """The latitudes (1e-7 deg) of the mission the vehicle holds."""
        self.send(
            self.conn.mav.mission_request_list_encode(self.target, 1, mav.MAV_MISSION_TYPE_MISSION)
        )
        count = self.next("MISSION_COUNT").count
        out = []
        for seq in range(count):
            self.send(
                self.conn.mav.mission_request_int_encode(
                    self.target, 1, seq, mav.MAV_MISSION_TYPE_MISSION
                )
            )
            out.append(self.next("MISSION_ITEM_INT", lambda m, s=seq: m.seq == s).x)
        self.send(self.conn.mav.mission_ack_encode(self.target, 1, mav.MAV_MISSION_ACCEPTED))
        return out

    def latitudes(self) -> list[int]:
        return [item.x for item in self.items]

    def close(self) -> None:
        self.conn.close()


@dataclass
class Setup:
    """A running simulator and the two ports the uploaders use (the same port for two
    peers of one link)."""

    sim: subprocess.Popen[str]
    ports: tuple[int, int]
    target: int


@pytest.fixture(params=["fleet-gcs-and-api-links", "one-vehicle-one-link"])
def setup(request: pytest.FixtureRequest) -> Iterator[Setup]:
    gcs, api = free_udp_port(), free_udp_port()
    if request.param == "fleet-gcs-and-api-links":
        links = f"--gcs udpin:127.0.0.1:{gcs} --api udpin:127.0.0.1:{api} --vehicles 2"
        ports, target = (gcs, api), 2
    else:
        links = f"--gcs udpin:127.0.0.1:{gcs} --api none"
        ports, target = (gcs, gcs), 1
    sim = subprocess.Popen(
        cli(f"sim {links} --logs none --speed 4"),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    wait_until_listening(sim, *set(ports))
    try:
        yield Setup(sim, ports, target)
    finally:
        stop_process(sim)


def _pair(setup: Setup) -> tuple[Uploader, Uploader]:
    a = Uploader(setup.ports[0], setup.target, 10.0, 3)
    b = Uploader(setup.ports[1], setup.target, 100.0, 4)
    a.connect()
    b.connect()
    return a, b


def test_a_second_uploader_with_the_same_ids_is_refused_and_the_first_completes(setup):
    a, b = _pair(setup)
    try:
        a.count()
        assert a.next("MISSION_REQUEST_INT").seq == 0
        a.send(a.items[0])
        a.next("MISSION_REQUEST_INT", lambda m: m.seq == 1)
        # B, with A's very ids, starts its own upload in the middle of A's and sends
        # its items anyway: told no, and none of them count.
        b.count()
        assert b.next("MISSION_ACK").type == mav.MAV_MISSION_DENIED
        for item in b.items:
            b.send(item)
        a.send(a.items[1])
        a.next("MISSION_REQUEST_INT", lambda m: m.seq == 2)
        a.send(a.items[2])
        # A's first MISSION_ACK is its own, accepted (B's refusal never reached it).
        assert a.next("MISSION_ACK").type == mav.MAV_MISSION_ACCEPTED
        assert a.download() == a.latitudes()
        # The vehicle free again, B's upload goes through.
        assert b.upload() == mav.MAV_MISSION_ACCEPTED
        assert b.download() == b.latitudes()
    finally:
        a.close()
        b.close()


def _upload(name: str, who: Uploader, go: threading.Barrier, results: dict[str, int]) -> None:
    go.wait()
    results[name] = who.upload()


def test_two_uploaders_at_once_never_leave_a_mixed_mission(setup):
    """Both upload as ground stations do, at the same moment, three times over: each
    hears an answer; an accepted one leaves exactly its items on the vehicle."""
    a, b = _pair(setup)
    try:
        for _ in range(3):
            results: dict[str, int] = {}
            go = threading.Barrier(2)
            threads = [
                threading.Thread(target=_upload, args=(name, who, go, results))
                for name, who in (("a", a), ("b", b))
            ]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join(timeout=2 * TIMEOUT)
            assert set(results) == {"a", "b"}, results
            accepted = [n for n, r in results.items() if r == mav.MAV_MISSION_ACCEPTED]
            assert accepted, results  # the first to begin finishes
            held = a.download()
            owners = {"a": a.latitudes(), "b": b.latitudes()}
            assert held in [owners[n] for n in accepted], (results, held)
    finally:
        a.close()
        b.close()


# --- the link: an answer to one peer keeps its place among what is held ---------------
def test_an_answer_to_one_peer_is_held_in_order_with_what_goes_to_every_peer():
    """A refusal's STATUSTEXT (to every peer) then its MISSION_ACK (to the sender alone),
    sent while the link holds its frames: the sender gets them in that order, and
    nobody else gets the ACK."""
    link = Link("udpin:127.0.0.1:0", "gcs", 1, 1)
    ground = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
    try:
        hello = mav.MAVLink(None, 255, 190).heartbeat_encode(6, 8, 0, 0, 0)
        for station in ground:
            station.bind(("127.0.0.1", 0))
            station.settimeout(5.0)
            station.sendto(hello.pack(mav.MAVLink(None, 255, 190)), ("127.0.0.1", link.local_port))
        peers: dict[object, object] = {}
        deadline = time.monotonic() + 5.0
        while len(peers) < 2 and time.monotonic() < deadline:
            for _, peer in link.receive():
                link.accept(peer)
                peers[peer.address] = peer
        sender = ground[0].getsockname()
        assert set(peers) == {sender, ground[1].getsockname()}
        link.hold()
        link.send_bytes(b"text to all")
        link.send_to(b"ack to one", sender)
        link.send_bytes(b"more to all")
        link.release()
        link.send_bytes(b"end")
        assert [ground[0].recv(100) for _ in range(4)] == [
            b"text to all",
            b"ack to one",
            b"more to all",
            b"end",
        ]
        assert [ground[1].recv(100) for _ in range(3)] == [b"text to all", b"more to all", b"end"]
    finally:
        link.close()
        for station in ground:
            station.close()
