"""What every flight-stack bridge does around its own framing: the options they share,
their ports opened with a clear error, their vehicles' physics, and the loop that
serves them until a signal or ``--duration`` and says what was flown.

With ``--rerun`` a :class:`LiveWatch` shows the flight after the turns: each
autopilot's own telemetry (:mod:`.autopilot_telemetry`) beside the physics' truth, in
the view the command line composes (``quadsitl.viz.flight_stack_view``; none of Rerun is
imported here).

A bridge (:mod:`.ardupilot_udp`, :mod:`.px4_tcp`) adds only its server: the sockets'
framing (UDP datagrams of servo frames, TCP streams of MAVLink), who each instance
belongs to and how a turn of its instances is taken (:class:`Server`).
"""

from __future__ import annotations

import errno
import signal
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from quadsitl.physics.fleet import Fleet
from quadsitl.physics.wind import Wind

WAIT = 0.2  # wall s, longest sleep in one turn (signals, --duration)
WATCH_PERIOD = 1.0 / 60.0  # wall s between the live view's looks at the flight
SIGNALS = (signal.SIGINT, signal.SIGTERM)
Say = Callable[[str], None]


@dataclass
class BridgeConfig:
    """What ``quadsitl sim --flight-stack …`` is told; see ``quadsitl sim --help``."""

    vehicles: int = 1  # autopilot instances, one vehicle each, one batched physics
    airframe: str = "iris"
    bind: str = "127.0.0.1"  # address the ports listen on
    port: int = 0  # of instance 0 (each bridge has its own default and stride)
    duration: float | None = None  # wall seconds, None: until a signal
    quiet: bool = False
    wind: Wind | None = None  # the weather every vehicle flies in (None: still air)
    wind_seed: int = 0


class Server(Protocol):
    """A bridge's sockets around its vehicles' physics."""

    def serve(self, timeout: float = WAIT) -> int:
        """One turn of every instance, waiting up to ``timeout`` s for input."""
        ...

    def close(self) -> None:
        """Close every socket; say what was counted and not said."""
        ...


class View(Protocol):
    """Something that shows the flight (``quadsitl.viz.flight_stack_view``)."""

    def show(self, wall_now: float, times_s: list[float], messages: list[tuple[int, Any]]) -> None:
        """Each vehicle's physics time now and the autopilots' messages that arrived."""
        ...

    def close(self) -> None: ...


MakeView = Callable[[Fleet, str], View]  # (the vehicles' physics, "px4" | "ardupilot")


class LiveWatch:
    """The view, shown what the autopilots said and where the vehicles are, at most once
    every WATCH_PERIOD of wall time (called after every turn of the server)."""

    def __init__(self, view: View, telemetry: Any, times_s: Callable[[], list[float]]) -> None:
        self.view, self.telemetry, self.times_s = view, telemetry, times_s
        self.next_look = 0.0

    def __call__(self, wall_now: float) -> None:
        if wall_now >= self.next_look:
            self.next_look = wall_now + WATCH_PERIOD
            self.view.show(wall_now, self.times_s(), self.telemetry.poll(wall_now))

    def close(self) -> None:
        self.telemetry.close()
        self.view.close()


def live_watch(
    make_view: MakeView | None,
    fleet: Fleet,
    stack: str,
    config: BridgeConfig,
    times_s: Callable[[], list[float]],
    say: Say,
) -> LiveWatch | None:
    """The live view of ``quadsitl sim --flight-stack … --rerun`` (None without one):
    its autopilot telemetry opened (OSError naming a port in use) and said where."""
    if make_view is None:
        return None
    from quadsitl.bridges.autopilot_telemetry import AutopilotTelemetry, instance_numbers

    telemetry = AutopilotTelemetry(
        stack, instance_numbers(stack, config.port, config.vehicles), notice=say
    )
    try:
        view = make_view(fleet, stack)
    except BaseException:
        telemetry.close()
        raise
    if not config.quiet:
        say(f"live view: the physics' truth beside {telemetry.describe()}")
    return LiveWatch(view, telemetry, times_s)


def say_on_stderr(text: str) -> None:
    print(f"quadsitl sim: {text}", file=sys.stderr, flush=True)


def check_ports(config: BridgeConfig, stride: int, transport: str) -> None:
    """ValueError unless 1..1000 vehicles whose ports (``config.port`` + ``stride`` i)
    are all valid ``transport`` ports."""
    if not 1 <= config.vehicles <= 1000:
        raise ValueError(f"--vehicles must be 1 .. 1000, got {config.vehicles}")
    last_port = config.port + stride * (config.vehicles - 1)
    if not config.port >= 1 or last_port > 65535:
        raise ValueError(f"ports {config.port} .. {last_port} are not all valid {transport} ports")


def bridge_fleet(config: BridgeConfig, dt: float | None = None) -> Fleet:
    """The vehicles' batched physics (``dt``: its step, s; None: the default), in the
    configured weather."""
    n, airframe = config.vehicles, config.airframe
    fleet = Fleet(n, airframe) if dt is None else Fleet(n, airframe, dt=dt)
    if config.wind is not None:
        fleet.set_wind(config.wind, seed=config.wind_seed)
    return fleet


def open_ports(
    ports: list[int], bind: str, tcp: bool, stack: str, first_instance: int = 0
) -> list[socket.socket]:
    """One non-blocking socket per instance (``first_instance`` ..), bound to
    ``bind``:port (TCP: listening for one connection). OSError naming the port and its
    instance when one cannot be opened (in use, say); the ones opened before it are
    closed."""
    sockets: list[socket.socket] = []
    transport = "TCP" if tcp else "UDP"
    try:
        for index, number in enumerate(ports):
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM if tcp else socket.SOCK_DGRAM)
            sockets.append(sock)
            if tcp:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((bind, number))
                if tcp:
                    sock.listen(1)
            except OSError as error:
                why = "is in use" if error.errno == errno.EADDRINUSE else f"({error})"
                raise OSError(
                    f"{transport} port {number} ({stack} instance {first_instance + index}) "
                    f"on {bind} {why}"
                ) from None
            sock.setblocking(False)
    except OSError:
        for sock in sockets:
            sock.close()
        raise
    return sockets


def say_weather(config: BridgeConfig, out: Say) -> None:
    """The banner's line of the weather, unless the air is still."""
    if config.wind is not None and not config.wind.calm:
        out(f"  weather: {config.wind.describe()}")


def serve_until_stopped(
    config: BridgeConfig,
    server: Server,
    banner: Callable[[Say], None],
    summary: Callable[[float], str],
    watch: LiveWatch | None = None,
) -> int:
    """Say ``banner`` (unless quiet), serve until SIGINT, SIGTERM or ``config.duration``
    (``watch`` shown the flight after each turn), print ``summary(wall seconds
    served)``, close; the exit status."""
    stopping: list[int] = []
    previous = [signal.signal(s, lambda n, _: stopping.append(n)) for s in SIGNALS]
    try:
        if not config.quiet:
            banner(lambda text: print(text, flush=True))
        started = time.monotonic()
        end = None if config.duration is None else started + config.duration
        while not stopping and (end is None or time.monotonic() < end):
            server.serve(WAIT if end is None else max(0.0, min(WAIT, end - time.monotonic())))
            if watch is not None:
                watch(time.monotonic())
        print(summary(time.monotonic() - started), flush=True)
    finally:
        for s, handler in zip(SIGNALS, previous, strict=True):
            signal.signal(s, handler)
        server.close()
        if watch is not None:
            watch.close()
    return 0
