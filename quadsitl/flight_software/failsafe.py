"""Failsafes, as PX4 names and numbers them: low battery, geofence, lost ground station.

Each check looks at the vehicle's numbers and answers what to say and which mode to fly,
once per breach (it re-arms when the condition clears); the vehicle carries it out. Only
a vehicle that is armed and in the air reacts: on the ground a failsafe only warns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadsitl.flight_software import external_control as X
from quadsitl.flight_software.results import Severity
from quadsitl.flight_software.view import VehicleView
from quadsitl.wire.modes import Mode

# COM_LOW_BAT_ACT, NAV_DLL_ACT and GF_ACTION values -> the mode flown (None: warn only).
BATTERY_ACTIONS = {0: None, 2: Mode.LAND, 3: Mode.RTL}
DATALINK_ACTIONS = {0: None, 1: Mode.LOITER, 2: Mode.RTL, 3: Mode.LAND}
GEOFENCE_ACTIONS = {0: None, 1: None, 2: Mode.LOITER, 3: Mode.RTL, 5: Mode.LAND}
_ACTION_TEXT = {None: "", Mode.LOITER: ": holding", Mode.RTL: ": returning", Mode.LAND: ": landing"}


@dataclass(frozen=True)
class Reaction:
    severity: Severity
    text: str
    mode: Mode | None = None  # the mode to switch to, if any


class Failsafes:
    """Remembers which failsafes have fired, so that each fires once per breach."""

    def __init__(self) -> None:
        self.battery_level = 0  # 0 fine, 1 low, 2 critical, 3 emergency
        self.fence_breached = False

    def battery(self, remaining: float, params: dict[str, float]) -> Reaction | None:
        """``remaining``: fraction of charge left."""
        level = (
            (remaining < params["BAT_LOW_THR"])
            + (remaining < params["BAT_CRIT_THR"])
            + (remaining < params["BAT_EMERGEN_THR"])
        )
        if level <= self.battery_level:
            return None
        self.battery_level = level
        percent = f"{100 * remaining:.0f} %"
        if level == 3:
            return Reaction(Severity.CRITICAL, f"battery emergency ({percent}): landing", Mode.LAND)
        if level == 2:
            mode = BATTERY_ACTIONS.get(int(params["COM_LOW_BAT_ACT"]))
            return Reaction(
                Severity.CRITICAL, f"battery critical ({percent}){_ACTION_TEXT[mode]}", mode
            )
        return Reaction(Severity.WARNING, f"battery low ({percent})")

    def geofence(
        self, horizontal: float, height: float, params: dict[str, float]
    ) -> Reaction | None:
        """``horizontal`` distance from home and ``height`` above it, m."""
        max_xy, max_z = params["GF_MAX_HOR_DIST"], params["GF_MAX_VER_DIST"]
        outside = (max_xy > 0 and horizontal > max_xy) or (max_z > 0 and height > max_z)
        if not outside:
            self.fence_breached = False
            return None
        if self.fence_breached:
            return None
        self.fence_breached = True
        action = int(params["GF_ACTION"])
        if action == 0:
            return None
        where = f"{horizontal:.0f} m from home, {height:.0f} m up"
        mode = GEOFENCE_ACTIONS.get(action)
        return Reaction(Severity.CRITICAL, f"geofence breached ({where}){_ACTION_TEXT[mode]}", mode)

    @staticmethod
    def datalink_lost(silence: float, params: dict[str, float]) -> Reaction:
        """The ground station has been silent ``silence`` seconds (wall clock)."""
        mode = DATALINK_ACTIONS.get(int(params["NAV_DLL_ACT"]))
        seconds = "" if math.isinf(silence) else f" for {silence:.0f} s"
        text = f"ground station link lost{seconds}{_ACTION_TEXT[mode]}"
        return Reaction(Severity.CRITICAL, text, mode)

    def reset(self) -> None:
        self.battery_level = 0
        self.fence_breached = False


def check(v: VehicleView, failsafes: Failsafes) -> None:
    """Each control tick: the battery and the geofence (``failsafes``: which fired)."""
    p = v.params.values
    react(v, failsafes.battery(v.battery.remaining, p))
    x, y, z = v.nav_position.tolist()
    home_x, home_y, home_z = v.home_position.tolist()
    height = z - home_z - v.airframe.gear_height
    react(v, failsafes.geofence(math.hypot(x - home_x, y - home_y), height, p))


def react(v: VehicleView, reaction: Reaction | None) -> None:
    """Announce a failsafe; fly its mode if armed and in the air."""
    if reaction is None:
        return
    v.event(reaction.severity, reaction.text)
    mode = reaction.mode
    if mode is None or not v.armed or v.on_ground or mode is v.flight.mode:
        return
    if mode is Mode.RTL and v.flight.mode is Mode.LAND:
        return  # already coming down
    if v.motor_control:
        X.release_motors(v, reaction.text)
    v.event(Severity.INFO, f"mode {mode.name}")
    v.flight.enter(mode)
