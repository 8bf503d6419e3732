"""Links: UDP and TCP endpoints that carry MAVLink to any number of peers.

URLs follow pymavlink (:mod:`quadsitl.wire.addresses`): ``udpout:HOST:PORT`` sends to
HOST:PORT (where QGroundControl, MAVProxy or MAVSDK listen) and also answers anyone else
who writes to it; ``udpin:HOST:PORT`` listens and answers every peer heard from;
``tcpin:HOST:PORT`` accepts TCP clients.

Loopback unless asked otherwise: a ``udpout`` link to a loopback address binds the
loopback interface (nobody off this host can reach it), an empty HOST means
127.0.0.1, and listening on other interfaces takes an explicit address such as
``udpin:0.0.0.0:14551``. :attr:`Link.exposed` says whether a link can be reached from
other hosts. Each peer has its own parser, so a garbled datagram from one
never corrupts another's frames. Sending packs a message once per link (one sequence
number stream per link) and writes it to every live peer.

A UDP peer is live only once the server has accepted a frame from it
(:meth:`Link.accept`: a valid MAVLink frame, validly signed when signing is on), and
stays live while such frames keep coming, for PEER_TIMEOUT. A datagram with a forged
source address therefore never turns the link into a reflector that sends telemetry
to someone who did not ask for it. (A ``udpout`` destination is chosen by the user
and always gets everything; a TCP client has proved its address by connecting.)
"""

from __future__ import annotations

import contextlib
import itertools
import socket
import time
from dataclasses import dataclass, field
from typing import Any

from quadsitl.wire import fast_codec as FC
from quadsitl.wire.addresses import LOOPBACK, MAX_DATAGRAM, is_loopback, parse_url
from quadsitl.wire.dialect import mavlink
from quadsitl.wire.lockstep import OWNER_SILENCE
from quadsitl.wire.signing import now_timestamp

PEER_TIMEOUT = OWNER_SILENCE  # s without an accepted frame before a UDP peer is dropped


@dataclass
class Peer:
    address: Any
    parser: Any  # a pymavlink MAVLink object used only to parse this peer's bytes
    last_seen: float = field(default_factory=time.monotonic)  # any datagram
    sock: socket.socket | None = None  # TCP only
    heard: float | None = None  # monotonic s of the last accepted frame (UDP: live)


def _new_parser() -> Any:
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True  # bad frames come back as MAVLink_bad_data, not raise
    return parser


class Link:
    """One endpoint; see the module docstring. ``name`` labels it in logs."""

    def __init__(self, url: str, name: str, system_id: int, component_id: int) -> None:
        self.url, self.name = url, name
        self.kind, host, port = parse_url(url)
        self.system_id, self.component_id = system_id, component_id
        self.signer: FC.Signer | None = None  # signs every frame sent here (set_signing)
        self._seq: dict[int, int] = {}  # next sequence number of each system sending here
        # Frames kept back by hold(), each with its one peer's address (None: every peer).
        self._held: list[tuple[bytes, Any]] | None = None
        self._held_limit = FC.DATAGRAM_LIMIT  # bytes per datagram when released
        self.peers: dict[Any, Peer] = {}
        self.destination: tuple[str, int] | None = None
        self.only: Any = None  # when set, the one peer that hears what is sent here
        self.bad_frames = 0
        self.sent = 0
        try:
            if self.kind == "tcpin":
                self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self.sock.bind((host, port))
                self.sock.listen(8)
            else:
                self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                if self.kind == "udpin":
                    self.sock.bind((host, port))
                else:
                    self.destination = (socket.gethostbyname(host), port)
                    # Answers come from where we send: to a loopback destination, nobody
                    # off this host needs to reach us (a remote one needs every interface).
                    local = LOOPBACK if is_loopback(host) else "0.0.0.0"
                    self.sock.bind((local, 0))
        except OSError as error:
            raise OSError(f"link {url!r}: cannot open ({error.strerror or error})") from None
        self.sock.setblocking(False)

    @property
    def local_port(self) -> int:
        return int(self.sock.getsockname()[1])

    @property
    def exposed(self) -> bool:
        """Whether hosts other than this one can send to this link."""
        return not is_loopback(str(self.sock.getsockname()[0]))

    def sockets(self) -> list[socket.socket]:
        """Sockets to wait on with select()."""
        return [self.sock] + [p.sock for p in self.peers.values() if p.sock is not None]

    # --- receiving --------------------------------------------------------------------
    def receive(self, fast: frozenset[int] = frozenset()) -> list[tuple[Any, Peer]]:
        """Every complete message now waiting, with the peer it came from. Unsigned
        frames of the message ids in ``fast`` come as :class:`fast_codec.Frame` (parsed
        without pymavlink: the hot path of lockstep rounds), the rest as pymavlink
        messages."""
        out: list[tuple[Any, Peer]] = []
        if self.kind == "tcpin":
            self._accept()
            for peer in list(self.peers.values()):
                self._read_stream(peer, out)
        else:
            while True:
                try:
                    data, address = self.sock.recvfrom(MAX_DATAGRAM)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:  # e.g. ICMP port unreachable reported on a UDP socket
                    continue
                peer = self.peers.get(address) or Peer(address, _new_parser())
                self.peers[address] = peer
                peer.last_seen = time.monotonic()
                if fast:
                    self._parse_fast(peer, data, out, fast)
                else:
                    self._parse(peer, data, out)
        return out

    def _accept(self) -> None:
        while True:
            try:
                conn, address = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            conn.setblocking(False)
            self.peers[address] = Peer(address, _new_parser(), sock=conn)

    def _read_stream(self, peer: Peer, out: list[tuple[Any, Peer]]) -> None:
        assert peer.sock is not None
        while True:
            try:
                data = peer.sock.recv(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:  # closed by the client
                peer.sock.close()
                self.peers.pop(peer.address, None)
                return
            peer.last_seen = time.monotonic()
            self._parse(peer, data, out)

    def _parse(self, peer: Peer, data: bytes, out: list[tuple[Any, Peer]]) -> None:
        try:
            messages = peer.parser.parse_buffer(data) or []
        except Exception:  # pymavlink raises on some malformed input even when robust
            self.bad_frames += 1
            peer.parser = _new_parser()
            return
        for message in messages:
            if message.get_type() == "BAD_DATA":
                self.bad_frames += 1
            else:
                out.append((message, peer))

    def _parse_fast(
        self, peer: Peer, data: bytes, out: list[tuple[Any, Peer]], fast: frozenset[int]
    ) -> None:
        used = 0
        for frame in FC.parse(data):
            used += len(frame.data)
            if frame.msgid in fast and not frame.data[2] & FC.SIGNED:
                out.append((frame, peer))
            else:
                self._parse(peer, frame.data, out)
        if used < len(data):  # bytes that were no frame of a message known here
            self.bad_frames += 1

    def accept(self, peer: Peer) -> None:
        """``peer`` sent a frame the server accepts: send it what this link sends."""
        peer.heard = time.monotonic()

    # --- sending ----------------------------------------------------------------------
    def pack(self, message: Any, system_id: int | None = None) -> bytes:
        """Encode ``message`` as sent by ``system_id`` (default: the link's), with that
        system's sequence numbers on this link (and signed, if set)."""
        system = self.system_id if system_id is None else system_id
        seq = self.next_seq(system)
        return FC.pack_message(message, seq, system, self.component_id, self.signing())

    def set_signing(self, key: bytes | None, link_id: int = 0) -> None:
        """Sign every frame sent here with ``key`` (MAVLink 2 signing; None: stop)."""
        self.signer = None if key is None else FC.Signer(key, link_id & 0xFF, now_timestamp())

    def signing(self) -> FC.Signer | None:
        """The signer for the next frames, its timestamp brought up to the wall clock (a
        receiver refuses a stream more than a minute behind its own clock), or None."""
        if self.signer is not None:
            self.signer.timestamp = max(self.signer.timestamp, now_timestamp())
        return self.signer

    def next_seq(self, system_id: int) -> int:
        """The sequence number of ``system_id``'s next frame here (for frames packed
        without pymavlink)."""
        seq = self._seq.get(system_id, 0)
        self._seq[system_id] = (seq + 1) & 0xFF
        return seq

    def hold(self, limit: int = FC.DATAGRAM_LIMIT) -> None:
        """Collect what is sent from now on, until :meth:`release` sends it together in
        datagrams of at most ``limit`` bytes."""
        if self._held is None:
            self._held = []
            self._held_limit = limit

    def release(self) -> None:
        """Send what was held, in order, in as few datagrams as fit (each unit given to
        :meth:`send_bytes` or :meth:`send_to` stays whole)."""
        held, self._held = self._held, None
        for address, run in itertools.groupby(held or [], key=lambda unit: unit[1]):
            for datagram in FC.datagrams([frame for frame, _ in run], self._held_limit):
                if address is None:
                    self.send_bytes(datagram)
                else:
                    self.send_to(datagram, address)

    def send_bytes(self, frame: bytes) -> None:
        """Write already packed frames to every live peer (and the fixed destination),
        or keep them for :meth:`release` while held."""
        if self._held is not None:
            self._held.append((frame, None))
            return
        now = time.monotonic()
        targets = []
        if self.destination is not None and self.only in (None, self.destination):
            targets.append(self.destination)
        for address, peer in list(self.peers.items()):
            if self.only is not None and address != self.only:
                continue
            if peer.sock is not None:
                try:
                    peer.sock.send(frame)
                except (BlockingIOError, InterruptedError):
                    pass  # a slow TCP client misses this frame rather than stall the loop
                except OSError:
                    peer.sock.close()
                    self.peers.pop(address, None)
            elif peer.heard is None or now - peer.heard > PEER_TIMEOUT:
                if now - peer.last_seen > PEER_TIMEOUT:
                    del self.peers[address]  # silent: forgotten
            elif address != self.destination:
                targets.append(address)
        for target in targets:
            # Nobody listening there (yet) is fine: UDP is fire-and-forget.
            with contextlib.suppress(OSError):
                self.sock.sendto(frame, target)
        self.sent += 1

    def send_to(self, frame: bytes, address: Any) -> None:
        """Write packed frames to one peer only, whatever :attr:`only` says (kept, in
        order with the rest, for :meth:`release` while held)."""
        if self._held is not None:
            self._held.append((frame, address))
            return
        peer = self.peers.get(address)
        with contextlib.suppress(OSError):
            if peer is not None and peer.sock is not None:
                peer.sock.send(frame)
            elif self.kind != "tcpin":
                self.sock.sendto(frame, address)

    def close(self) -> None:
        for peer in self.peers.values():
            if peer.sock is not None:
                peer.sock.close()
        self.peers.clear()
        self.sock.close()
