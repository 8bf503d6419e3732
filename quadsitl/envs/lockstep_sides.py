"""The simulator's side of autopilots flown from an env, one per flight stack: the
physics each autopilot flies and the server that holds its clock (docs/autopilots.md,
"How an env step works").

Both stacks wait for the simulator in lockstep, so the server holds an autopilot at a
simulated instant by not sending what would move it past it:

* PX4 (:class:`Px4Side`): simulator_mavlink over TCP 4560 + i; PX4 waits for each
  HIL_SENSOR round (4 ms), and the round that reaches the hold is kept back.
* ArduPilot (:class:`ArduPilotSide`): the JSON interface over UDP 9002 + 10 i; ArduPilot
  waits for the answer to each servo frame (1/SIM_RATE_HZ s), and the frame that would
  step past the hold is left unanswered.

The env's :class:`~quadsitl.envs.autopilot_link.Autopilots` sees either through the same
few methods: the vehicle's simulated time, where to hold it, whether it leads in
lockstep, whether it is still connected.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from quadsitl.bridges.ardupilot_json import PORT as JSON_PORT
from quadsitl.bridges.ardupilot_json import PORT_STRIDE, JsonPhysics
from quadsitl.bridges.ardupilot_udp import ArduPilotJsonServer
from quadsitl.bridges.px4_hil import PORT, ROUND_US, HilPhysics
from quadsitl.bridges.px4_tcp import Px4TcpServer
from quadsitl.physics.fleet import Fleet

STARTING_ROUND_S = 1.0  # wall s between PX4 rounds until the autopilot leads in lockstep
# wall s an ArduPilot's JSON port must be silent before another sender takes it: only the
# env's own child sends there (a restart is forgotten first, and taken at once)
JSON_SILENCE_S = 0.5
FRAME_RATE = 800  # Hz: the physics frames ArduPilot asks for (SIM_RATE_HZ in offboard.parm)


class Px4Side:
    """PX4 instances ``first_instance`` .. on simulator_mavlink, flying ``fleet``."""

    name, title = "px4", "PX4"
    frame_us = ROUND_US  # µs: the shortest span an env can hold a vehicle at

    def __init__(
        self, fleet: Fleet, first_instance: int, sensor_noise: float, notice: Callable[[str], None]
    ) -> None:
        self.physics = HilPhysics(fleet, noise_scale=sensor_noise, notice=notice)
        self.fleet = self.physics.fleet
        self.server = Px4TcpServer(self.physics, "127.0.0.1", PORT + first_instance, first_instance)
        # One round when an autopilot connects, then only those it answers: the rounds
        # before it leads in lockstep are then the same every time (the fake answers the
        # first; a real PX4 that does not is sent another each second).
        self.server.wall_round_s = STARTING_ROUND_S

    def time_us(self, row: int) -> int:
        """Vehicle ``row``'s simulated time (its autopilot's clock)."""
        return self.physics.peers[row].time_us

    def answered_us(self, row: int) -> int:
        """The clock of the last round its autopilot answered (its motor outputs)."""
        return self.physics.peers[row].answered_us

    def begin(self, row: int) -> Any:
        """A new autopilot is about to start for ``row``: hold it from its first round.
        What :meth:`leading` compares with (a connection makes a new peer)."""
        self.server.hold_at_us[row] = 0
        return self.physics.peers[row]

    def leading(self, row: int, before: Any) -> bool:
        """Whether the autopilot started after :meth:`begin` leads in lockstep."""
        peer = self.physics.peers[row]
        return peer is not before and peer.lockstep

    def hold(self, row: int, until_us: int) -> None:
        """Let ``row`` fly until ``until_us`` of its clock (the round held so far goes)."""
        self.server.hold_at_us[row] = until_us
        self.server.release(row)

    def reached(self, row: int, until_us: int) -> bool:
        """Whether ``row`` has flown to ``until_us`` of its clock and waits there."""
        return self.time_us(row) + self.frame_us // 2 >= until_us

    def sent_all(self, row: int) -> bool:
        """Whether everything the autopilot sends before its clock moves on has come
        (PX4's modules run in threads of their own: never known; its stamps say)."""
        return False

    def connected(self, row: int) -> bool:
        return self.server.connections[row] is not None

    def serve(self, timeout: float) -> None:
        self.server.serve(timeout)

    def close(self) -> None:
        self.server.close()


class ArduPilotSide:
    """ArduPilot instances ``first_instance`` .. on the JSON interface, flying ``fleet``
    (``sensor_noise`` is not used here: ArduPilot models its own sensors from the JSON
    state, their noise set by its SIM_ parameters: see
    :func:`~quadsitl.envs.autopilot_commands.arducopter_command`)."""

    name, title = "ardupilot", "ArduPilot"
    frame_us = round(1e6 / FRAME_RATE)

    def __init__(
        self, fleet: Fleet, first_instance: int, sensor_noise: float, notice: Callable[[str], None]
    ) -> None:
        fleet.dt = 1.0 / FRAME_RATE
        self.physics = JsonPhysics(fleet, notice=notice)
        self.fleet = self.physics.fleet
        port = JSON_PORT + PORT_STRIDE * first_instance
        self.server = ArduPilotJsonServer(
            self.physics, "127.0.0.1", port, JSON_SILENCE_S, first_instance
        )

    def time_us(self, row: int) -> int:
        return round(self.physics.peers[row].time_s * 1e6)

    def answered_us(self, row: int) -> int:
        # ArduPilot's clock is the timestamp of the last answer (held: the step's end)
        return self.time_us(row)

    def begin(self, row: int) -> Any:
        self.server.forget(row)  # the vehicle at rest at its start, the new sender taken
        self.server.hold_at_us[row] = 0
        return None

    def leading(self, row: int, before: Any) -> bool:
        return self.server.holding(row) or self.physics.peers[row].frame_count is not None

    def hold(self, row: int, until_us: int) -> None:
        self.server.hold_at_us[row] = until_us
        self.server.release(row)

    def reached(self, row: int, until_us: int) -> bool:
        # its next frame, held: it has run its loop at the hold's time and waits
        return self.server.holding(row) and self.time_us(row) + self.frame_us // 2 >= until_us

    def sent_all(self, row: int) -> bool:
        # ArduPilot's SITL writes its MAVLink in its one main loop, before the servo frame
        # that ends the loop: once that frame is held, what it sent is in the socket
        return self.server.holding(row)

    def connected(self, row: int) -> bool:
        return True  # UDP: an ArduPilot that is gone is seen by its exit or its stall

    def serve(self, timeout: float) -> None:
        self.server.serve(timeout)

    def close(self) -> None:
        self.server.close()


SIDES: dict[str, type[Px4Side] | type[ArduPilotSide]] = {"px4": Px4Side, "ardupilot": ArduPilotSide}
