"""``quadsitl sim --flight-stack px4``: PX4's simulator_mavlink over TCP.

One listening TCP socket per PX4 instance (port 4560 + i, as PX4's instance i connects
to), on loopback unless asked otherwise. PX4 connects out to it; what it sends is read
as MAVLink 2 frames and answered by :class:`~quadsitl.bridges.px4_hil.HilPhysics`. A
PX4 that disconnects is said, and the next connection on that port starts its vehicle
again; the other instances are served throughout. Each :meth:`Px4TcpServer.serve` is a
turn of every connection: at most one lockstep round and :data:`FRAMES_PER_TURN` frames
each, so a PX4 that floods its port moves its own vehicle no faster than the others
move theirs. This module only moves bytes, prints and stops.
"""

from __future__ import annotations

import contextlib
import select
import socket
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

from quadsitl.bridges.frame_reader import FrameReader
from quadsitl.bridges.px4_airframe import parameter_folder
from quadsitl.bridges.px4_hil import PORT, ROUND_US, HilPhysics
from quadsitl.bridges.serve import (
    WAIT,
    BridgeConfig,
    MakeView,
    Say,
    bridge_fleet,
    check_ports,
    live_watch,
    open_ports,
    say_on_stderr,
    say_weather,
    serve_until_stopped,
)
from quadsitl.geo import Home
from quadsitl.wire import fast_codec as FC
from quadsitl.wire.addresses import is_loopback
from quadsitl.wire.dialect import mavlink as mav

RECEIVE = 65536  # bytes per read, taken when the frames of the last read are all handled
FRAMES_PER_TURN = 64  # frames of one connection handled in one turn (bounds a flood's work)
SEND_LIMIT = 4 << 20  # bytes queued for a PX4 that does not read: it is dropped


@dataclass
class Px4Config(BridgeConfig):
    """What ``quadsitl sim --flight-stack px4`` is told; see ``quadsitl sim --help``."""

    port: int = PORT  # of instance 0; instance i listens on port + i
    home: Home | None = None  # where the GPS puts the vehicles (None: PX4's Zurich field)
    sensor_noise: float = 1.0  # scale of the sensor models' noise


class Connection:
    """One PX4's TCP connection: frames in, bytes out (queued while the socket is full)."""

    def __init__(self, sock: socket.socket, address: Any) -> None:
        self.sock, self.address = sock, address
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.reader = FrameReader()
        self.pending: deque[FC.Frame] = deque()  # read, not handled yet: they wait their turn
        self.outgoing = bytearray()

    def turn(self) -> list[FC.Frame]:
        """The frames handled in this turn: up to and with the first HIL_ACTUATOR_CONTROLS
        (one lockstep round), at most FRAMES_PER_TURN."""
        pending = self.pending
        frames: list[FC.Frame] = []
        while pending and len(frames) < FRAMES_PER_TURN:
            frames.append(pending.popleft())
            if frames[-1].msgid == mav.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS:
                break
        return frames

    def send(self, data: bytes) -> None:
        """Send ``data`` after what is queued; OSError when PX4 stopped reading."""
        if not self.outgoing:
            with contextlib.suppress(BlockingIOError):
                data = data[self.sock.send(data) :]
        self.outgoing += data
        if len(self.outgoing) > SEND_LIMIT:
            raise OSError(f"{len(self.outgoing)} bytes wait for a PX4 that does not read")

    def flush(self) -> None:
        if self.outgoing:
            with contextlib.suppress(BlockingIOError):
                del self.outgoing[: self.sock.send(self.outgoing)]


class Px4TcpServer:
    """The ports of N PX4 instances (``first_instance`` .., as errors name them) around
    one :class:`HilPhysics`.

    Raises OSError naming the port when a port cannot be opened (in use, say)."""

    def __init__(
        self, physics: HilPhysics, bind: str = "127.0.0.1", port: int = PORT,
        first_instance: int = 0,
    ) -> None:  # fmt: skip
        self.physics = physics
        self.ports = [port + i for i in range(physics.fleet.n)]
        self.listeners = open_ports(self.ports, bind, True, "PX4", first_instance)
        self.connections: list[Connection | None] = [None] * physics.fleet.n
        self._clock = time.monotonic()  # wall s of the next round on the server's clock
        # Wall s between the server's rounds while no PX4 leads (the first comes at once);
        # an env that wants each episode reproducible waits longer for its autopilot.
        self.wall_round_s = ROUND_US * 1e-6
        # Lockstep rounds that reach this simulated time (µs) are not sent until
        # release(): an env holds its autopilot at a step's end (None: never held).
        self.hold_at_us: list[int | None] = [None] * physics.fleet.n
        self._held: dict[int, bytes] = {}

    def serve(self, timeout: float = WAIT) -> int:
        """One turn of every connection: wait up to ``timeout`` s (none while frames wait
        their turn), accept, read, answer each connection's turn (:meth:`Connection.turn`);
        also move the vehicles the server's clock moves when their round is due. The
        count of frames handled."""
        waiting = self.physics.waiting_for_clock()
        if waiting:
            timeout = max(0.0, min(timeout, self._clock - time.monotonic()))
        live = [(i, c) for i, c in enumerate(self.connections) if c is not None]
        if any(c.pending for _, c in live):
            timeout = 0.0
        readers = [c.sock for _, c in live if not c.pending]  # the others are read later:
        writers = [c.sock for _, c in live if c.outgoing]  # TCP holds a flood back meanwhile
        ready = select.select(self.listeners + readers, writers, [], timeout)
        readable, writable = set(ready[0]), set(ready[1])
        # By connection, not by socket number: a connection dropped or replaced in this
        # turn has closed its socket (number -1), and what it sent goes with it.
        for index, conn in live:
            if conn.sock in writable:
                self._guard(index, conn, Connection.flush)
            if conn.sock in readable and self.connections[index] is conn:
                self._receive(index, conn)
        for index, sock in enumerate(self.listeners):
            if sock in readable:
                self._accept(index)
        messages = {}
        for index, current in enumerate(self.connections):
            if current is not None and current.pending:
                messages[index] = current.turn()
        replies = self.physics.answer(messages) if messages else {}
        for index in list(replies):
            hold = self.hold_at_us[index]
            if hold is not None and self.physics.peers[index].time_us >= hold:
                self._held[index] = self._held.get(index, b"") + replies.pop(index)
        waiting = self.physics.waiting_for_clock()
        if waiting and time.monotonic() >= self._clock:
            self._clock = max(self._clock + self.wall_round_s, time.monotonic() - 0.1)
            for index, data in self.physics.tick(waiting).items():
                replies[index] = replies.get(index, b"") + data
        for index, data in replies.items():
            current = self.connections[index]
            if current is not None:
                self._guard(index, current, partial(Connection.send, data=data))
        return sum(len(frames) for frames in messages.values())

    def release(self, index: int) -> None:
        """Send instance ``index`` the round held back (hold_at_us), if any."""
        data, current = self._held.pop(index, b""), self.connections[index]
        if data and current is not None:
            self._guard(index, current, partial(Connection.send, data=data))

    def _receive(self, index: int, conn: Connection) -> None:
        """Read what instance ``index``'s PX4 sent into its frames waiting their turn."""
        try:
            data = conn.sock.recv(RECEIVE)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as error:
            self._drop(index, _failure(error))
            return
        if not data:
            self._drop(index, "PX4 disconnected")
            return
        conn.pending.extend(conn.reader.feed(data))

    def _accept(self, index: int) -> None:
        try:
            sock, address = self.listeners[index].accept()
        except (BlockingIOError, InterruptedError):
            return
        if self.connections[index] is not None:
            self._drop(index, "a new connection replaces this one")
        # The server's clock starts now for this vehicle (a clock left from before would
        # catch up with a burst of rounds), or keeps the pace of those it already moves.
        now, others = time.monotonic(), self.physics.waiting_for_clock()
        self.connections[index] = Connection(sock, address)
        self.physics.connect(index)
        self._clock = min(self._clock, now) if others else now
        self.physics.notice(
            f"vehicle {index}: PX4 connected from {address[0]}:{address[1]} "
            f"(port {self.ports[index]}); its vehicle is at rest at home"
        )

    def _guard(self, index: int, conn: Connection, action: Callable[[Connection], None]) -> None:
        """``action`` on instance ``index``'s connection ``conn`` unless it was dropped or
        replaced; an OSError drops it."""
        if self.connections[index] is not conn:
            return
        try:
            action(conn)
        except OSError as error:
            self._drop(index, _failure(error))

    def _drop(self, index: int, why: str) -> None:
        conn = self.connections[index]
        if conn is None:
            return
        self.connections[index] = None
        self._held.pop(index, None)
        conn.sock.close()
        self.physics.disconnect(index)
        self.physics.notice(
            f"vehicle {index}: {why}; waiting for PX4 on port {self.ports[index]} again "
            "(the other vehicles fly on)"
        )

    def close(self) -> None:
        for conn in self.connections:
            if conn is not None:
                conn.sock.close()
        self.physics.notices.flush()  # what was counted and not said
        for sock in self.listeners:
            sock.close()


def run_px4(config: Px4Config, say: Say | None = None, make_view: MakeView | None = None) -> int:
    """Serve PX4 instances until a signal or ``config.duration`` (``make_view``: the
    live view's, for ``--rerun``); the exit status."""
    check_ports(config, 1, "TCP")
    say = say or say_on_stderr
    physics = HilPhysics(bridge_fleet(config), config.home, config.sensor_noise, notice=say)
    server = Px4TcpServer(physics, config.bind, config.port)
    if not is_loopback(config.bind):
        say(
            f"warning: the PX4 simulator ports on {config.bind} can be reached from other "
            "hosts: anyone there can fly the vehicles (docs/security.md)"
        )

    def summary(wall: float) -> str:
        rounds = sum(peer.rounds for peer in physics.peers)
        simulated = max(peer.time_us for peer in physics.peers) / 1e6
        return (
            f"quadsitl sim: {rounds} sensor rounds in {wall:.1f} s; the vehicle flying "
            f"longest since its PX4 connected has flown {simulated:.1f} s of physics"
        )

    try:
        watch = live_watch(
            make_view,
            physics.fleet,
            "px4",
            config,
            lambda: [peer.time_us * 1e-6 for peer in physics.peers],
            say,
        )
    except BaseException:
        server.close()
        raise
    return serve_until_stopped(config, server, partial(_banner, config, server), summary, watch)


def _banner(config: Px4Config, server: Px4TcpServer, out: Say) -> None:
    """Say where each instance connects and how to start PX4 against it."""
    folder = parameter_folder(config.airframe)
    out(
        f"quadsitl sim: the aircraft for PX4's simulator_mavlink, {config.vehicles} "
        f"vehicle(s), airframe {config.airframe}; quadsitl's own flight software is off"
    )
    path = f"PATH={folder}:$PATH " if folder else ""
    for index, port in enumerate(server.ports):
        instance = port - PORT  # PX4's startup connects instance i to 4560 + i
        start = (
            f"{path}PX4_SIM_MODEL=none_iris px4 -i {instance}"
            if instance >= 0
            else f"PX4 started by hand with 'simulator_mavlink start -c {port}'"
        )
        out(f"  vehicle {index}: TCP {config.bind}:{port}  <-  {start}")
    if folder is None:
        out(f"  (no PX4 parameter file ships for {config.airframe}; see docs/autopilots.md)")
    say_weather(config, out)


def _failure(error: OSError) -> str:
    """Why a connection ended, in words: a peer that closed or reset it (found while
    sending or receiving, whichever came first) disconnected; anything else failed."""
    if isinstance(error, (BrokenPipeError, ConnectionResetError, ConnectionAbortedError)):
        return f"PX4 disconnected ({error})"
    return f"the connection failed ({error})"
