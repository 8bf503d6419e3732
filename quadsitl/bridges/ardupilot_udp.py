"""``quadsitl sim --flight-stack ardupilot``: ArduPilot's JSON physics over UDP.

One UDP socket per ArduPilot instance (port 9002 + 10 i, as ArduPilot's ``-I i`` sends),
on loopback unless asked otherwise. Each datagram that arrives is a servo frame; the
answer goes back to the address it came from. The protocol and the physics are
:mod:`.ardupilot_json`; this module only moves bytes, prints and stops.

Each instance belongs to one peer (address and port): the first to send it a servo
frame. Frames from any other sender are refused and counted, so that a stray datagram
can neither put a flying vehicle back at its start (a frame count of 0 reads as a
restart) nor turn the answers towards itself. ArduPilot's JSON backend sends from a
socket it never binds, so a restarted ArduPilot comes from a new ephemeral port: a new
sender is taken only once the bound one has been silent for SILENCE s (a live ArduPilot
sends a frame at least once a second, re-sending when unanswered).
"""

from __future__ import annotations

import math
import select
import socket
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from quadsitl.bridges.ardupilot_json import (
    ARDUPILOT_QUAD_FRAMES,
    PORT,
    PORT_STRIDE,
    JsonPhysics,
    PacketError,
    ServoFrame,
    parse_servo_packet,
)
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
from quadsitl.wire.addresses import is_loopback

PARAMETER_FOLDER = Path(__file__).resolve().parent / "ardupilot"
DATAGRAM = 2048  # bytes, more than the largest servo frame (72)
# s: a frame sent again sooner than this after our answer to it crossed that answer on
# the way (ArduPilot sends again only after 1 s without one); answering it twice would
# leave an extra answer queued, which ArduPilot would take for the next frame's. Queued
# re-sends are dropped by this rule one by one, so no socket needs draining.
CROSSING = 0.5
# wall s: the bound peer's silence after which another sender may take the instance.
# ArduPilot, when unanswered, sends its frame again every 1 s (SIM_JSON.cpp, recv_fdm), so
# a restarted one is taken within about SILENCE + 1 s of the old one's last frame.
SILENCE = 3.0
# Waiting for the next frame of one instance: a blocked process takes tens of µs to wake
# on a busy machine, more than ArduPilot's own turn-around when it is quick. So the wait
# first polls the socket for up to SPIN s, but only while the peer's recent turn-arounds
# (moving average, each counted up to TURNAROUND_CAP s) are shorter than SPIN: a slow peer,
# such as ArduCopter itself at ~150 µs a frame, is waited for asleep and costs no CPU.
SPIN = 60e-6
TURNAROUND_CAP = 1e-3
TURNAROUND_WEIGHT = 1 / 16  # of the newest turn-around in the moving average


def parameter_file(airframe: str) -> Path | None:
    """The shipped ArduCopter parameter file of preset ``airframe`` (None: there is none)."""
    path = PARAMETER_FOLDER / f"{airframe}.parm"
    return path if path.is_file() else None


@dataclass
class ArduPilotConfig(BridgeConfig):
    """What ``quadsitl sim --flight-stack ardupilot`` is told; see ``quadsitl sim --help``."""

    port: int = PORT  # of instance 0; instance i listens on port + 10 i


class ArduPilotJsonServer:
    """The sockets of N ArduPilot instances around one :class:`JsonPhysics`.

    Args:
        physics: the vehicles and the protocol; its ``notices`` say what is refused.
        bind: address the sockets listen on.
        port: of instance 0; instance i listens on ``port + 10 i``.
        silence: wall s the bound peer must be silent before another sender is taken.

    Raises OSError naming the port when a port cannot be opened (in use, say)."""

    def __init__(
        self,
        physics: JsonPhysics,
        bind: str = "127.0.0.1",
        port: int = PORT,
        silence: float = SILENCE,
        first_instance: int = 0,
    ) -> None:
        self.physics, self.silence = physics, silence
        self.notices = physics.notices
        self.ports = [port + PORT_STRIDE * i for i in range(physics.fleet.n)]
        self.sockets = open_ports(self.ports, bind, False, "ArduPilot", first_instance)
        self.addresses: list[Any] = [None] * physics.fleet.n  # each one's bound peer
        self.heard = [-math.inf] * physics.fleet.n  # monotonic s of its peer's last frame
        self.refused = [0] * physics.fleet.n  # frames from other senders, refused
        self.answered = [-math.inf] * physics.fleet.n  # monotonic s of each one's last answer
        self._index = {sock.fileno(): i for i, sock in enumerate(self.sockets)}
        self._sent_at = 0.0  # perf_counter s of the last answer (one instance)
        self.turnaround = TURNAROUND_CAP  # s, moving average: our answer to its next frame
        # Frames that would step a vehicle past this simulated time (µs) are not answered
        # until release(): an env holds its autopilot at a step's end (None: never held).
        self.hold_at_us: list[int | None] = [None] * physics.fleet.n
        self._held: dict[int, ServoFrame] = {}

    def serve(self, timeout: float = WAIT) -> int:
        """Wait up to ``timeout`` s for frames, answer those that came; the count answered.

        One datagram per instance and call: ArduPilot sends its next frame only once
        answered, so nothing else waits behind it but re-sends (see CROSSING)."""
        if len(self.sockets) == 1:
            received = [(0, self.sockets[0])] if self._wait_one(timeout) else []
        else:
            ready, _, _ = select.select(self.sockets, [], [], timeout)
            received = [(self._index[sock.fileno()], sock) for sock in ready]
        frames: dict[int, ServoFrame] = {}
        now = time.monotonic()
        for index, sock in received:
            try:
                data, address = sock.recvfrom(DATAGRAM)
            except (TimeoutError, BlockingIOError, InterruptedError):
                continue
            except OSError as error:  # e.g. ICMP unreachable from a peer that left
                self.notices(index, "receive errors", f"receive failed: {error}")
                continue
            try:
                frame = parse_servo_packet(data)
            except PacketError as error:
                text = f"ignored a datagram from {_name(address)}: {error}"
                self.notices(index, error.kind, text)
                continue
            if address != self.addresses[index] and not self._take(index, address, now):
                continue
            self.heard[index] = now
            repeat = frame.frame_count == self.physics.peers[index].frame_count
            if repeat and now - self.answered[index] < CROSSING:
                continue  # sent again just as our answer went out: it has one
            if not repeat and self._reached_hold(index):
                self._held[index] = frame  # (a re-send of it replaces it)
                continue
            frames[index] = frame
        return self._answer(frames, now)

    def release(self, index: int) -> None:
        """Answer instance ``index``'s frame held back (hold_at_us), if any."""
        frame = self._held.pop(index, None)
        if frame is not None:
            self._answer({index: frame}, time.monotonic())

    def forget(self, index: int) -> None:
        """Instance ``index`` is to be flown by a new ArduPilot (its old one ended): the
        vehicle back at its start, the first sender taken at once, what was queued
        dropped."""
        self.addresses[index], self.heard[index] = None, -math.inf
        self._held.pop(index, None)
        sock = self.sockets[index]
        while _readable(sock):
            try:
                sock.recvfrom(DATAGRAM)
            except OSError:
                break
        self.physics.restart(index)

    def holding(self, index: int) -> bool:
        """Whether a frame of instance ``index`` waits for :meth:`release`."""
        return index in self._held

    def _reached_hold(self, index: int) -> bool:
        """Whether instance ``index``'s vehicle has flown to its hold (within half a frame:
        a frame rate that does not divide the hold's time stops as near as it can)."""
        hold, peer = self.hold_at_us[index], self.physics.peers[index]
        if hold is None:
            return False
        half_frame_us = 0.5e6 / peer.frame_rate if peer.frame_rate else 0.0
        return peer.time_s * 1e6 + half_frame_us >= hold

    def _answer(self, frames: dict[int, ServoFrame], now: float) -> int:
        if not frames:
            return 0
        replies = self.physics.answer(frames)
        for index, reply in replies.items():
            self.answered[index] = now
            try:
                self.sockets[index].sendto(reply, self.addresses[index])
            except OSError as error:
                text = f"could not answer {_name(self.addresses[index])}: {error}"
                self.notices(index, "send errors", text)
        self._sent_at = time.perf_counter()
        return len(replies)

    def _take(self, index: int, address: Any, now: float) -> bool:
        """Whether instance ``index`` now belongs to ``address``, which sent it a frame:
        yes if it had no peer, or its peer has been silent for ``silence`` s; otherwise
        the frame is refused, counted and said (rate-limited)."""
        bound = self.addresses[index]
        quiet = now - self.heard[index]
        if bound is not None and quiet < self.silence:
            self.refused[index] += 1
            self.notices(
                index,
                "frames from another sender",
                f"refused a servo frame from {_name(address)}: this instance is flown by "
                f"{_name(bound)} (another sender is taken once it has been silent for "
                f"{self.silence:g} s)",
            )
            return False
        if bound is not None:
            self.notices(
                index,
                "new senders",
                f"now flown by {_name(address)}: {_name(bound)} was silent for {quiet:.1f} s",
            )
        self.addresses[index] = address
        return True

    def _wait_one(self, timeout: float) -> bool:
        """Wait up to ``timeout`` s for the one socket to hold a datagram; whether it does.

        Polls for up to SPIN s first while the peer is quick (see SPIN), then sleeps."""
        sock = self.sockets[0]
        arrived = False
        if self.turnaround < SPIN:
            end = self._sent_at + SPIN
            while not (arrived := _readable(sock)) and time.perf_counter() < end:
                pass
        if not arrived:
            arrived = bool(select.select(self.sockets, [], [], timeout)[0])
        if arrived:
            waited = min(TURNAROUND_CAP, time.perf_counter() - self._sent_at)
            self.turnaround += TURNAROUND_WEIGHT * (waited - self.turnaround)
        return arrived

    def close(self) -> None:
        """Say what was counted and not said; close the sockets."""
        self.notices.flush()
        for sock in self.sockets:
            sock.close()


def _name(address: Any) -> str:
    """``host:port`` of a socket address."""
    return f"{address[0]}:{address[1]}"


def _readable(sock: socket.socket) -> bool:
    """Whether a datagram waits in ``sock`` (non-blocking)."""
    try:
        sock.recv(1, socket.MSG_PEEK)
    except (BlockingIOError, InterruptedError):
        return False
    except OSError:
        return True  # a pending error (ICMP unreachable): recvfrom reports it
    return True


def run_ardupilot(
    config: ArduPilotConfig, say: Say | None = None, make_view: MakeView | None = None
) -> int:
    """Serve ArduPilot instances until a signal or ``config.duration`` (``make_view``:
    the live view's, for ``--rerun``); the exit status."""
    check_ports(config, PORT_STRIDE, "UDP")
    say = say or say_on_stderr
    physics = JsonPhysics(bridge_fleet(config, dt=1.0 / 1200), notice=say)
    server = ArduPilotJsonServer(physics, config.bind, config.port)
    if not is_loopback(config.bind):
        say(
            f"warning: the ArduPilot ports on {config.bind} can be reached from other hosts: "
            "whoever sends an instance the first servo frame flies that vehicle (or once its "
            f"ArduPilot has been silent {SILENCE:g} s), and each 40-byte frame is answered "
            "with ~300 bytes to the address it claims (docs/security.md)"
        )

    def summary(wall: float) -> str:
        simulated = max(peer.time_s for peer in physics.peers)
        frames = sum(peer.frames for peer in physics.peers)
        return (
            f"quadsitl sim: {frames} frames answered in {wall:.1f} s; "
            f"the longest-flying vehicle flew {simulated:.1f} s of physics"
        )

    try:
        watch = live_watch(
            make_view,
            physics.fleet,
            "ardupilot",
            config,
            lambda: [peer.time_s for peer in physics.peers],
            say,
        )
    except BaseException:
        server.close()
        raise
    banner = partial(_banner, config, physics, server)
    return serve_until_stopped(config, server, banner, summary, watch)


def _banner(
    config: ArduPilotConfig,
    physics: JsonPhysics,
    server: ArduPilotJsonServer,
    out: Say,
) -> None:
    """Say where each instance connects and how to start ArduCopter against it."""
    frame_name, _ = ARDUPILOT_QUAD_FRAMES[physics.frame_types[0]]
    parm = parameter_file(config.airframe)
    defaults = f" --defaults {parm}" if parm else ""
    out(
        f"quadsitl sim: the aircraft for ArduPilot's JSON backend, {config.vehicles} "
        f"vehicle(s), airframe {config.airframe} (FRAME_CLASS 1, FRAME_TYPE "
        f"{physics.frame_types[0]} {frame_name}); quadsitl's own flight software is off"
    )
    for index, port in enumerate(server.ports):
        target = "" if config.bind in ("127.0.0.1", "0.0.0.0") else f":{config.bind}"
        # ArduPilot's -I i sends its servo frames to 9002 + 10 i; another port is named.
        instance, off = divmod(port - PORT, PORT_STRIDE)
        start = (
            f"-I {instance}" if off == 0 and instance >= 0 else f"-I {index} --sim-port-out {port}"
        )
        out(
            f"  vehicle {index}: UDP {config.bind}:{port}  <-  arducopter --model JSON{target}"
            f"{defaults} {start}"
        )
    if parm is None:
        out(f"  (no parameter file ships for {config.airframe}; see docs/autopilots.md)")
    say_weather(config, out)
