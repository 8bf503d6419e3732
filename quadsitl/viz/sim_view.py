"""``quadsitl sim --rerun``: the simulated vehicles streamed to Rerun as they fly.

At most 30 times a wall-clock second, the telemetry each vehicle would send (attitude,
local position, rotor speeds, battery, mission item, and the wind when the air moves) is
built by the same builders as the MAVLink telemetry and logged through
:class:`LiveLogger`, and once a second its heartbeat (flight mode and armed state);
vehicle events go to the text log. Rotor speeds are shown as multiples of the airframe's
hover speed. One vehicle: the 3-D camera follows it. A fleet (``sim --vehicles N``):
each vehicle under its system id (:mod:`quadsitl.viz.fleet`), the camera framing the
fleet's start grid and the air above it. The vehicles are logged in turn, one per tick
(a tick then costs what one vehicle's does, never a burst for the whole fleet), at most
FLEET_SNAPSHOTS ticks a second: 30 Hz each for 2 vehicles, 15 Hz each for 4, less for
more (recording more stole the real-time loop's time on a 2-core machine). A crowd (more
than :data:`~quadsitl.viz.fleet.CROWD` vehicles) is drawn dimmed but for the vehicle in
focus (``sim --rerun-focus SYSID``, default the first), which is logged on its own at
RATE besides. A vehicle's messages are logged one per pass of the simulator's loop, in
the time a physics step leaves (at most PENDING_LIMIT wait: the oldest are dropped).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from typing import Any

from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.simulator import telemetry_pose as pose
from quadsitl.simulator import telemetry_sensors as sensors
from quadsitl.simulator import telemetry_status as status
from quadsitl.simulator.snapshot import Snapshot
from quadsitl.viz.fleet import Member, fleet_of, origin_offset
from quadsitl.viz.live import LiveLogger, open_live
from quadsitl.viz.scene import LIVE_PANELS, SENSOR_PANELS

RATE = 30.0  # Hz of wall time, per vehicle
FLEET_SNAPSHOTS = 60.0  # Hz of wall time: vehicles logged a second, the fleet together
PENDING_LIMIT = 64  # messages waiting to be logged
MESSAGE_TIME = 0.5e-3  # wall s a message's logging may take (a few rr.log calls)
BUILDERS = (
    pose.build_attitude,
    pose.build_attitude_quaternion,
    pose.build_local_position_ned,
    status.build_actuator_output_status,
    status.build_battery_status,
    status.build_mission_current,
    sensors.build_highres_imu,  # what the sensor models read, noise and all
)
PANELS = (*LIVE_PANELS, "battery_remaining", "mission_item", *SENSOR_PANELS)


class SimView:
    """``vehicles``: system id -> vehicle. Spawns a viewer, saves to ``save`` (an .rrd
    path), or (``web``) serves the web viewer on this host and prints its URL;
    ``notice`` takes the message saying where the recording goes when no viewer can be
    shown."""

    def __init__(
        self,
        vehicles: Mapping[int, Vehicle],
        save: str | None = None,
        notice: Callable[[str], None] | None = None,
        web: bool = False,
        focus: int | None = None,
    ) -> None:
        if not vehicles:
            raise ValueError("SimView needs at least one vehicle")
        self.vehicles = dict(vehicles)
        members = fleet_members(self.vehicles, focus) if len(self.vehicles) > 1 else []
        windy = any(v.fleet.windy for v in self.vehicles.values())
        panels = (*PANELS, "wind") if windy else PANELS
        hovers = [vehicle.airframe.hover_rotor_speed for vehicle in self.vehicles.values()]
        self.rec, self.loggers = open_live(
            "quadsitl_sim", members, panels, hovers, save, notice, web
        )
        turns = list(enumerate(zip(self.vehicles.values(), self.loggers, strict=True)))
        focused = [i for i, m in enumerate(members) if m.focus]
        # A crowd's vehicle in focus is logged on its own, at RATE; the rest take turns.
        self.focus = turns.pop(focused[0]) if focused else None
        self.next_focus = 0.0
        self.turns = turns
        self.period = 1.0 / min(RATE * len(self.turns), FLEET_SNAPSHOTS)  # s of wall time
        self.turn = 0
        self.next_due = 0.0
        self.next_heartbeat = [0.0] * len(self.vehicles)  # wall s, per vehicle
        self.pending: list[tuple[LiveLogger, Any, float]] = []  # (logger, message, stamp)

    def tick(self, wall_now: float, spare: float = math.inf) -> None:
        """Called on every pass of the simulator's loop, ``spare`` wall s before its next
        physics step: when a snapshot is due, take the next vehicle's messages; log one
        message a pass, when the pass has MESSAGE_TIME to spare or, where passes never
        have (faster than real time), once half the time to the next snapshot has gone.
        A snapshot logged at once (a dozen series) made the next physics steps late."""
        if wall_now >= self.next_due:
            self.next_due = wall_now + self.period
            turn, self.turn = self.turn, (self.turn + 1) % len(self.turns)
            index, (vehicle, logger) = self.turns[turn]
            self.pending = self._snapshot(wall_now, index, vehicle, logger) + self.pending
        if self.focus is not None and wall_now >= self.next_focus:
            self.next_focus = wall_now + 1.0 / RATE
            index, (vehicle, logger) = self.focus
            self.pending = self._snapshot(wall_now, index, vehicle, logger) + self.pending
        del self.pending[PENDING_LIMIT:]  # the oldest (logged from the end)
        urgent = wall_now >= self.next_due - self.period / 2
        if self.pending and (spare >= MESSAGE_TIME or urgent):
            logger, message, stamp = self.pending.pop()
            logger.message(message, own=True, now=stamp)

    def _snapshot(
        self, wall_now: float, index: int, vehicle: Vehicle, logger: LiveLogger
    ) -> list[tuple[LiveLogger, Any, float]]:
        """Vehicle ``index``'s messages (its heartbeat once a second), to be logged in
        order (popped from the end), stamped with the time they were taken."""
        stamp = time.time()
        snapshot = Snapshot(vehicle)
        messages = [build(snapshot) for build in BUILDERS]
        if vehicle.estimator.enabled:  # the truth beside the estimate the telemetry shows
            messages.append(pose.build_sim_state(snapshot))
        if vehicle.fleet.windy:
            messages.append(sensors.build_wind_cov(snapshot))
        if wall_now >= self.next_heartbeat[index]:
            self.next_heartbeat[index] = wall_now + 1.0
            messages.insert(0, status.build_heartbeat(vehicle))
        return [(logger, message, stamp) for message in reversed(messages)]

    def event(self, text: str) -> None:
        self.loggers[0].text(text)

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()


def fleet_members(vehicles: Mapping[int, Vehicle], focus: int | None = None) -> list[Member]:
    """The fleet in the scene: each vehicle at its local origin's offset from the first's
    (``focus``: the system id a crowd shows in full; ValueError if none has it)."""
    first = next(iter(vehicles.values())).origin
    offsets = [origin_offset(first, (0, 0, 0), v.origin, (0, 0, 0)) for v in vehicles.values()]
    return fleet_of(list(vehicles), offsets, focus=focus)
