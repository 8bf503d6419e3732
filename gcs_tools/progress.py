"""How a mission is getting on, as ``quadsitl fly`` watches it: a line when an item is
reached, the distance to the current item every few wall seconds, and a stall (no item
reached and the distance to the current one not down by ``PROGRESS`` m for
``stall_after`` simulated seconds) raised as a ClientError, instead of silence until the
timeout. Positions and times come from the vehicle's LOCAL_POSITION_NED stream
(simulated time: a simulator running faster than real time stalls in its own seconds)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from gcs_tools.client import ClientError, MissionItem, VehicleClient, mav
from quadsitl.geo import Home

PROGRESS = 0.5  # m nearer the current item that counts as progress
NEAR = 1.0  # m: within this of the item it is holding, landing or done: never a stall
REPORT_EVERY = 5.0  # wall s between progress lines
LANDINGS = (mav.MAV_CMD_NAV_LAND, mav.MAV_CMD_NAV_RETURN_TO_LAUNCH)
POSITIONS = (
    mav.MAV_CMD_NAV_WAYPOINT,
    mav.MAV_CMD_NAV_LOITER_UNLIM,
    mav.MAV_CMD_NAV_LOITER_TIME,
    mav.MAV_CMD_NAV_LOITER_TURNS,
)
NAMES = {
    mav.MAV_CMD_NAV_TAKEOFF: "take-off",
    mav.MAV_CMD_NAV_LAND: "land",
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: "return to launch",
    **{command: "waypoint" for command in POSITIONS},
}


def height(item: MissionItem, home: Home) -> float:
    """m above home of an item's altitude, by its frame (AMSL or relative/terrain)."""
    if item.frame in (mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_INT):
        return item.altitude - home.altitude
    return item.altitude


def item_distance(item: MissionItem, home: Home, enu: np.ndarray) -> float | None:
    """m from ``enu`` (m from home) to where ``item`` takes the vehicle: a take-off's
    height, a waypoint, a landing's ground (at its spot, or home for RTL); None for an
    item that goes nowhere (camera, speed, ...)."""
    if item.command == mav.MAV_CMD_NAV_TAKEOFF:
        return abs(height(item, home) - float(enu[2]))
    if item.command == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
        return float(np.linalg.norm(enu))
    if item.command == mav.MAV_CMD_NAV_LAND and math.isnan(item.latitude):
        return abs(float(enu[2]))
    if item.command in (*POSITIONS, mav.MAV_CMD_NAV_LAND):
        east, north, _ = home.to_local(item.latitude, item.longitude, home.altitude)
        up = 0.0 if item.command == mav.MAV_CMD_NAV_LAND else height(item, home)
        return float(np.linalg.norm(enu - np.array([east, north, up])))
    return None


class Progress:
    """Watches ``items`` being flown: call :meth:`update` after each received message."""

    def __init__(
        self,
        items: list[MissionItem],
        home: Home,
        stall_after: float | None,
        say: Callable[[str], None],
    ) -> None:
        self.items, self.home, self.stall_after, self.say = items, home, stall_after, say
        self.seq = -1
        self.reached = 0  # of the client's MISSION_ITEM_REACHED seen
        self.mark = (-math.inf, math.inf)  # (simulated s, m) of the last progress
        self.last_line = time.monotonic()

    def _name(self, seq: int) -> str:
        what = NAMES.get(self.items[seq].command, f"command {self.items[seq].command}")
        return f"item {seq + 1}/{len(self.items)} ({what})"

    def update(self, client: VehicleClient) -> None:
        """Report what is new; ClientError when the vehicle has stalled."""
        position = client.latest.get("LOCAL_POSITION_NED")
        current = client.latest.get("MISSION_CURRENT")
        if position is None or current is None or not 0 <= current.seq < len(self.items):
            return
        now = position.time_boot_ms / 1000  # simulated s
        for seq in client.reached[self.reached :]:
            if 0 <= seq < len(self.items):
                self.say(f"{self._name(seq)} reached at {now:.1f} s (simulated)")
            self.mark = (now, math.inf)
        self.reached = len(client.reached)
        if current.seq != self.seq or now < self.mark[0]:
            self.seq, self.mark = current.seq, (now, math.inf)
        enu = np.array([position.y, position.x, -position.z])
        distance = item_distance(self.items[self.seq], self.home, enu)
        if distance is None or distance < NEAR:
            self.mark = (now, math.inf)
        elif distance <= self.mark[1] - PROGRESS:
            self.mark = (now, distance)
        elif self.stall_after and now - self.mark[0] > self.stall_after:
            raise ClientError(
                f"stalled: no progress for {self.stall_after:g} s (simulated) on "
                f"{self._name(self.seq)}: {distance:.2f} m away and not {PROGRESS:g} m "
                f"nearer since {self.mark[0]:.1f} s, at east {enu[0]:.2f}, north "
                f"{enu[1]:.2f}, up {enu[2]:.2f} m (--stall-after)"
            )
        if time.monotonic() - self.last_line >= REPORT_EVERY:
            self.last_line = time.monotonic()
            away = "" if distance is None else f", {distance:.1f} m away"
            self.say(f"{now:.0f} s (simulated): {self._name(self.seq)}{away}")
